"""Contact-clean feet: the person's contacts, the soles' plan, and the IK pass that pins them."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from pimann.core.contacts import true_runs
from pimann.core.params import load_params
from pimann.core.robot import SEGMENTS
from pimann.mocap.human_motion import HumanMotion
from pimann.retarget.feet import (
    SWING_VERTICAL,
    bridge_flights,
    debounce,
    human_contacts,
    hysteresis,
    min_jerk,
    plan_soles,
    step_pivots,
)
from pimann.retarget.ik import RetargetIK

RATE = 50.0


@pytest.fixture(scope="module")
def params():
    return load_params().retarget


def test_hysteresis_and_debounce_closed_form():
    on = np.array([0, 1, 0, 0, 0, 0, 0, 1, 0, 0], bool)
    off = np.array([1, 0, 0, 0, 1, 0, 0, 0, 0, 1], bool)
    # on at 1, held until the off at 4, on again at 7, off at 9
    expected = np.array([0, 1, 1, 1, 0, 0, 0, 1, 1, 0], bool)
    np.testing.assert_array_equal(hysteresis(on, off, start=False), expected)
    flags = np.array([1, 1, 0, 1, 1, 1, 0, 0, 0, 1, 0, 0, 0, 1], bool)
    # the one-frame gap is filled, the lone interior frame dropped, the end runs kept
    np.testing.assert_array_equal(
        debounce(flags, min_on=2, min_off=2),
        np.array([1, 1, 1, 1, 1, 1, 0, 0, 0, 0, 0, 0, 0, 1], bool),
    )


def _walking_feet(n: int, period: int = 50, down: int = 30) -> tuple[np.ndarray, np.ndarray]:
    """Heel and toe points of two feet stepping in turn at 1 m/s: each foot is down `down`
    frames of every `period` (so both are down 2 * down - period frames a cycle) and swings
    8 cm high in between. Returns the points (T, 2, 2, 3) and the true contacts (T, 2)."""
    t = np.arange(n)
    points = np.zeros((n, 2, 2, 3))
    truth = np.zeros((n, 2), bool)
    for side, phase in ((0, 0), (1, period // 2)):
        cycle = (t + phase) % period
        stance = cycle < down
        truth[:, side] = stance
        s = np.clip((cycle - down) / (period - down), 0.0, 1.0)
        step = np.floor((t + phase) / period)
        x = (step + np.where(stance, 0.0, min_jerk(s))) * 2.0 * period / RATE
        for point, (dx, floor) in enumerate(((0.0, 0.08), (0.15, 0.03))):
            points[:, side, point] = np.column_stack(
                [x + dx, np.full(n, 0.1 - 0.2 * side), floor + 0.08 * np.sin(np.pi * s)]
            )
    return points, truth


def test_human_contacts_find_each_step_with_double_support(params):
    n = 300
    points, truth = _walking_feet(n)
    motion = HumanMotion(
        np.arange(n) / RATE,
        np.broadcast_to(np.eye(3), (n, len(SEGMENTS), 3, 3)).copy(),
        np.zeros((n, len(SEGMENTS), 3)),
        "synthetic",
        foot_points=points,
    )
    contacts = human_contacts(motion, params)
    # the hysteresis holds a lifting foot down until it is clearly up: a few frames late at
    # lift-off, never early, never at touchdown
    late = contacts & ~truth
    assert not (truth & ~contacts).any()
    lift_offs = 2 * (n // 50)
    assert 0 < late.sum() <= 6 * lift_offs  # at most 6 frames (0.12 s) a lift-off
    # double support kept: the truth's 2 * 30 - 50 = 10 of 50 frames, plus the late frames
    double = contacts.all(axis=1).mean()
    assert 0.2 <= double <= 0.2 + late.sum() / n
    touchdowns = np.sum(~contacts[:-1] & contacts[1:], axis=0)
    np.testing.assert_array_equal(touchdowns, np.sum(~truth[:-1] & truth[1:], axis=0))


def test_a_flight_is_bridged_by_the_foot_that_left_last():
    # columns left, right: the right foot leaves at frame 3 (left gone since 2), lands at 6;
    # a clip opening in flight keeps the foot that lands first; no foot ever down stays so
    contacts = np.array(
        [[1, 1], [1, 1], [0, 1], [0, 0], [0, 0], [0, 1], [1, 1], [1, 0], [0, 0], [0, 1]], bool
    )
    bridged = bridge_flights(contacts)
    expected = contacts.copy()
    expected[3:5, 1] = True  # right was down last before the first flight
    expected[8, 0] = True  # left was down last before the second
    np.testing.assert_array_equal(bridged, expected)
    assert bridged.any(axis=1).all()
    opening = np.array([[0, 0], [0, 0], [1, 0], [1, 1]], bool)
    np.testing.assert_array_equal(bridge_flights(opening)[:2], [[1, 0], [1, 0]])
    never = np.zeros((4, 2), bool)
    np.testing.assert_array_equal(bridge_flights(never), never)


def test_the_plan_pins_stance_and_lifts_before_moving(params):
    n = 300
    points, truth = _walking_feet(n)
    time = np.arange(n) / RATE
    # soles that slide 5 cm and rise 2 cm while down, as a copied leg's do
    soles = points[:, :, 0].copy()
    cycle = np.cumsum(truth, axis=0) % 30
    soles[..., 0] += np.where(truth, 0.05 * cycle / 30, 0.0)
    soles[..., 2] += np.where(truth, 0.02 * cycle / 30, 0.0)
    yaw = np.where(truth, 0.1 * cycle / 30, 0.0)
    plan = plan_soles(soles, yaw, truth, time, params)
    for side in range(2):
        down = truth[:, side]
        edges = np.flatnonzero(np.diff(down.astype(int)))
        for start, stop in zip(edges[1::2] + 1, edges[2::2] + 1, strict=False):
            run = plan.positions[start:stop, side]
            assert np.ptp(run, axis=0).max() == 0.0  # one place through the whole contact
            assert np.all(run[:, 2] == 0.0)  # on the floor
            assert np.ptp(plan.headings[start:stop, side]) == 0.0
        # between footsteps: no horizontal motion until the sole is (about) at the lift height
        velocity = np.linalg.norm(np.diff(plan.positions[:, side, :2], axis=0), axis=-1) * RATE
        low = np.minimum(plan.positions[1:, side, 2], plan.positions[:-1, side, 2])
        assert np.all(velocity[low < 0.9 * params.lift_height] < 1e-9)
        assert plan.positions[:, side, 2].min() >= 0.0
        assert plan.positions[~down, side, 2].max() >= params.swing_clearance
        # held hard near the footsteps, looser in mid-swing
        assert set(np.unique(plan.weights[:, side])) == {params.stance_weight, params.swing_weight}
        # the person's leg takes the sole over only off the floor, fully at mid-swing
        following = plan.leg_following[:, side]
        assert np.all(following[down] == 0.0)
        assert np.all(following[plan.positions[:, side, 2] < params.lift_height - 1e-9] == 0.0)
        assert following.max() > 0.99 and np.all((following >= 0.0) & (following <= 1.0))
    assert 0.0 < SWING_VERTICAL < 0.5


def test_planted_soles_hold_and_the_base_gives_way(robot, params):
    """Pelvis target 6 cm ahead of a standing pose with both soles planted: the soles stay
    (to 1 mm), the base moves toward the target only as the legs allow."""
    import pinocchio as pin

    ik = RetargetIK(robot, dataclasses.replace(params, pelvis_position_weight=1.0), RATE)
    q0 = robot.standing_configuration()
    soles = tuple(robot.frame_placement(q0, f) for f in ("l_sole", "r_sole"))
    pelvis = robot.frame_placement(q0, "data_Pelvis")
    targets = np.array([robot.frame_placement(q0, f"data_{s}").rotation for s in SEGMENTS[1:]])
    ahead = pin.SE3(pelvis.rotation, pelvis.translation + [0.06, 0.0, 0.0])
    ik.reset(q0)
    weights = (params.stance_weight, params.stance_weight)
    for _ in range(20):
        q = ik.solve(ahead, targets, soles, weights)
    for frame, target in zip(("l_sole", "r_sole"), soles, strict=True):
        placement = robot.frame_placement(q, frame)
        assert np.linalg.norm(placement.translation - target.translation) < 1e-3
        assert np.linalg.norm(pin.log3(placement.rotation.T @ target.rotation)) < 1e-2
    moved = robot.frame_placement(q, "data_Pelvis").translation - pelvis.translation
    assert 0.005 < moved[0] < 0.06


def _corner_heights(robot, q) -> np.ndarray:
    from pimann.core.robot import SOLE_CORNERS

    heights = []
    for frame in ("l_sole", "r_sole"):
        placement = robot.frame_placement(q, frame)
        heights.append([placement.act(corner)[2] for corner in SOLE_CORNERS])
    return np.concatenate(heights)


def test_floor_limit_rows_are_the_corner_heights_derivative(robot, rng):
    """The linearised floor rows against finite differences of the corners' heights."""
    import pink
    import pinocchio as pin

    from pimann.retarget.ik import FloorLimit

    q = robot.standing_configuration()
    q[3:7] = pin.Quaternion(pin.rpy.rpyToMatrix(0.1, -0.2, 0.4)).coeffs()
    q[7:] += rng.uniform(-0.2, 0.2, size=len(q) - 7)
    configuration = pink.Configuration(robot.model, robot.model.createData(), q)
    rows, heights = FloorLimit(robot).compute_qp_inequalities(configuration, 0.02)
    np.testing.assert_allclose(heights, _corner_heights(robot, q), atol=1e-12)
    step = 1e-6 * rng.standard_normal(robot.model.nv)
    moved = pin.integrate(robot.model, q, step)
    change = _corner_heights(robot, moved) - _corner_heights(robot, q)
    np.testing.assert_allclose(-rows @ step, change, atol=1e-11)


def test_a_sole_target_under_the_floor_stops_at_it(robot, params):
    """Both soles asked 3 cm under the floor, a light swing cost: the corners stop at z = 0
    (the floor limit), and go under it without the limit."""
    import pinocchio as pin

    q0 = robot.standing_configuration()
    q0[2] -= min(robot.frame_placement(q0, f).translation[2] for f in ("l_sole", "r_sole"))
    soles = tuple(robot.frame_placement(q0, f) for f in ("l_sole", "r_sole"))
    sunk = tuple(pin.SE3(s.rotation, s.translation - [0.0, 0.0, 0.03]) for s in soles)
    pelvis = robot.frame_placement(q0, "data_Pelvis")
    targets = np.array([robot.frame_placement(q0, f"data_{s}").rotation for s in SEGMENTS[1:]])
    ik = RetargetIK(robot, params, RATE)
    ik.reset(q0)
    for _ in range(20):
        q = ik.solve(pelvis, targets, sunk, (params.stance_weight,) * 2)
    assert _corner_heights(robot, q).min() > -1e-6
    assert _corner_heights(robot, q).min() < 1e-3  # pressed onto the floor
    ik.limits_with_soles = ik.limits  # without the floor
    ik.reset(q0)
    for _ in range(20):
        q = ik.solve(pelvis, targets, sunk, (params.stance_weight,) * 2)
    assert _corner_heights(robot, q).min() < -0.02


def test_a_turning_planted_foot_steps_while_the_other_stands():
    n, step, turn = 60, 5, 0.35
    contacts = np.ones((n, 2), bool)
    headings = np.zeros((n, 2))
    headings[:, 0] = np.linspace(0.0, 1.0, n)  # the left foot pivots by 1 rad
    stepped = step_pivots(contacts, headings, turn, step)
    assert stepped[:, 1].all()  # the right foot does not turn: it stays
    lifts = [(a, b) for a, b in true_runs(~stepped[:, 0])]
    assert len(lifts) == 2 and all(b - a == step for a, b in lifts)
    for a, b in true_runs(stepped[:, 0]):  # one heading per footstep, to a frame's turn
        assert np.ptp(headings[a:b, 0]) <= turn + 1.0 / (n - 1)
    # the first lift starts where the turn first passes the limit
    assert lifts[0][0] == np.argmax(headings[:, 0] > turn)
    # with the other foot up, the turning foot waits for it to land
    contacts[: lifts[0][0] + 10, 1] = False
    waited = step_pivots(contacts, headings, turn, step)
    assert np.flatnonzero(~waited[:, 0])[0] == lifts[0][0] + 10
    assert waited.any(axis=1).all()
