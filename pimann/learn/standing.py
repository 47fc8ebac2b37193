"""The standing pose a rollout starts from and returns to on a stop.

ergoCub's nominal standing pose (pimann.core.robot.STANDING_JOINTS) is not how the retargeted
people stand: in the quick data the shoulders' yaw differs by 0.7 rad and hips and knees by
0.13-0.16 rad. A network started from the nominal pose jumps towards the data's pose in its
first step (0.3 rad of the shoulders in 20 ms), which shows as a base jump and a foot-pitch
dip at t = 0. The data's standing pose is the medoid of the training clips' standing frames
(pimann.learn.motion_classes): one real frame, so joints and base tilt belong together and its
retargeted feet are flat. The features stage computes it, training keeps it with the model
(meta.json "standing"), generation starts from it.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Iterable
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from pimann.core.robot import STANDING_BASE_QUATERNION_XYZW, STANDING_JOINTS
from pimann.core.rotations import roll_pitch
from pimann.core.trajectory import Trajectory
from pimann.learn.motion_classes import CLASSES, motion_classes

log = logging.getLogger(__name__)

MIN_STANDING_FRAMES = 50  # 1 s at 50 Hz: fewer, and the robot's nominal pose is kept
STANDING = CLASSES.index("standing")


def _roll_pitch(quaternions_xyzw: np.ndarray) -> np.ndarray:
    """(N, 2) roll and pitch of R = Rz(yaw) Ry(pitch) Rx(roll) (pinocchio's rpy)."""
    return roll_pitch(Rotation.from_quat(quaternions_xyzw).as_matrix())


@dataclasses.dataclass(frozen=True)
class StandingPose:
    """Joint positions and base roll, pitch (rad); yaw and position come from the rollout."""

    joints: np.ndarray
    roll_pitch: np.ndarray
    origin: str  # "robot" (nominal) or "data: N frames"

    @classmethod
    def nominal(cls) -> StandingPose:
        roll_pitch = _roll_pitch(np.asarray(STANDING_BASE_QUATERNION_XYZW)[None])[0]
        return cls(STANDING_JOINTS.copy(), roll_pitch, "robot")

    def to_json(self) -> dict[str, Any]:
        return {
            "joints": [float(v) for v in self.joints],
            "roll_pitch": [float(v) for v in self.roll_pitch],
            "origin": self.origin,
        }

    @classmethod
    def from_json(cls, raw: dict[str, Any] | None) -> StandingPose:
        """The pose a model was trained with; the nominal one when it recorded none."""
        if not raw:
            return cls.nominal()
        joints = np.asarray(raw["joints"], dtype=float)
        if joints.shape != STANDING_JOINTS.shape:
            raise ValueError(f"standing pose has {joints.size} joints, not {STANDING_JOINTS.size}")
        roll_pitch = np.asarray(raw["roll_pitch"], dtype=float)
        finite = np.isfinite(joints).all() and np.isfinite(roll_pitch).all()
        if roll_pitch.shape != (2,) or not finite:
            raise ValueError("standing pose needs finite joints and 2 finite roll, pitch angles")
        return cls(joints, roll_pitch, str(raw["origin"]))


def data_standing(clips: Iterable[Trajectory]) -> StandingPose:
    """The medoid (least L1 distance to the per-joint median) of the clips' standing frames."""
    joints, quaternions = [], []
    for trajectory in clips:
        standing = motion_classes(trajectory) == STANDING
        joints.append(np.asarray(trajectory.joint_positions)[standing])
        quaternions.append(np.asarray(trajectory.base_quaternion_xyzw)[standing])
    all_joints = np.concatenate(joints) if joints else np.empty((0, STANDING_JOINTS.size))
    if len(all_joints) < MIN_STANDING_FRAMES:
        log.info("%d standing frames in the data: the robot's nominal pose", len(all_joints))
        return StandingPose.nominal()
    medoid = int(np.argmin(np.abs(all_joints - np.median(all_joints, axis=0)).sum(axis=1)))
    roll_pitch = _roll_pitch(np.concatenate(quaternions)[medoid][None])[0]
    return StandingPose(all_joints[medoid].copy(), roll_pitch, f"data: {len(all_joints)} frames")
