"""Gait sustainment: does a trained model keep walking in a gait it is started in?

Teacher forcing (diagnostics.teacher_forcing) feeds a model the data's inputs at every step; a
rollout feeds it its own from a standing start. This sits between the two: each held-out
clip's state at its middle frame (joints, joint velocities, base roll and pitch) starts a
rollout (unsteered; `--steering`: steered) under the clip's own base motion there, held as
one command. Beside it the same command from the model's standing pose. A model that walks
from both is fine; one that walks from mid-stride only fails to start; one that walks from
neither cannot sustain the gait, however it starts. Run after `dvc repro` (it reads models/
and data/retargeted):

    python -m diagnostics.mid_stride [--models models] [--seconds 10] [--steering]

prints per model, seed and motion class (the clip's at its middle frame): the commanded
speed, and from each start the ratio of the speed the legs achieve (leg odometry, along the
command, after the first 2 s) to it, and the touchdowns per foot. Beside them, whether the
network or its legs fail: the ratio of the network's own base velocity (the one fed back) to
the command, and how well its two joint outputs agree on the legs (the correlation of the
predicted joint velocities with the differences of the predicted joints; 1: they agree). A
network that holds the commanded velocity while its legs do not step has lost the gait in its
joint outputs, not in its velocity.
"""

from __future__ import annotations

import argparse
import functools
import sys
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd
from scipy.spatial.transform import Rotation

from diagnostics.teacher_forcing import add_models_argument, table_over_models
from pimann.core.contacts import touchdowns
from pimann.core.params import MotionSegment, Params, load_params
from pimann.core.paths import REPO_ROOT
from pimann.core.robot import LEG_JOINTS as LEGS
from pimann.core.rotations import roll_pitch, to_heading_frame, yaw_of
from pimann.core.trajectory import Trajectory
from pimann.generate.benchmark_clips import held_out_clips
from pimann.learn.model_files import model_seeds
from pimann.learn.motion_classes import CLASSES, base_motion, classify
from pimann.learn.standing import StandingPose

if TYPE_CHECKING:
    from pimann.generate.rollout_batch import Rollout

SETTLE_S = 2.0  # s left out at the start of each rollout before its speed is measured
MOVING = ("forward", "backward", "side", "diagonal", "turning")


def clip_start(trajectory: Trajectory, seconds: float):
    """(class, command, start pose, joint velocities) at a clip's middle frame."""
    velocity, yaw_rate = base_motion(trajectory)
    mid = len(trajectory.time) // 2
    name = CLASSES[classify(velocity[mid : mid + 1], yaw_rate[mid : mid + 1])[0]]
    command = MotionSegment(
        seconds, float(velocity[mid, 0]), float(velocity[mid, 1]), float(yaw_rate[mid])
    )
    rotation = Rotation.from_quat(trajectory.base_quaternion_xyzw[mid : mid + 1]).as_matrix()
    pose = StandingPose(
        trajectory.joint_positions[mid].copy(), roll_pitch(rotation)[0], "mid-stride"
    )
    joint_velocities = np.gradient(trajectory.joint_positions, trajectory.time, axis=0)[mid]
    return name, command, pose, joint_velocities


def achieved(trajectory: Trajectory, command: MotionSegment) -> tuple[float, float]:
    """(achieved speed / commanded speed along the command after SETTLE_S, touchdowns per
    foot per 10 s, the feet averaged)."""
    velocity, _ = base_motion(trajectory)
    per_foot = touchdowns(trajectory.contacts).mean()
    ratio = _ratio_along(velocity[trajectory.time >= SETTLE_S], command)
    return ratio, float(per_foot * 10.0 / trajectory.time[-1])


def _ratio_along(velocity: np.ndarray, command: MotionSegment) -> float:
    """Mean of heading-frame velocities (T, 2) along the command over the command's speed."""
    return ratio_along(velocity, np.array([command.vx, command.vy]))


def ratio_along(velocity: np.ndarray, wanted: np.ndarray) -> float:
    """Mean of planar velocities (T, 2) along `wanted` (2,) over its norm."""
    speed = float(np.linalg.norm(wanted))
    along = velocity @ (wanted / speed) if speed > 0 else np.zeros(len(velocity))
    return float(along.mean()) / speed


def network_ratio(rollout: Rollout, command: MotionSegment) -> float:
    """The network's own base velocity along the command over the command's speed, after
    SETTLE_S (the generator's fed-back velocity, in each frame's heading frame)."""
    if command.vx == 0 and command.vy == 0:
        return float("nan")
    trajectory = rollout.trajectory
    settled = trajectory.time >= SETTLE_S
    yaw = yaw_of(Rotation.from_quat(trajectory.base_quaternion_xyzw[settled]).as_matrix())
    world = rollout.base_velocity[settled]
    return _ratio_along(to_heading_frame(world[:, :2], yaw), command)


def leg_joint_agreement(trajectory: Trajectory) -> float:
    """Correlation, after SETTLE_S, of the legs' predicted joint velocities with the central
    differences of the predicted leg joints (NaN when either is constant)."""
    settled = np.flatnonzero(trajectory.time >= SETTLE_S)
    inner = settled[(settled > 0) & (settled < len(trajectory.time) - 1)]
    joints = trajectory.joint_positions[:, LEGS]
    differences = (joints[inner + 1] - joints[inner - 1]) / (
        trajectory.time[inner + 1] - trajectory.time[inner - 1]
    )[:, None]
    predicted = trajectory.joint_velocities[inner][:, LEGS]
    if differences.std() == 0 or predicted.std() == 0:
        return float("nan")
    return float(np.corrcoef(predicted.ravel(), differences.ravel())[0, 1])


def sustainment(
    models_dir: Path, collection: Path, params: Params, seconds: float, steering: bool = False
) -> pd.DataFrame:
    """One row per model seed and held-out clip of `collection` (the features stage's split)
    in motion at its middle frame; `steering`: the rollouts steered (rollout.k0, k1)."""
    from pimann.generate.rollout_batch import RolloutSpec, generate_batch
    from pimann.learn.model_files import load_model

    starts = [(name, *clip_start(t, seconds)) for name, t in held_out_clips(collection, params)]
    starts = [start for start in starts if start[1] in MOVING]
    rows = []
    for seed, folder in model_seeds(models_dir).items():
        model, layout, stats, meta = load_model(folder)
        roll = functools.partial(
            generate_batch,
            model,
            layout,
            stats,
            params=params.rollout,
            contact_params=params.contacts,
        )
        # from standing: every clip's command in one batch; from mid-stride: one start each
        standing = StandingPose.from_json(meta.get("standing"))
        specs = [RolloutSpec([start[2]], steering) for start in starts]
        from_stand = roll(specs, standing=standing)
        for (clip, motion_class, command, pose, velocities), stand in zip(
            starts, from_stand, strict=True
        ):
            (mid,) = roll(
                [RolloutSpec([command], steering)], standing=pose, start_joint_velocities=velocities
            )
            row = {
                "model": models_dir.name,
                "seed": seed,
                "clip": clip,
                "class": motion_class,
                "speed": float(np.hypot(command.vx, command.vy)),
            }
            for start, rollout in (("mid", mid), ("stand", stand)):
                ratio, count = achieved(rollout.trajectory, command)
                row[f"ratio_{start}"], row[f"touchdowns_{start}"] = ratio, count
                row[f"network_{start}"] = network_ratio(rollout, command)
                row[f"agreement_{start}"] = leg_joint_agreement(rollout.trajectory)
            rows.append(row)
    return pd.DataFrame(rows)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_models_argument(parser)
    parser.add_argument("--seconds", type=float, default=10.0, help="rollout length")
    parser.add_argument("--steering", action="store_true", help="steered rollouts")
    args = parser.parse_args(argv)

    def starts(folders: list[Path]) -> pd.DataFrame:
        params = load_params()
        collection = REPO_ROOT / params.features.input
        frames = [
            sustainment(folder, collection, params, args.seconds, args.steering)
            for folder in folders
        ]
        return pd.concat(frames, ignore_index=True)

    table = table_over_models("mid_stride", args.models, starts)
    if table is None:
        return 2
    summary = table.groupby(["model", "class"]).agg(
        clips=("clip", "nunique"),
        speed=("speed", "median"),
        ratio_mid=("ratio_mid", "median"),
        ratio_stand=("ratio_stand", "median"),
        touchdowns_mid=("touchdowns_mid", "median"),
        touchdowns_stand=("touchdowns_stand", "median"),
        network_mid=("network_mid", "median"),
        network_stand=("network_stand", "median"),
        agreement_mid=("agreement_mid", "median"),
        agreement_stand=("agreement_stand", "median"),
    )
    with pd.option_context("display.width", 160, "display.max_rows", 500):
        print(summary.round(2).to_string())
    return 0


if __name__ == "__main__":
    sys.exit(main())
