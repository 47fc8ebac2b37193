"""Whole-body IK, ZMP-CoM feedback and the closed loop in MuJoCo (the closed loop end to end)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pinocchio as pin
import pytest

from pimann.core.robot import LEFT_SOLE, RIGHT_SOLE, STANDING_JOINTS
from pimann.sim.closed_loop import simulate_trajectory
from pimann.sim.synthetic import standing_feet, stepping_plan, stepping_trajectory
from pimann.sim.wbc import IKTargets, LowPass, WholeBodyIK, standing_pose, zmp_com_feedback


def test_feedback_law_closed_form():
    v = zmp_com_feedback(
        com_velocity_ref=np.array([0.1, 0.0]),
        zmp_ref=np.array([0.02, 0.0]),
        zmp_measured=np.array([0.0, 0.01]),
        com_ref=np.array([0.0, 0.0]),
        com_measured=np.array([0.01, 0.0]),
        k_zmp=1.0,
        k_com=3.0,
    )
    np.testing.assert_allclose(v, [0.1 - 0.02 - 0.03, 0.01])


def test_low_pass_step_response():
    dt, cutoff = 0.001, 15.0
    lowpass = LowPass(cutoff, dt, np.zeros(2))
    for _ in range(20):
        out = lowpass(np.ones(2))
    np.testing.assert_allclose(out, 1.0 - np.exp(-2 * np.pi * cutoff * dt * 20), rtol=1e-12)
    np.testing.assert_allclose(lowpass(np.full(2, np.nan)), out)  # no contact: hold


def test_ik_tracks_feet_and_com(sim_robot, sim_params):
    """A few ticks toward shifted targets: feet and CoM land on them (pinocchio FK)."""
    q0 = standing_pose(sim_robot, sim_params)
    ik = WholeBodyIK(sim_robot, sim_params, q0)
    left = sim_robot.frame_placement(q0, LEFT_SOLE)
    right = sim_robot.frame_placement(q0, RIGHT_SOLE)
    lifted = pin.SE3(left.rotation, left.translation + [0.01, 0.0, 0.01])
    com = ik.com_position() + [0.005, 0.01, 0.0]
    for _ in range(5):
        q = ik.step(IKTargets(lifted, right, com, 0.0, STANDING_JOINTS))
    np.testing.assert_allclose(
        sim_robot.frame_placement(q, LEFT_SOLE).translation, lifted.translation, atol=1e-4
    )
    np.testing.assert_allclose(
        sim_robot.frame_placement(q, RIGHT_SOLE).translation, right.translation, atol=1e-4
    )
    np.testing.assert_allclose(pin.centerOfMass(sim_robot.model, sim_robot.data, q), com, atol=1e-4)


def test_closed_loop_stepping_keeps_balance(sim_robot, sim_params):
    """Four steps of 0.05 m (0.1 m at 0.5x step size) in MuJoCo: no fall, no slip."""
    fast = dataclasses.replace(
        sim_params, speed_scale=1.0, step_scale=0.5, zmp_hold_s=1.0, end_hold_s=0.5
    )
    feet = standing_feet(sim_robot, standing_pose(sim_robot, sim_params))
    plan = stepping_plan(feet, steps=4, step=0.1, start=0.3, end=0.3)
    trajectory = stepping_trajectory(sim_robot, fast, plan)
    result = simulate_trajectory(trajectory, fast)
    assert not result.fallen
    assert result.time[-1] == pytest.approx(result.planned_duration, abs=0.011)
    assert result.base_height.min() > 0.7
    assert result.foot_slip < 0.01
    # the feet end where the plan put them: 0.075 m forward of the start
    np.testing.assert_allclose(result.soles_final[:, :2], result.soles_planned[:, :2], atol=0.01)
    np.testing.assert_allclose(result.soles_planned[:, 0] - feet[:, 0], 0.075, atol=1e-6)
    # the CoM follows the adjusted plan, the joints follow the IK
    assert np.abs(result.com_measured - result.com_reference)[:, :2].max() < 0.03
    assert result.joint_rmse < 0.02
    assert result.real_time_factor > 0
    summary = result.summary()
    assert summary["fallen"] is False and summary["foot_slip_m"] == result.foot_slip
    assert summary["final_sole_error_m"] < 0.015


def test_paper_scaling_turning_walk(sim_robot, sim_params):
    """Default sim_params (0.33x speed, 0.4x steps, 1.6 s hold) on a quick turning walk."""
    feet = standing_feet(sim_robot, standing_pose(sim_robot, sim_params))
    plan = stepping_plan(feet, 4, (0.3, 0.0, 0.3), single=0.35, double=0.1, start=0.2, end=0.2)
    result = simulate_trajectory(stepping_trajectory(sim_robot, sim_params, plan), sim_params)
    assert not result.fallen and result.foot_slip < 0.01
    # the robot turned with the plan: final sole yaw from the simulation's sole positions
    left, right = result.soles_final[0, :2], result.soles_final[1, :2]
    lateral = left - right  # points to the robot's left
    yaw = np.arctan2(-lateral[0], lateral[1])
    assert yaw == pytest.approx(plan.feet[0].yaws[-1], abs=0.05)
