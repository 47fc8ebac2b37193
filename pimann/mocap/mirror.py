"""Mirroring across the sagittal (x-z) plane: doubles the data with the other-handed motion.

The reflection is M = diag(1, -1, 1). A point p maps to M p; a frame's rotation R maps to
M R M (still a proper rotation: roll and yaw negated, pitch kept). The mirror image of the
left foot is the new right foot, so left and right are swapped as well.

A human motion is mirrored segment by segment (every XSens frame is x forward, y left, z up
in the T-pose, so M R M of a left segment is a valid right segment). A robot trajectory is
mirrored in joint space (docs/data.md): ergoCub's left and right limbs already have
mirrored joint axes, so the limb joints are only swapped; only the torso and neck roll and
yaw change sign. Forward kinematics of the result equals the mirror of every link.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from pimann.core.robot import JOINT_NAMES, SEGMENTS, mirror_joint_name
from pimann.core.trajectory import Trajectory
from pimann.mocap.human_motion import HumanMotion

REFLECTION = np.diag([1.0, -1.0, 1.0])
# Central joints whose axis lies in the sagittal plane (roll about x, yaw about z): they flip.
NEGATED_JOINTS = ("torso_roll", "torso_yaw", "neck_roll", "neck_yaw")


def mirror_segment_name(name: str) -> str:
    """`LeftFoot` <-> `RightFoot`; central segments unchanged."""
    if name.startswith("Left"):
        return "Right" + name[4:]
    if name.startswith("Right"):
        return "Left" + name[5:]
    return name


SEGMENT_PERMUTATION = np.array([SEGMENTS.index(mirror_segment_name(s)) for s in SEGMENTS])
JOINT_PERMUTATION = np.array([JOINT_NAMES.index(mirror_joint_name(j)) for j in JOINT_NAMES])
JOINT_SIGNS = np.array([-1.0 if j in NEGATED_JOINTS else 1.0 for j in JOINT_NAMES])


def mirror_points(points: np.ndarray) -> np.ndarray:
    """(..., 3) positions reflected: y -> -y."""
    return np.asarray(points) * np.array([1.0, -1.0, 1.0])


def mirror_rotations(rotations: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotation matrices R -> M R M (entries (0,1),(1,0),(1,2),(2,1) flip)."""
    signs = np.array([[1.0, -1.0, 1.0], [-1.0, 1.0, -1.0], [1.0, -1.0, 1.0]])
    return np.asarray(rotations) * signs


def mirror_quaternions_xyzw(quaternions: np.ndarray) -> np.ndarray:
    """(..., 4) xyzw quaternions of M R M: the axis a becomes -M a, so x and z flip."""
    return np.asarray(quaternions) * np.array([-1.0, 1.0, -1.0, 1.0])


def mirror_joints(joints: np.ndarray) -> np.ndarray:
    """(T, 26) joint positions or velocities of the mirrored robot, in the study's order."""
    return np.asarray(joints)[:, JOINT_PERMUTATION] * JOINT_SIGNS


def mirror_human(motion: HumanMotion) -> HumanMotion:
    """The same motion performed by the mirror-image person."""
    return HumanMotion(
        time=motion.time.copy(),
        orientations=mirror_rotations(motion.orientations[:, SEGMENT_PERMUTATION]),
        segment_positions=mirror_points(motion.segment_positions[:, SEGMENT_PERMUTATION]),
        source=motion.source,
        mirrored=not motion.mirrored,
        foot_points=None
        if motion.foot_points is None
        else mirror_points(motion.foot_points[:, ::-1]),
    )


def mirror_trajectory(trajectory: Trajectory) -> Trajectory:
    """The robot trajectory of the mirrored motion (time, rate and source kept)."""
    attrs = dict(trajectory.attrs)
    attrs["mirrored"] = not bool(attrs.get("mirrored", False))
    optional = {
        "contacts": None if trajectory.contacts is None else trajectory.contacts[:, ::-1].copy(),
        "joint_velocities": None
        if trajectory.joint_velocities is None
        else mirror_joints(trajectory.joint_velocities),
        "com_position": None
        if trajectory.com_position is None
        else mirror_points(trajectory.com_position),
    }
    return dataclasses.replace(
        trajectory,
        time=trajectory.time.copy(),
        base_position=mirror_points(trajectory.base_position),
        base_quaternion_xyzw=mirror_quaternions_xyzw(trajectory.base_quaternion_xyzw),
        joint_positions=mirror_joints(trajectory.joint_positions),
        attrs=attrs,
        **optional,
    )
