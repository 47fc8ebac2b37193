"""Mirroring: an involution; turns change direction; forward kinematics commutes with it."""

from __future__ import annotations

import re

import numpy as np
import pytest
from builders import random_configuration
from scipy.spatial.transform import Rotation

from pimann.core.robot import JOINT_NAMES, SEGMENTS, mirror_joint_name
from pimann.core.trajectory import Trajectory
from pimann.mocap.human_motion import HumanMotion
from pimann.mocap.mirror import (
    mirror_human,
    mirror_points,
    mirror_rotations,
    mirror_segment_name,
    mirror_trajectory,
)

M = np.diag([1.0, -1.0, 1.0])


def random_motion(rng: np.random.Generator, n: int = 7) -> HumanMotion:
    rotations = Rotation.random(n * len(SEGMENTS), random_state=rng.integers(1 << 31))
    return HumanMotion(
        time=np.arange(n) / 100.0,
        orientations=rotations.as_matrix().reshape(n, len(SEGMENTS), 3, 3),
        segment_positions=rng.normal(size=(n, len(SEGMENTS), 3)),
        source="random",
    )


def random_trajectory(robot, rng: np.random.Generator, n: int = 6) -> Trajectory:
    configurations = [random_configuration(robot, rng) for _ in range(n)]
    parts = [robot.split_configuration(q) for q in configurations]
    return Trajectory(
        time=np.arange(n) / 50.0,
        base_position=np.array([p[0] for p in parts]),
        base_quaternion_xyzw=np.array([p[1] / np.linalg.norm(p[1]) for p in parts]),
        joint_positions=np.array([p[2] for p in parts]),
        source="random",
        rate_hz=50.0,
        contacts=rng.random((n, 2)) > 0.5,
        joint_velocities=rng.normal(size=(n, len(JOINT_NAMES))),
        com_position=rng.normal(size=(n, 3)),
        attrs={"seed": 3},
    )


def test_mirror_formulas_match_the_reflection(rng):
    rotations = Rotation.random(5, random_state=1).as_matrix()
    np.testing.assert_allclose(mirror_rotations(rotations), M @ rotations @ M, atol=1e-15)
    points = rng.normal(size=(5, 3))
    np.testing.assert_allclose(mirror_points(points), points @ M, atol=0)


def test_human_mirror_twice_is_identity(rng):
    motion = random_motion(rng)
    twice = mirror_human(mirror_human(motion))
    np.testing.assert_array_equal(twice.orientations, motion.orientations)
    np.testing.assert_array_equal(twice.segment_positions, motion.segment_positions)
    assert twice.mirrored is False
    assert mirror_human(motion).mirrored is True


def test_human_left_and_right_segments_swap(rng):
    motion = random_motion(rng)
    mirrored = mirror_human(motion)
    for name in SEGMENTS:
        other = mirror_segment_name(name)
        assert (other != name) == name.startswith(("Left", "Right"))
        np.testing.assert_allclose(mirrored.segment(other), M @ motion.segment(name) @ M)
        k, j = SEGMENTS.index(name), SEGMENTS.index(other)
        expected = motion.segment_positions[:, k] * [1, -1, 1]
        np.testing.assert_array_equal(mirrored.segment_positions[:, j], expected)
    # mirrored rotations stay proper rotations
    np.testing.assert_allclose(np.linalg.det(mirrored.orientations), 1.0, atol=1e-12)


def test_human_left_turn_becomes_right_turn():
    n = 11
    yaw = np.linspace(0.0, 1.2, n)  # turning left: yaw increasing
    pitch, roll = 0.2, 0.3
    rotation = Rotation.from_euler(
        "ZYX", np.column_stack([yaw, np.full(n, pitch), np.full(n, roll)])
    )
    matrices = np.repeat(rotation.as_matrix()[:, None], len(SEGMENTS), axis=1)
    positions = np.zeros((n, len(SEGMENTS), 3))
    positions[:, :, 0] = np.cos(yaw)[:, None]
    positions[:, :, 1] = np.sin(yaw)[:, None]
    motion = HumanMotion(np.arange(n) / 50.0, matrices, positions, "turn")
    mirrored = mirror_human(motion)
    angles = Rotation.from_matrix(mirrored.segment("Pelvis")).as_euler("ZYX")
    np.testing.assert_allclose(angles[:, 0], -yaw, atol=1e-12)  # same angle, to the right
    np.testing.assert_allclose(angles[:, 1], pitch, atol=1e-12)
    np.testing.assert_allclose(angles[:, 2], -roll, atol=1e-12)
    np.testing.assert_allclose(mirrored.pelvis_position[:, 1], -np.sin(yaw), atol=1e-15)


def test_trajectory_mirror_twice_is_identity(robot, rng):
    trajectory = random_trajectory(robot, rng)
    once = mirror_trajectory(trajectory)
    twice = mirror_trajectory(once)
    assert once.attrs["mirrored"] is True and twice.attrs["mirrored"] is False
    assert once.attrs["seed"] == 3 and "mirrored" not in trajectory.attrs
    for name in ("base_position", "base_quaternion_xyzw", "joint_positions", "joint_velocities"):
        np.testing.assert_array_equal(getattr(twice, name), getattr(trajectory, name))
    np.testing.assert_array_equal(twice.contacts, trajectory.contacts)
    np.testing.assert_array_equal(twice.com_position, trajectory.com_position)
    np.testing.assert_array_equal(once.contacts, trajectory.contacts[:, ::-1])
    np.testing.assert_array_equal(once.com_position[:, 1], -trajectory.com_position[:, 1])


def test_trajectory_joints_swap_and_central_roll_yaw_flip(robot, rng):
    trajectory = random_trajectory(robot, rng)
    mirrored = mirror_trajectory(trajectory)
    flipped = {"torso_roll", "torso_yaw", "neck_roll", "neck_yaw"}
    for k, name in enumerate(JOINT_NAMES):
        source = JOINT_NAMES.index(mirror_joint_name(name))
        sign = -1.0 if name in flipped else 1.0
        for field in ("joint_positions", "joint_velocities"):
            np.testing.assert_array_equal(
                getattr(mirrored, field)[:, k], sign * getattr(trajectory, field)[:, source]
            )


def test_trajectory_left_turn_becomes_right_turn(robot):
    n = 9
    yaw = np.linspace(0.0, 2.0, n)
    quaternion = Rotation.from_euler("ZYX", np.column_stack([yaw, 0.1 * yaw, 0.05 * yaw])).as_quat()
    trajectory = Trajectory(
        time=np.arange(n) / 50.0,
        base_position=np.zeros((n, 3)),
        base_quaternion_xyzw=quaternion,
        joint_positions=np.zeros((n, len(JOINT_NAMES))),
        source="turn",
        rate_hz=50.0,
    )
    mirrored = mirror_trajectory(trajectory)
    angles = Rotation.from_quat(mirrored.base_quaternion_xyzw).as_euler("ZYX")
    np.testing.assert_allclose(angles, np.column_stack([-yaw, 0.1 * yaw, -0.05 * yaw]), atol=1e-12)


def mirror_frame_name(name: str) -> str:
    return re.sub(r"Left|Right", lambda m: mirror_segment_name(m.group(0)), mirror_joint_name(name))


# Frames the study uses. The URDF rounds pi to 3.14 in both lower legs' `data_` frames
# (rpy="-3.14 0 0"), so their mirror differs by 2 * 0.0016 rad; everything else is exact.
FRAMES = ["root_link", "chest", "head", "l_sole", "l_upper_leg", "l_lower_leg", "l_upperarm"]
FRAMES += ["l_forearm", "l_foot_front", "l_foot_rear"] + [f"data_{s}" for s in SEGMENTS]
ROTATION_TOLERANCE = {"data_LeftLowerLeg": 4e-3, "data_RightLowerLeg": 4e-3}


def configuration(robot, trajectory: Trajectory, k: int = 0) -> np.ndarray:
    return robot.configuration(
        trajectory.base_position[k],
        trajectory.base_quaternion_xyzw[k],
        trajectory.joint_positions[k],
    )


@pytest.mark.parametrize("seed", range(4))
def test_trajectory_mirror_commutes_with_forward_kinematics(robot, seed):
    trajectory = random_trajectory(robot, np.random.default_rng(seed), n=1)
    q, q_mirrored = (
        configuration(robot, trajectory),
        configuration(robot, mirror_trajectory(trajectory)),
    )
    names = FRAMES + [mirror_frame_name(f) for f in FRAMES if mirror_frame_name(f) != f]
    assert "r_sole" in names and "data_RightFoot" in names
    for name in names:
        original = robot.frame_placement(q, name)
        image = robot.frame_placement(q_mirrored, mirror_frame_name(name))
        np.testing.assert_allclose(
            image.translation, M @ original.translation, atol=1e-6, err_msg=name
        )
        np.testing.assert_allclose(
            image.rotation,
            M @ original.rotation @ M,
            atol=ROTATION_TOLERANCE.get(name, 1e-5),
            err_msg=name,
        )
