"""The generated CoM mapped onto the footstep plan, and the DCM plan pulled toward it."""

from __future__ import annotations

import dataclasses

import numpy as np
import pinocchio as pin
import pytest

from pimann.core.errors import PimannError
from pimann.core.robot import JOINT_NAMES, LEFT_SOLE, RIGHT_SOLE
from pimann.core.rotations import rot_z
from pimann.core.trajectory import Trajectory
from pimann.sim.closed_loop import simulate_trajectory
from pimann.sim.com_reference import com_reference
from pimann.sim.dcm import knot_times, lipm_matrices, lipm_residual, plan_dcm
from pimann.sim.footsteps import extract_footsteps, relative
from pimann.sim.synthetic import stepping_plan, stepping_trajectory

WEIGHT = 1.0  # the tests' own CoM weight (params.yaml's today), not read from params.yaml


@pytest.fixture(scope="module")
def stepping(sim_robot, sim_params, stance):
    """A synthetic 4-step walk, its footstep plan at the paper's scaling, and the reference."""
    source = stepping_plan(stance[1], steps=4, step=0.2, single=0.5, double=0.15)
    trajectory = stepping_trajectory(sim_robot, sim_params, source)
    plan = extract_footsteps(sim_robot, trajectory, sim_params, stance[1])
    times = knot_times(plan, sim_params)
    return trajectory, plan, times, com_reference(sim_robot, trajectory, plan, sim_params, times)


def _standing_trajectory(robot, q: np.ndarray, yaw: float, shift, frames: int = 40) -> Trajectory:
    """q held still, the whole body turned by yaw about z and shifted: feet flat, both down."""
    turn = rot_z(yaw)
    base = pin.XYZQUATToSE3(q[:7])
    quaternion = pin.Quaternion(turn @ base.rotation).coeffs()  # x, y, z, w
    return Trajectory(
        time=np.arange(frames) / 50.0,
        base_position=np.tile(turn @ base.translation + shift, (frames, 1)),
        base_quaternion_xyzw=np.tile(quaternion, (frames, 1)),
        joint_positions=np.tile(q[robot.q_index], (frames, 1)),
        source="standing",
        rate_hz=50.0,
        contacts=np.ones((frames, 2), bool),
    )


def _mid_feet(feet: np.ndarray) -> np.ndarray:
    return np.array([*feet[:, :2].mean(axis=0), np.angle(np.exp(1j * feet[:, 2]).mean())])


def test_standing_gives_the_mid_feet_point(sim_robot, sim_params, stance):
    """Upright standing (CoM over the feet's midpoint) anywhere in the world: the robot's own."""
    q0, feet = stance
    trajectory = _standing_trajectory(sim_robot, q0, 0.7, [1.0, -2.0, 0.0])
    plan = extract_footsteps(sim_robot, trajectory, sim_params, feet)
    times = knot_times(plan, sim_params)
    reference = com_reference(sim_robot, trajectory, plan, sim_params, times)
    assert reference.shape == (len(times), 2)
    # the standing pose's CoM sits within 0.1 mm of the feet's midpoint
    np.testing.assert_allclose(
        reference, np.tile(feet[:, :2].mean(axis=0), (len(times), 1)), atol=1e-4
    )


def test_leaning_offset_scaled_forward_kept_sideways(sim_robot, sim_params, stance):
    """A leaning pose turned in the world: offset in the feet's frame, x scaled, y kept."""
    q0, feet = stance
    q = q0.copy()
    for name, angle in (("torso_pitch", 0.5), ("torso_roll", 0.3)):
        q[sim_robot.q_index[JOINT_NAMES.index(name)]] += angle
    trajectory = _standing_trajectory(sim_robot, q, -0.5, [0.3, 0.4, 0.0])
    robot_feet = feet.copy()
    robot_feet[:, :2] += [0.2, 0.1]  # the robot stands elsewhere, turned
    robot_feet[:, 2] = 0.3
    robot_feet[:, :2] = robot_feet[:, :2] @ rot_z(0.3)[:2, :2].T
    plan = extract_footsteps(sim_robot, trajectory, sim_params, robot_feet)
    times = knot_times(plan, sim_params)
    reference = com_reference(sim_robot, trajectory, plan, sim_params, times)
    # independent: pinocchio's CoM and sole placements of the turned, shifted pose
    q_world = sim_robot.configuration(
        trajectory.base_position[0], trajectory.base_quaternion_xyzw[0], q[sim_robot.q_index]
    )
    com = pin.centerOfMass(sim_robot.model, sim_robot.data, q_world)
    soles = [sim_robot.frame_placement(q_world, f) for f in (LEFT_SOLE, RIGHT_SOLE)]
    generated = _mid_feet(
        np.array(
            [[*s.translation[:2], np.arctan2(s.rotation[1, 0], s.rotation[0, 0])] for s in soles]
        )
    )
    offset = relative(generated, np.array([*com[:2], generated[2]]))[:2]
    assert abs(offset[0]) > 0.015 and abs(offset[1]) > 0.015  # a real lean, both ways
    mid = _mid_feet(robot_feet)
    expected = mid[:2] + rot_z(mid[2])[:2, :2] @ (offset * [sim_params.step_scale, 1.0])
    replaying = (times > plan.hold + 1e-9) & (times < plan.duration - sim_params.end_hold_s)
    np.testing.assert_allclose(
        reference[replaying], np.tile(expected, (replaying.sum(), 1)), atol=1e-9
    )
    # the holds: standing on the mid-feet point, faded in over the hold's last 0.5 s
    before = times < plan.hold - 0.5 - 1e-9
    after = times > plan.duration - sim_params.end_hold_s + 0.5 + 1e-9
    assert before.sum() > 50 and after.sum() > 30
    np.testing.assert_allclose(
        reference[before | after], np.tile(mid[:2], (before.sum() + after.sum(), 1)), atol=1e-12
    )
    # no step: smoothstep's slope is at most 1.5 / 0.5 s, so 3 % of the offset per 0.01 s knot
    steps = np.linalg.norm(np.diff(reference, axis=0), axis=1)
    scaled = np.linalg.norm(offset * [sim_params.step_scale, 1.0])
    assert steps.max() <= 1.5 * sim_params.plan_dt / 0.5 * scaled + 1e-12


def test_reference_follows_the_generated_walk(sim_robot, sim_params, stepping):
    """Continuous, near the planned feet, and at a replayed frame the frame's own CoM offset."""
    trajectory, plan, times, reference = stepping
    assert np.isfinite(reference).all()
    # < 1 m/s: the synthetic CoM target itself jumps toward the support at each contact
    # switch, spread over one generated frame (6 knots at 0.33x); a jump in the mapping
    # (an offset switched on at once) would be centimetres
    assert np.linalg.norm(np.diff(reference, axis=0), axis=1).max() < 0.01
    feet = np.array([[plan.foot_pose(s, t)[0][:2] for s in (0, 1)] for t in times])
    mid = feet.mean(axis=1)
    half_width = 0.5 * np.linalg.norm(feet[0, 0] - feet[0, 1])
    assert np.linalg.norm(reference - mid, axis=1).max() < half_width
    # it ends where the robot's feet end: 0.4x the source's 0.3 m walk along x
    np.testing.assert_allclose(reference[-1], mid[-1], atol=1e-12)
    np.testing.assert_allclose(
        reference[-1] - reference[0], [0.3 * sim_params.step_scale, 0.0], atol=2e-3
    )
    # a knot that replays generated frame j exactly: pinocchio on that frame (walk along +x)
    j = 120
    t = plan.hold + (trajectory.time[j] - trajectory.time[0]) / plan.speed_scale
    got = com_reference(sim_robot, trajectory, plan, sim_params, np.array([0.0, t]))[1]
    q = sim_robot.configuration(
        trajectory.base_position[j],
        trajectory.base_quaternion_xyzw[j],
        trajectory.joint_positions[j],
    )
    com = pin.centerOfMass(sim_robot.model, sim_robot.data, q)[:2]
    soles = np.array(
        [sim_robot.frame_placement(q, f).translation[:2] for f in (LEFT_SOLE, RIGHT_SOLE)]
    )
    offset = com - soles.mean(axis=0)
    planned = np.mean([plan.foot_pose(s, t)[0][:2] for s in (0, 1)], axis=0)
    np.testing.assert_allclose(got, planned + offset * [sim_params.step_scale, 1.0], atol=2e-3)


def test_plan_is_pulled_toward_the_reference(sim_robot, sim_params, stance, stepping):
    """With the weight the plan's CoM is closer to the reference, still exactly on the LIPM."""
    _, plan, _, reference = stepping
    com0 = pin.centerOfMass(sim_robot.model, sim_robot.data, stance[0])
    errors = {}
    for weight in (0.0, WEIGHT):
        params = dataclasses.replace(sim_params, plan_com_weight=weight)
        dcm = plan_dcm(plan, params, com0, reference)
        a, b = lipm_matrices(dcm.omega, sim_params.plan_dt)
        states = np.vstack([dcm.com[:, :2].T, dcm.com_velocity[:, :2].T])
        assert lipm_residual(states, dcm.zmp, a, b) < 1e-8
        error = np.linalg.norm(dcm.com[:, :2] - reference, axis=1)
        errors[weight] = float(np.sqrt(np.mean(error**2)))
    assert errors[WEIGHT] < 0.7 * errors[0.0], errors


def test_simulate_trajectory_plans_with_the_reference(sim_robot, sim_params, stance, stepping):
    """The closed loop's DCM plan is the one solved with the mapped reference (a few ticks)."""
    trajectory, plan, _, reference = stepping
    params = dataclasses.replace(sim_params, plan_com_weight=WEIGHT)
    result = simulate_trajectory(trajectory, params, duration=0.02)
    com0 = pin.centerOfMass(sim_robot.model, sim_robot.data, stance[0])
    np.testing.assert_allclose(
        result.dcm.com, plan_dcm(plan, params, com0, reference).com, atol=1e-6
    )
    unweighted = plan_dcm(plan, dataclasses.replace(params, plan_com_weight=0.0), com0)
    assert np.abs(result.dcm.com - unweighted.com).max() > 0.005


def test_bad_knots_are_named(sim_robot, sim_params, stepping):
    trajectory, plan, _, _ = stepping
    with pytest.raises(PimannError, match="increasing"):
        com_reference(sim_robot, trajectory, plan, sim_params, np.array([1.0, 0.5]))
