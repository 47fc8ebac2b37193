"""The IK targets' pre-processing (pimann.retarget.targets), against scipy's rotations and
pinocchio's joint placements."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from scipy.spatial.transform import Rotation

from pimann.core.params import load_params
from pimann.core.robot import SEGMENTS
from pimann.mocap.human_motion import HumanMotion
from pimann.retarget.targets import (
    ARM_MARGIN,
    abduct_arms,
    hinge_elbows,
    min_arm_abduction,
    robot_leg_length,
    segment_targets,
    spread_legs,
)

T = 7


def _matrices(rng, n=T):
    return Rotation.random(n, random_state=rng).as_matrix()


def _about(axis, a):
    a = np.asarray(a, dtype=float)
    return Rotation.from_euler(axis, a[..., None]).as_matrix()  # (..., 3, 3)


def _rx(a):
    return _about("x", a)


def _rz(a):
    return _about("z", a)


def _k(name):
    return SEGMENTS.index(name)


def test_elbows_keep_only_the_flexion_about_the_upper_arms_z():
    rng = np.random.default_rng(0)
    targets = np.tile(np.eye(3), (T, len(SEGMENTS), 1, 1))
    upper_l, upper_r = _matrices(rng), _matrices(rng)
    flex = np.linspace(0.1, 1.5, T)
    swing = np.linspace(-0.6, 0.6, T)  # about x, perpendicular to the twist axis
    targets[:, _k("LeftUpperArm")], targets[:, _k("RightUpperArm")] = upper_l, upper_r
    targets[:, _k("LeftForeArm")] = upper_l @ _rx(swing) @ _rz(-flex)  # left flexes negative
    targets[:, _k("RightForeArm")] = upper_r @ _rx(swing) @ _rz(flex)
    hinge_elbows(targets)
    assert np.allclose(targets[:, _k("LeftForeArm")], upper_l @ _rz(-flex), atol=1e-9)
    assert np.allclose(targets[:, _k("RightForeArm")], upper_r @ _rz(flex), atol=1e-9)


def test_an_elbow_bent_backwards_is_kept_straight():
    rng = np.random.default_rng(1)
    targets = np.tile(np.eye(3), (T, len(SEGMENTS), 1, 1))
    upper = _matrices(rng)
    targets[:, _k("LeftUpperArm")] = upper
    targets[:, _k("LeftForeArm")] = upper @ _rz(0.7)  # the wrong way for the left elbow
    hinge_elbows(targets)
    assert np.allclose(targets[:, _k("LeftForeArm")], upper, atol=1e-9)


def _relative_roll(pelvis, segment):
    return Rotation.from_matrix(np.swapaxes(pelvis, -1, -2) @ segment).as_euler("ZYX")[..., 2]


def test_legs_closer_than_the_minimum_roll_spread_are_rolled_apart_evenly():
    rng = np.random.default_rng(2)
    pelvis = _rz(rng.uniform(-3, 3, T))
    rolls_l = np.array([0.0, 0.02, -0.05, 0.3, 0.0, 0.1, 0.04])
    rolls_r = np.array([0.0, -0.02, 0.0, -0.3, 0.05, 0.0, 0.1])
    targets = np.tile(np.eye(3), (T, len(SEGMENTS), 1, 1))
    targets[:, _k("Pelvis")] = pelvis
    for side, rolls in (("Left", rolls_l), ("Right", rolls_r)):
        for part in ("UpperLeg", "LowerLeg"):
            targets[:, _k(side + part)] = pelvis @ _rx(rolls)
    minimum = 0.1
    spread_legs(targets, minimum)
    new_l = _relative_roll(pelvis, targets[:, _k("LeftUpperLeg")])
    new_r = _relative_roll(pelvis, targets[:, _k("RightUpperLeg")])
    deficit = np.maximum(minimum - (rolls_l - rolls_r), 0.0)
    assert np.allclose(new_l, rolls_l + deficit / 2) and np.allclose(new_r, rolls_r - deficit / 2)
    assert np.all(new_l - new_r >= minimum - 1e-12)
    assert np.allclose(new_l[3], 0.3) and np.allclose(new_r[3], -0.3)  # wide apart: untouched
    # the shank turns with its thigh
    assert np.allclose(targets[:, _k("LeftLowerLeg")], targets[:, _k("LeftUpperLeg")])


def test_arms_too_close_to_the_chest_are_lifted_to_the_minimum_with_the_forearm():
    rng = np.random.default_rng(3)
    chest = _rz(rng.uniform(-3, 3, T))
    targets = np.tile(np.eye(3), (T, len(SEGMENTS), 1, 1))
    targets[:, _k("T8")] = chest
    abduction = np.array([0.0, 0.05, 0.2, 0.5, -0.1, 0.12, 0.0])
    bend = _rz(-0.9)
    # XSens frames: in the T-pose (abduction pi/2) an arm's frame is the chest's; hanging
    # down (abduction 0) the left arm is turned -pi/2 about x, the right one +pi/2
    for side, sign in (("Left", 1.0), ("Right", -1.0)):
        arm = chest @ _rx(sign * (abduction - np.pi / 2))
        targets[:, _k(side + "UpperArm")] = arm
        targets[:, _k(side + "ForeArm")] = arm @ bend
    minimum = 0.15
    abduct_arms(targets, minimum)
    for side in ("Left", "Right"):
        arm = targets[:, _k(side + "UpperArm")]
        lifted = np.arcsin(np.einsum("ti,ti->t", chest[:, :, 1], arm[:, :, 1]))
        assert np.allclose(lifted, np.maximum(abduction, minimum))
        relative = np.swapaxes(arm, -1, -2) @ targets[:, _k(side + "ForeArm")]
        assert np.allclose(relative, bend)  # the forearm moved with the upper arm


def test_the_robots_leg_length_is_its_joint_offsets(robot):
    model = robot.model
    names = ("l_hip_pitch", "l_hip_roll", "l_hip_yaw", "l_knee", "l_ankle_pitch")
    ids = [model.getJointId(n) for n in names]
    assert [model.parents[j] for j in ids[1:]] == ids[:-1]  # one chain, hip to ankle
    offsets = [model.jointPlacements[j] for j in ids[1:]]
    hip_to_knee = offsets[0] * offsets[1] * offsets[2]  # at zero joint angles
    length = np.linalg.norm(hip_to_knee.translation) + np.linalg.norm(offsets[3].translation)
    assert robot_leg_length(robot) == pytest.approx(length, rel=1e-9)
    assert 0.3 < length < 0.7  # a 1.6 m robot's thigh and shank
    assert isinstance(hip_to_knee, pin.SE3)


def test_the_arm_abduction_limit_grows_with_the_minimum_shoulder_roll():
    low, high = min_arm_abduction(0.05), min_arm_abduction(0.3)
    assert ARM_MARGIN < low < high < np.pi / 2


def test_flat_feet_and_the_head_from_t8():
    params = load_params().retarget
    assert params.flat_feet and params.head_from_t8
    rng = np.random.default_rng(4)
    orientations = np.stack([_matrices(rng) for _ in SEGMENTS], axis=1)
    motion = HumanMotion(np.arange(T) / 50.0, orientations, np.zeros((T, len(SEGMENTS), 3)), "x")
    targets = segment_targets(motion, params)
    for foot in ("LeftFoot", "RightFoot"):
        yaw = Rotation.from_matrix(orientations[:, _k(foot)]).as_euler("ZYX")[:, 0]
        assert np.allclose(targets[:, _k(foot)], _rz(yaw), atol=1e-9)  # heading kept, flat
    headings = np.tile([0.3, -0.2], (T, 1))
    planned = segment_targets(motion, params, sole_headings=headings)
    assert np.allclose(planned[:, _k("RightFoot")], _rz(-0.2), atol=1e-12)
    t8 = Rotation.from_matrix(targets[:, _k("T8")]).as_euler("ZYX")
    head = Rotation.from_matrix(targets[:, _k("Head")]).as_euler("ZYX")
    head_yaw = Rotation.from_matrix(orientations[:, _k("Head")]).as_euler("ZYX")[:, 0]
    # Rz(head yaw) Rz(-t8 yaw) R_t8: the T8's tilt, turned to the head's heading
    expected = _rz(head_yaw) @ _rz(-t8[:, 0]) @ targets[:, _k("T8")]
    assert np.allclose(targets[:, _k("Head")], expected, atol=1e-9)
    assert np.allclose(np.cos(head[:, 0] - head_yaw), 1.0)
    assert not np.allclose(targets, orientations)  # the input is not changed in place
    assert np.allclose(motion.orientations, orientations)
