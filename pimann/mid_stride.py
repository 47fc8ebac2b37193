"""Gait sustainment: does a trained model keep walking in a gait it is started in?

Teacher forcing (pimann.teacher_forcing) feeds a model the data's inputs at every step; a
rollout feeds it its own from a standing start. This sits between the two: each held-out
clip's state at its middle frame (joints, joint velocities, base roll and pitch) starts an
unsteered rollout under the clip's own base motion there, held as one command. Beside it the
same command from the model's standing pose. A model that walks from both is fine; one that
walks from mid-stride only fails to start; one that walks from neither cannot sustain the
gait, however it starts. Run after `dvc repro` (it reads models/ and data/retargeted):

    python -m pimann.mid_stride [--models models] [--seconds 10]

prints per model, seed and motion class (the clip's at its middle frame): the commanded
speed, and from each start the ratio of the speed the legs achieve (leg odometry, along the
command, after the first 2 s) to it, and the touchdowns per foot.
"""

from __future__ import annotations

import argparse
import functools
import sys
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.spatial.transform import Rotation

from pimann.benchmark_clips import held_out_clips
from pimann.command_following import touchdowns
from pimann.motion_classes import CLASSES, base_motion, classify
from pimann.params import MotionSegment, Params, load_params
from pimann.paths import REPO_ROOT
from pimann.rollout_layout import model_seeds
from pimann.standing import StandingPose
from pimann.steering import roll_pitch
from pimann.teacher_forcing import add_models_argument, table_over_models
from pimann.trajectory import Trajectory

SETTLE_S = 2.0  # s left out at the start of each rollout before its speed is measured
MOVING = ("forward", "backward", "side", "diagonal", "turning")


def clip_start(trajectory: Trajectory, seconds: float):
    """(class, command, start pose, joint velocities) at a clip's middle frame."""
    velocity, yaw_rate = base_motion(trajectory)
    mid = len(trajectory.time) // 2
    name = CLASSES[classify(velocity[mid : mid + 1], yaw_rate[mid : mid + 1])[0]]
    command = MotionSegment(seconds, float(velocity[mid, 0]), float(velocity[mid, 1]),
                            float(yaw_rate[mid]))  # fmt: skip
    rotation = Rotation.from_quat(trajectory.base_quaternion_xyzw[mid : mid + 1]).as_matrix()
    pose = StandingPose(trajectory.joint_positions[mid].copy(), roll_pitch(rotation)[0],
                        "mid-stride")  # fmt: skip
    joint_velocities = np.gradient(trajectory.joint_positions, trajectory.time, axis=0)[mid]
    return name, command, pose, joint_velocities


def achieved(trajectory: Trajectory, command: MotionSegment) -> tuple[float, float]:
    """(achieved speed / commanded speed along the command after SETTLE_S, touchdowns per
    foot per 10 s, the feet averaged)."""
    velocity, _ = base_motion(trajectory)
    settled = trajectory.time >= SETTLE_S
    wanted = np.array([command.vx, command.vy])
    speed = float(np.linalg.norm(wanted))
    along = velocity[settled] @ (wanted / speed) if speed > 0 else np.zeros(settled.sum())
    per_foot = touchdowns(trajectory.contacts).mean()
    return float(along.mean()) / speed, float(per_foot * 10.0 / trajectory.time[-1])


def sustainment(models_dir: Path, collection: Path, params: Params, seconds: float) -> pd.DataFrame:
    """One row per model seed and held-out clip of `collection` (the features stage's split)
    in motion at its middle frame."""
    from pimann.generate import RolloutSpec, generate_batch
    from pimann.model_files import load_model

    starts = [(name, *clip_start(t, seconds)) for name, t in held_out_clips(collection, params)]
    starts = [start for start in starts if start[1] in MOVING]
    rows = []
    for seed, folder in model_seeds(models_dir).items():
        model, layout, stats, meta = load_model(folder)
        roll = functools.partial(generate_batch, model, layout, stats, params=params.rollout,
                                 contact_params=params.evaluate)  # fmt: skip
        # from standing: every clip's command in one batch; from mid-stride: one start each
        standing = StandingPose.from_json(meta.get("standing"))
        from_stand = roll([RolloutSpec([start[2]], False) for start in starts], standing=standing)
        for (clip, motion_class, command, pose, velocities), stand in zip(
            starts, from_stand, strict=True
        ):
            (mid,) = roll([RolloutSpec([command], False)], standing=pose,
                          start_joint_velocities=velocities)  # fmt: skip
            row = {"model": models_dir.name, "seed": seed, "clip": clip, "class": motion_class,
                   "speed": float(np.hypot(command.vx, command.vy))}  # fmt: skip
            for start, rollout in (("mid", mid), ("stand", stand)):
                ratio, count = achieved(rollout.trajectory, command)
                row[f"ratio_{start}"], row[f"touchdowns_{start}"] = ratio, count
            rows.append(row)
    return pd.DataFrame(rows)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_models_argument(parser)
    parser.add_argument("--seconds", type=float, default=10.0, help="rollout length")
    args = parser.parse_args(argv)

    def starts(folders: list[Path]) -> pd.DataFrame:
        params = load_params()
        collection = REPO_ROOT / params.features.input
        frames = [sustainment(folder, collection, params, args.seconds) for folder in folders]
        return pd.concat(frames, ignore_index=True)

    table = table_over_models("mid_stride", args.models, starts)
    if table is None:
        return 2
    summary = table.groupby(["model", "class"]).agg(
        clips=("clip", "nunique"), speed=("speed", "median"),
        ratio_mid=("ratio_mid", "median"), ratio_stand=("ratio_stand", "median"),
        touchdowns_mid=("touchdowns_mid", "median"),
        touchdowns_stand=("touchdowns_stand", "median"),
    )  # fmt: skip
    with pd.option_context("display.width", 160, "display.max_rows", 500):
        print(summary.round(2).to_string())
    return 0


if __name__ == "__main__":
    sys.exit(main())
