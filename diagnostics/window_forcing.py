"""Where does a model's gait fail: in the base motion it generates, or in its legs?

Each benchmark clip (held-out and training, pimann.generate.benchmark_clips) is entered at its first
sample's step with the data's whole state (pimann.generate.batch_generator.data_start: velocity
history,
future window, joints, pose), and rolled out unsteered with no command blend for up to
`--seconds`, two ways in one batch:

- `free`: the network's own predictions fed back (the autoregression alone);
- `windows`: the velocity window of every input replaced by the data's at that step, while the
  joints, joint velocities and pose stay the network's own.

For each, against the clip over the same frames: the legs' speed along the clip's own motion
(leg odometry, the mean planar base velocity of the rollout over the clip's), the touchdowns
per foot per 10 s beside the clip's, and the leg joints' RMSE. A model whose legs walk under
the data's windows but stall free fails in the base motion it generates; one that stalls under
both fails in its legs. Run after `dvc repro` (it reads models/ and data/retargeted):

    python -m diagnostics.window_forcing [--models models] [--seconds 8]
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import torch
from scipy.spatial.transform import Rotation

from diagnostics.mid_stride import ratio_along
from diagnostics.teacher_forcing import add_models_argument, table_over_models
from pimann.core.contacts import touchdowns
from pimann.core.params import MotionSegment, Params, load_params
from pimann.core.paths import REPO_ROOT
from pimann.core.robot import LEG_JOINTS as LEGS
from pimann.core.robot import load_robot
from pimann.core.trajectory import Trajectory
from pimann.generate.batch_generator import BatchGenerator, data_start
from pimann.generate.benchmark_clips import held_out_clips, training_clips
from pimann.generate.command_script import ScriptSteps
from pimann.learn.features import clip_features
from pimann.learn.model_files import model_seeds
from pimann.learn.motion_classes import base_motion, class_counts, majority_class
from pimann.learn.standing import StandingPose

MODES = ("free", "windows")


class WindowForcedNetwork:
    """The rollout's network with the velocity-window inputs of the `forced` rows replaced by
    the data's x at the current step (every row walks: the generator passes them all)."""

    def __init__(self, network, data_x: np.ndarray, forced: np.ndarray, columns: np.ndarray):
        self.network, self.data_x, self.forced, self.columns = network, data_x, forced, columns
        self.calls = 0

    def __call__(self, x: np.ndarray) -> np.ndarray:
        k, self.calls = self.calls, self.calls + 1
        x = x.copy()
        x[np.ix_(self.forced, self.columns)] = self.data_x[k, self.columns]
        return self.network(x)


def forced_rollouts(
    model: torch.nn.Module,
    layout,
    stats,
    clip: Trajectory,
    params: Params,
    seconds: float,
    network=None,
) -> dict[str, Trajectory] | None:
    """{mode: the rollout's trajectory, "data": the clip over the same frames}: both modes in
    one batch from the clip's first sample step; None when the clip is shorter than the
    windows. `network`: x -> y in physical units in place of the model's (the tests)."""
    x, _, steps = clip_features(clip, layout)
    length = min(round(seconds * layout.rate_hz), len(steps))
    if length < 2:
        return None
    rollout = dataclasses.replace(params.rollout, command_blend_tau=None)
    generator = BatchGenerator(
        model,
        layout,
        stats,
        rollout,
        np.zeros(len(MODES), bool),
        load_robot(),
        params.contacts,
        StandingPose.nominal(),
    )
    xs = layout.x_slices
    columns = np.r_[xs["base_linear_window"], xs["base_angular_window"]]
    forced = np.array([mode == "windows" for mode in MODES])
    inner = generator.network if network is None else network
    generator.network = WindowForcedNetwork(inner, x, forced, columns)
    data_start([clip] * len(MODES), [int(steps[0])] * len(MODES), generator)
    # a motion command (a zero one is a stand); with no steering and no blend it is not used
    walk = MotionSegment(length / layout.rate_hz, 0.1, 0.0, 0.0)
    plan = ScriptSteps([[walk]] * len(MODES), layout.rate_hz)
    record = {name: [] for name in ("position", "rotation", "joints", "contacts")}
    with torch.inference_mode():
        for k in range(1, length + 1):
            generator.step(k, *plan.at(k))
            for name, values in record.items():
                values.append(np.array(getattr(generator, name)))
    arrays = {name: np.stack(values, axis=1) for name, values in record.items()}
    time = np.arange(length) / layout.rate_hz
    out = {
        mode: Trajectory(
            time=time,
            base_position=arrays["position"][row],
            base_quaternion_xyzw=Rotation.from_matrix(arrays["rotation"][row]).as_quat(),
            joint_positions=arrays["joints"][row],
            source=mode,
            rate_hz=layout.rate_hz,
            contacts=arrays["contacts"][row],
        )
        for row, mode in enumerate(MODES)
    }
    frames = slice(int(steps[0]), int(steps[0]) + length)  # the frames generated
    out["data"] = Trajectory(
        time=time,
        base_position=clip.base_position[frames],
        base_quaternion_xyzw=clip.base_quaternion_xyzw[frames],
        joint_positions=clip.joint_positions[frames],
        source=clip.source,
        rate_hz=clip.rate_hz,
        contacts=None if clip.contacts is None else clip.contacts[frames],
    )
    return out


def gait_measures(rollout: Trajectory, data: Trajectory) -> dict[str, float]:
    """The rollout's planar base speed along the data's mean velocity over the data's speed,
    touchdowns per foot per 10 s, and the leg joints' RMSE (rad) against the data's."""
    velocity, _ = base_motion(rollout)
    data_velocity, _ = base_motion(data)
    mean = data_velocity.mean(axis=0)
    speed = float(np.linalg.norm(mean))
    duration = float(rollout.time[-1] - rollout.time[0]) or 1.0
    error = rollout.joint_positions[:, LEGS] - data.joint_positions[:, LEGS]
    return {
        "speed_ratio": ratio_along(velocity, mean) if speed > 0 else float("nan"),
        "touchdowns": float(touchdowns(rollout.contacts).mean() * 10.0 / duration),
        "leg_rmse": float(np.sqrt(np.mean(error**2))),
    }


def window_forcing(
    models_dir: Path, collection: Path, params: Params, seconds: float
) -> pd.DataFrame:
    """One row per model seed, clip (held-out and training) and mode, plus the clip's own."""
    splits = {
        "held_out": held_out_clips(collection, params),
        "training": training_clips(collection, params),
    }
    named = [(split, name, t) for split, clips in splits.items() for name, t in clips]
    from pimann.learn.model_files import load_model

    rows = []
    for seed, folder in model_seeds(models_dir).items():
        model, layout, stats, _ = load_model(folder)
        for split, name, trajectory in named:
            runs = forced_rollouts(model, layout, stats, trajectory, params, seconds)
            if runs is None:
                continue
            base = {
                "model": models_dir.name,
                "seed": seed,
                "split": split,
                "clip": name,
                "class": majority_class(class_counts(trajectory)),
            }
            data = runs["data"]
            rows.append({**base, "mode": "data", **gait_measures(data, data)})
            for mode in MODES:
                rows.append({**base, "mode": mode, **gait_measures(runs[mode], data)})
    return pd.DataFrame(rows)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_models_argument(parser)
    parser.add_argument("--seconds", type=float, default=8.0, help="rollout length at most")
    args = parser.parse_args(argv)

    def table_of(folders: list[Path]) -> pd.DataFrame:
        params = load_params()
        collection = REPO_ROOT / params.features.input
        return pd.concat(
            [window_forcing(folder, collection, params, args.seconds) for folder in folders],
            ignore_index=True,
        )

    table = table_over_models("window_forcing", args.models, table_of)
    if table is None:
        return 2
    summary = table.pivot_table(
        index=["model", "split", "class"],
        columns="mode",
        values=["speed_ratio", "touchdowns", "leg_rmse"],
        aggfunc="median",
    )
    with pd.option_context("display.width", 200, "display.max_rows", 500):
        print(summary.round(2).to_string())
    return 0


if __name__ == "__main__":
    sys.exit(main())
