"""Footsteps from contacts and the offline DCM/ZMP plan (LIPM-consistent, ZMP in the support)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pinocchio as pin
import pytest
from scipy.spatial import ConvexHull

from pimann.core.errors import PimannError
from pimann.core.robot import SOLE_HALF_LENGTH, SOLE_HALF_WIDTH
from pimann.core.rotations import rot_z
from pimann.sim.dcm import lipm_matrices, lipm_residual, plan_dcm
from pimann.sim.footsteps import clean_contacts, extract_footsteps, relative
from pimann.sim.synthetic import stepping_plan, stepping_trajectory
from pimann.sim.wbc import SOLE_HEIGHT


@pytest.fixture(scope="module")
def synthetic(sim_robot, sim_params, stance):
    plan = stepping_plan(stance[1], steps=4, step=0.1, start=0.5, end=0.5)
    return plan, stepping_trajectory(sim_robot, sim_params, plan)


def test_clean_contacts_removes_blips_and_flight():
    time = np.arange(20) * 0.02
    contacts = np.ones((20, 2), bool)
    contacts[5:12, 0] = False  # a swing
    contacts[8, 0] = True  # a 0.02 s blip inside it
    contacts[12:14, 1] = False  # flight: both feet up at 12, 13 ...
    contacts[12:14, 0] = False
    cleaned = clean_contacts(contacts, time, min_contact=0.05, min_swing=0.05)
    assert not cleaned[5:12, 0].any()  # blip removed
    assert cleaned.any(axis=1).all()  # never both feet up
    assert cleaned[0].all() and cleaned[-1].all()


def test_clean_contacts_drops_swings_cut_by_the_clip():
    """A clip that starts or ends mid-swing: no one-sample contact, no instant step."""
    time = np.arange(40) * 0.06
    contacts = np.ones((40, 2), bool)
    contacts[:3, 0] = False  # left lands at sample 3
    contacts[3:20, 1] = False  # right swings
    contacts[37:, 0] = False  # left lifts at the very end
    cleaned = clean_contacts(contacts, time, min_contact=0.1, min_swing=0.5)
    assert cleaned[:, 0].all()  # both cut swings dropped: the left foot never lifts
    np.testing.assert_array_equal(cleaned[:, 1], contacts[:, 1])  # the real swing is kept


def test_footsteps_round_trip(sim_robot, sim_params, stance, synthetic):
    """At 1x speed and step size the footsteps and timings of the source plan come back."""
    plan, trajectory = synthetic
    same = dataclasses.replace(
        sim_params, speed_scale=1.0, step_scale=1.0, zmp_hold_s=0.0, end_hold_s=0.0
    )
    got = extract_footsteps(sim_robot, trajectory, same, stance[1])
    for side in (0, 1):
        want, have = plan.feet[side], got.feet[side]
        assert len(have) == len(want)
        np.testing.assert_allclose(have.positions, want.positions, atol=1e-4)
        np.testing.assert_allclose(have.t_on, want.t_on, atol=1e-9)
        # a contact sample holds until the next sample: lift-off at most one sample later
        lag = have.t_off - want.t_off
        assert np.all(lag >= -1e-9) and np.all(lag <= 1.0 / trajectory.rate_hz + 1e-9)
    assert got.duration == pytest.approx(plan.duration)


def test_footsteps_scaling(sim_robot, sim_params, stance, synthetic):
    """0.33x speed stretches every phase by 1/0.33; 0.4x steps shorten every displacement."""
    plan, trajectory = synthetic
    got = extract_footsteps(sim_robot, trajectory, sim_params, stance[1])
    for side in (0, 1):
        want, have = plan.feet[side], got.feet[side]
        np.testing.assert_allclose(
            np.diff(have.positions, axis=0),
            sim_params.step_scale * np.diff(want.positions, axis=0),
            atol=1e-4,
        )
        np.testing.assert_allclose(
            have.t_on[1:], sim_params.zmp_hold_s + want.t_on[1:] / sim_params.speed_scale, atol=1e-6
        )
        np.testing.assert_allclose(have.positions[0], stance[1][side, :2], atol=1e-12)
    # swing: lifted by swing_height at mid-swing, flat on the floor in stance
    left = got.feet[0]
    mid = 0.5 * (left.t_off[0] + left.t_on[1])
    assert got.foot_pose(0, mid)[0][2] == pytest.approx(sim_params.swing_height - SOLE_HEIGHT)
    assert got.foot_pose(0, left.t_on[1] + 0.01)[0][2] == pytest.approx(-SOLE_HEIGHT)


def test_missing_contacts_is_named(sim_robot, sim_params, stance, synthetic):
    trajectory = dataclasses.replace(synthetic[1], contacts=None)
    with pytest.raises(PimannError, match="no contacts"):
        extract_footsteps(sim_robot, trajectory, sim_params, stance[1])


def _inside_support(plan, dcm, half, tolerance=1e-6):
    """Every ZMP sample in the stance foot's rectangle, or in the hull of both rectangles."""
    dt = dcm.time[1] - dcm.time[0]
    for k, zmp in enumerate(dcm.zmp):
        t = dcm.time[k] + 0.5 * dt
        corners = []
        for side in np.flatnonzero(dcm.support[k]):
            centre, yaw = plan.foot_pose(side, t)
            box = np.array([[sx * half[0], sy * half[1]] for sx in (-1, 1) for sy in (-1, 1)])
            corners.append(centre[:2] + box @ rot_z(yaw)[:2, :2].T)
        corners = np.concatenate(corners)
        hull = ConvexHull(corners)
        assert np.all(hull.equations[:, :2] @ zmp + hull.equations[:, 2] <= tolerance), (k, t)


def test_dcm_plan_is_lipm_consistent_and_supported(sim_robot, sim_params, stance):
    q0, feet = stance
    plan = stepping_plan(feet, steps=4, step=0.1, start=0.8, end=0.8)
    com0 = pin.centerOfMass(sim_robot.model, sim_robot.data, q0)
    dcm = plan_dcm(plan, sim_params, com0)
    assert dcm.omega == pytest.approx(np.sqrt(9.81 / sim_params.com_height))
    a, b = lipm_matrices(dcm.omega, sim_params.plan_dt)
    states = np.vstack([dcm.com[:, :2].T, dcm.com_velocity[:, :2].T])
    assert lipm_residual(states, dcm.zmp, a, b) < 1e-8
    # the continuous LIPM, integrated finely, lands on the plan's knots (independent check)
    k, fine = 150, 100
    x, v = dcm.com[k, :2].copy(), dcm.com_velocity[k, :2].copy()
    h = sim_params.plan_dt / fine
    for _ in range(fine):
        acc = dcm.omega**2 * (x - dcm.zmp[k])
        x, v = x + h * v + 0.5 * h * h * acc, v + h * acc
    np.testing.assert_allclose(x, dcm.com[k + 1, :2], atol=1e-6)
    half = np.array([SOLE_HALF_LENGTH, SOLE_HALF_WIDTH]) - sim_params.zmp_margin
    _inside_support(plan, dcm, half)
    # starts and ends at rest, the CoM moves forward with the feet, sways toward the stance foot
    np.testing.assert_allclose(dcm.com_velocity[[0, -1]], 0.0, atol=1e-9)
    np.testing.assert_allclose(dcm.com[0, :2], com0[:2], atol=1e-9)
    assert dcm.com[-1, 0] - dcm.com[0, 0] == pytest.approx(0.15, abs=0.01)
    first_swing = (dcm.time[:-1] > plan.feet[1].t_off[0]) & (dcm.time[:-1] < plan.feet[1].t_on[1])
    assert dcm.com[:-1][first_swing, 1].max() > 0.03  # right foot swings: CoM over the left
    # DCM and CoM at the interval end agree with DCMPlan.at
    com, velocity, zmp = dcm.at(dcm.time[k + 1] - 1e-12)
    np.testing.assert_allclose(com[:2], dcm.com[k + 1, :2], atol=1e-9)


def test_dcm_plan_rejects_impossible_margin(sim_robot, sim_params, stance):
    plan = stepping_plan(stance[1], steps=2, step=0.1)
    bad = dataclasses.replace(sim_params, zmp_margin=0.06)
    with pytest.raises(PimannError, match="no support area"):
        plan_dcm(plan, bad, np.zeros(3))


def test_turning_footsteps_keep_the_stance_width(sim_robot, sim_params, stance):
    """Scaled turns: each landing foot stays a stance width beside the other (never crossed)."""
    plan = stepping_plan(stance[1], steps=6, step=(0.2, 0.0, 0.4), start=0.3, end=0.3)
    trajectory = stepping_trajectory(sim_robot, sim_params, plan)
    got = extract_footsteps(sim_robot, trajectory, sim_params, stance[1])
    width = np.linalg.norm(stance[1][0, :2] - stance[1][1, :2])
    assert got.feet[0].yaws[-1] == pytest.approx(plan.feet[0].yaws[-1], abs=1e-3)  # turns kept
    checked = 0
    for side in (0, 1):
        landing, other = got.feet[side], got.feet[1 - side]
        for j in range(1, len(landing)):
            k = got.stance_index(1 - side, landing.t_on[j])
            offset = relative(
                np.array([*other.positions[k], other.yaws[k]]),
                np.array([*landing.positions[j], landing.yaws[j]]),
            )
            # lateral offset toward the landing foot's own side, about one stance width
            assert (1 if side == 0 else -1) * offset[1] > 0.8 * width
            checked += 1
    assert checked >= 5


def test_one_sample_handover_gets_double_support(sim_robot, sim_params, stance):
    """Contacts that hand over in one sample still give min_double_s of double support."""
    plan = stepping_plan(stance[1], steps=2, step=0.1, single=0.4, double=0.0, start=0.3, end=0.3)
    trajectory = stepping_trajectory(sim_robot, sim_params, plan)
    contacts = trajectory.contacts.copy()
    both = contacts.all(axis=1)
    both[[0, -1]] = False
    contacts[both, 1] = False  # right lifts exactly when left lands: no shared sample inside
    trajectory = dataclasses.replace(trajectory, contacts=contacts)
    got = extract_footsteps(sim_robot, trajectory, sim_params, stance[1])
    for side in (0, 1):
        landing, other = got.feet[side], got.feet[1 - side]
        for j in range(1, len(landing)):
            k = got.stance_index(1 - side, landing.t_on[j])
            assert k is not None
            if k < len(other) - 1:
                assert other.t_off[k] - landing.t_on[j] >= sim_params.min_double_s - 1e-9
