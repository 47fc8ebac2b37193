"""Contact-consistent trajectories (pimann.generate.contact_consistent): a glide removed, the
swing untouched, the leg IK checked against pinocchio's forward kinematics."""

from __future__ import annotations

import dataclasses

import numpy as np
import pinocchio as pin
import pytest
from builders import GaitModel, roll

from pimann.core.contacts import foot_kinematics, trajectory_configurations, true_runs
from pimann.core.params import MotionSegment, load_params
from pimann.core.robot import LEFT_SOLE, LEG_JOINTS, RIGHT_SOLE
from pimann.generate.contact_consistent import LegSolver, make_consistent

GLIDE = 0.03  # m the base (and so every foot on the floor) is pushed during one stance


@pytest.fixture(scope="module")
def params():
    return load_params()


@pytest.fixture(scope="module")
def gait(robot, params):
    """A stepping rollout of the analytic gait model (crouched legs: every sole reachable)."""
    script = [MotionSegment(4.0, 0.4, 0.0, 0.0)]
    return roll(GaitModel(robot), script, params, False, robot).trajectory


def _glide(trajectory, start: int, stop: int):
    """The trajectory with its base pushed GLIDE m sideways over frames start..stop (then kept
    there): every foot on the floor then glides GLIDE m."""
    push = np.clip((np.arange(len(trajectory)) - start) / (stop - start), 0.0, 1.0)
    base = trajectory.base_position.copy()
    base[:, 1] += GLIDE * push
    return dataclasses.replace(trajectory, base_position=base)


def _world_soles(robot, trajectory):
    feet = foot_kinematics(robot, trajectory_configurations(robot, trajectory))
    return feet.positions, feet.rotations


def test_a_glide_is_removed_and_the_swing_untouched(robot, params, gait):
    runs = [(a, b) for a, b in true_runs(gait.contacts[:, 0]) if a > 50 and b - a >= 20]
    start, stop = runs[0][0] + 6, runs[0][1] - 6  # inside a left stance, off its blends
    raw = _glide(gait, start, stop)
    out = make_consistent(raw, robot, params.rollout.consistent, params.contacts)
    trajectory = out.trajectory
    positions, rotations = _world_soles(robot, trajectory)
    raw_positions, raw_rotations = _world_soles(robot, raw)
    held = out.weights.min(axis=-1) >= 1.0  # (T, 2) both weights 1: the foot is held
    # the raw left sole glides the push; ours stays within 1 mm over the whole stance
    stance = np.arange(start, stop + 1)
    assert held[stance, 0].all()
    raw_travel = np.linalg.norm(raw_positions[stance, 0] - raw_positions[start, 0], axis=1)
    assert raw_travel.max() > 0.9 * GLIDE
    for foot in (0, 1):
        for a, b in true_runs(held[:, foot]):
            drift = np.linalg.norm(positions[a:b, foot] - positions[a, foot], axis=1)
            assert drift.max() < 1e-3, (foot, a, b, drift.max())
            # flat on the floor, yaw kept
            np.testing.assert_allclose(positions[a:b, foot, 2], 0.0, atol=1e-3)
            np.testing.assert_allclose(rotations[a:b, foot, 2, 2], 1.0, atol=1e-6)
    assert out.residual[held].max() < params.rollout.consistent.tolerance
    # a foot the hold leaves alone (both weights 0) is the network's to rounding
    free = out.weights.max(axis=-1) <= 0.0
    assert free.sum() > 50
    np.testing.assert_allclose(positions[free], raw_positions[free], atol=1e-9)
    np.testing.assert_allclose(rotations[free], raw_rotations[free], atol=1e-9)
    # the base and every joint but the legs' untouched
    others = np.setdiff1d(np.arange(26), LEG_JOINTS)
    np.testing.assert_array_equal(
        trajectory.joint_positions[:, others], raw.joint_positions[:, others]
    )
    np.testing.assert_array_equal(trajectory.base_position, raw.base_position)
    # joint velocities: the network's plus the correction's change, so a free leg keeps its own
    correction = trajectory.joint_positions - raw.joint_positions
    expected = raw.joint_velocities[1:] + np.diff(correction, axis=0) * raw.rate_hz
    np.testing.assert_allclose(trajectory.joint_velocities[1:], expected, atol=1e-9)
    # no joint jumps at touchdown and lift-off: the correction changes smoothly
    assert np.abs(np.diff(correction, axis=0)).max() < 0.1
    assert trajectory.attrs["consistent"] == "post"


def test_the_sliding_falls_where_the_feet_glide(robot, params, gait):
    from pimann.evaluate.metrics import trajectory_metrics

    raw = _glide(gait, 60, 160)  # a slow glide over several stances
    out = make_consistent(raw, robot, params.rollout.consistent, params.contacts).trajectory
    before = trajectory_metrics(raw, robot, params.evaluate, params.contacts)
    after = trajectory_metrics(out, robot, params.evaluate, params.contacts)
    key = "support_rmse_linear_position_total"
    assert after[key] < 0.8 * before[key], (before[key], after[key])


def test_leg_ik_reaches_pinocchio_placements(robot, params):
    """Soles of perturbed legs (pinocchio FK, base at the origin) reached from the standing
    legs within 1e-6 m and 1e-6 rad."""
    rng = np.random.default_rng(3)
    standing = robot.split_configuration(robot.standing_configuration())[2]
    start = np.tile(standing, (8, 1))
    goal = start.copy()
    goal[:, LEG_JOINTS] += rng.uniform(-0.15, 0.15, size=(8, 12))
    goal[:, [3, 9]] = np.minimum(goal[:, [3, 9]], -0.2)  # knees bent: away from the limit
    targets = np.empty((8, 2, 4, 4))
    for row, joints in enumerate(goal):
        q = robot.configuration([0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0], joints)
        for foot, frame in enumerate((LEFT_SOLE, RIGHT_SOLE)):
            targets[row, foot] = robot.frame_placement(q, frame).homogeneous
    solver = LegSolver(robot, dataclasses.replace(params.rollout.consistent, tolerance=1e-7))
    solution = solver.solve(start, targets, np.ones((8, 2), dtype=bool))
    for row, joints in enumerate(solution.joints):
        q = robot.configuration([0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0], joints)
        for foot, frame in enumerate((LEFT_SOLE, RIGHT_SOLE)):
            error = pin.log6(robot.frame_placement(q, frame).actInv(pin.SE3(targets[row, foot])))
            assert np.abs(error.vector).max() < 1e-6, (row, foot, error.vector)
    assert solution.residual.max() < 1e-6
