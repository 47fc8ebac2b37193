"""The ergoCub model: joint order, frames, forward kinematics and Jacobians."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from builders import random_configuration

from pimann.core.errors import PimannError
from pimann.core.robot import JOINT_NAMES, SEGMENTS, STANDING_JOINTS, load_robot

URDF_ORDER = (
    "l_hip_pitch l_hip_roll l_hip_yaw l_knee l_ankle_pitch l_ankle_roll "
    "r_hip_pitch r_hip_roll r_hip_yaw r_knee r_ankle_pitch r_ankle_roll "
    "torso_pitch torso_roll torso_yaw neck_pitch neck_roll neck_yaw "
    "l_shoulder_pitch l_shoulder_roll l_shoulder_yaw l_elbow "
    "r_shoulder_pitch r_shoulder_roll r_shoulder_yaw r_elbow"
).split()


def test_joint_order_is_spec(robot):
    assert list(JOINT_NAMES) == URDF_ORDER
    assert robot.model.nq == 7 + 26 and robot.model.nv == 6 + 26
    # the study's order maps by name onto pinocchio's joints
    for k, name in enumerate(URDF_ORDER):
        joint = robot.model.joints[robot.model.getJointId(name)]
        assert robot.q_index[k] == joint.idx_q and robot.v_index[k] == joint.idx_v


def test_configuration_round_trip(robot, rng):
    joints = rng.uniform(robot.joint_lower, robot.joint_upper)
    quaternion = np.array([0.1, -0.2, 0.3, 0.9])
    q = robot.configuration([1, 2, 3], quaternion, joints)
    position, quat, back = robot.split_configuration(q)
    np.testing.assert_allclose(back, joints)
    np.testing.assert_allclose(quat, quaternion / np.linalg.norm(quaternion))
    np.testing.assert_allclose(position, [1, 2, 3])


def test_frames_and_standing_pose(robot):
    for frame in ["l_sole", "r_sole", "chest", "root_link", *(f"data_{s}" for s in SEGMENTS)]:
        robot.frame_id(frame)
    q = robot.standing_configuration()
    left, right = robot.frame_placement(q, "l_sole"), robot.frame_placement(q, "r_sole")
    # standing: both soles near the floor, left foot on the left
    assert abs(left.translation[2]) < 0.01 and abs(right.translation[2]) < 0.01
    assert left.translation[1] > 0.05 > -0.05 > right.translation[1]
    assert np.all(STANDING_JOINTS >= robot.joint_lower) and np.all(
        STANDING_JOINTS <= robot.joint_upper
    )
    assert 50 < robot.total_mass < 60  # ergoCub ~56 kg


def test_unknown_frame_is_named(robot):
    with pytest.raises(PimannError, match="no frame named 'l_sol'"):
        robot.frame_id("l_sol")


def test_sole_jacobian_matches_finite_differences(robot, rng):
    """J maps [body twist, joint rates] to the sole's body twist: check it by integrating q."""
    for _ in range(3):
        q = random_configuration(robot, rng)
        jacobian = robot.frame_jacobian(q, "l_sole", pin.LOCAL)
        eps = 1e-6
        for column in range(6 + 26):
            v_study = np.zeros(32)
            v_study[column] = 1.0
            v = np.zeros(32)
            v[robot.velocity_order] = v_study
            before = robot.frame_placement(q, "l_sole")
            after = robot.frame_placement(pin.integrate(robot.model, q, eps * v), "l_sole")
            numeric = pin.log6(before.actInv(after)).vector / eps
            np.testing.assert_allclose(jacobian[:, column], numeric, atol=1e-5)


def test_knee_moves_only_its_leg(robot):
    """Raising l_knee only moves frames below the knee: the pelvis frame stays put."""
    q = robot.standing_configuration()
    joints = STANDING_JOINTS.copy()
    joints[JOINT_NAMES.index("l_knee")] -= 0.5
    q_bent = robot.configuration(q[:3], q[3:7], joints)
    np.testing.assert_allclose(
        robot.frame_placement(q, "data_Pelvis").translation,
        robot.frame_placement(q_bent, "data_Pelvis").translation,
    )
    moved = (
        robot.frame_placement(q_bent, "l_sole").translation
        - robot.frame_placement(q, "l_sole").translation
    )
    assert np.linalg.norm(moved) > 0.05
    np.testing.assert_allclose(
        robot.frame_placement(q, "r_sole").translation,
        robot.frame_placement(q_bent, "r_sole").translation,
    )


def test_unknown_variant():
    with pytest.raises(PimannError, match="unknown robot variant"):
        load_robot("nao")
