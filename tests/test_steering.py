"""Steering (Eqs. lin_pid, rot_pid): closed-loop convergence and the goal helpers."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from pimann.core.rotations import hat, rotation_rpy, skew_part, vee, yaw_of
from pimann.generate.steering import CarrotGoal, goal_from_command, reached_goal, steer

K0, K1 = 0.2, 2.0


def test_vee_of_skew_part(rng):
    w = rng.normal(size=3)
    np.testing.assert_allclose(vee(hat(w)), w)
    A = rng.normal(size=(3, 3))
    expected = 0.5 * np.array([A[2, 1] - A[1, 2], A[0, 2] - A[2, 0], A[1, 0] - A[0, 1]])
    np.testing.assert_allclose(vee(skew_part(A)), expected)
    # for a rotation by angle a about axis u: vee(skew(R)) = sin(a) u
    u = rng.normal(size=3)
    u /= np.linalg.norm(u)
    np.testing.assert_allclose(vee(skew_part(pin.exp3(0.7 * u))), np.sin(0.7) * u, atol=1e-12)


def test_no_correction_at_the_goal(rng):
    R = pin.exp3(rng.normal(size=3))
    p = rng.normal(size=3)
    v_hat, omega_hat = rng.normal(size=(7, 3)), rng.normal(size=(7, 3))
    v_c, omega_c = steer(v_hat, omega_hat, p, R, p, R, K0, K1)
    np.testing.assert_allclose(v_c, v_hat, atol=1e-15)
    np.testing.assert_allclose(omega_c, omega_hat, atol=1e-15)


def test_correction_is_the_paper_formula_and_broadcasts(rng):
    R, R_d = pin.exp3(rng.normal(size=3)), pin.exp3(rng.normal(size=3))
    p, p_d = rng.normal(size=3), rng.normal(size=3)
    v_hat, omega_hat = rng.normal(size=(7, 3)), rng.normal(size=(7, 3))
    v_c, omega_c = steer(v_hat, omega_hat, p, R, p_d, R_d, K0, K1)
    E = R_d.T @ R
    np.testing.assert_allclose(v_c, v_hat - K0 * R.T @ (p - p_d))
    np.testing.assert_allclose(omega_c, omega_hat - K1 * vee((E - E.T) / 2))
    # a batch of poses equals the poses one by one
    Rs = np.stack([pin.exp3(rng.normal(size=3)) for _ in range(4)])
    ps = rng.normal(size=(4, 3))
    v_b, w_b = steer(np.zeros((4, 3)), np.zeros((4, 3)), ps, Rs, p_d, R_d, K0, K1)
    for k in range(4):
        v_k, w_k = steer(np.zeros(3), np.zeros(3), ps[k], Rs[k], p_d, R_d, K0, K1)
        np.testing.assert_allclose(v_b[k], v_k)
        np.testing.assert_allclose(w_b[k], w_k)


def _integrate(p, R, p_d, R_d, duration, dt=1e-3):
    """Zero network velocities; p_dot = R v_c, R_dot = R [omega_c]x (exact exponential step)."""
    history = []
    for _ in range(round(duration / dt)):
        v_c, omega_c = steer(np.zeros(3), np.zeros(3), p, R, p_d, R_d, K0, K1)
        p = p + dt * (R @ v_c)
        R = R @ pin.exp3(omega_c * dt)
        history.append((p, R))
    return history


def test_small_errors_decay_at_rates_k0_and_k1(rng):
    p_d, R_d = np.array([2.0, -1.0, 0.8]), rotation_rpy(0.0, -0.09, 0.6)
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    p0, theta0 = p_d + np.array([0.01, 0.02, -0.01]), 0.01 * axis
    R0 = R_d @ pin.exp3(theta0)
    dt, duration = 1e-3, 1.5
    history = _integrate(p0, R0, p_d, R_d, duration, dt)
    times = dt * np.arange(1, len(history) + 1)
    position_errors = np.array([p - p_d for p, _ in history])
    orientation_errors = np.array([pin.log3(R_d.T @ R) for _, R in history])
    # explicit Euler steps of the closed form e_dot = -k e: e_n = (1 - k dt)^n e_0 ~ exp(-k t) e_0
    steps = np.arange(1, len(history) + 1)
    np.testing.assert_allclose(
        position_errors, ((1 - K0 * dt) ** steps)[:, None] * (p0 - p_d), rtol=1e-9, atol=1e-12
    )
    np.testing.assert_allclose(
        orientation_errors, ((1 - K1 * dt) ** steps)[:, None] * theta0, rtol=1e-4, atol=1e-9
    )
    np.testing.assert_allclose(np.exp(-K1 * times), (1 - K1 * dt) ** steps, rtol=5e-3)


def test_large_offsets_converge_to_the_goal():
    p_d, R_d = np.array([2.5, 0.0, 0.78]), rotation_rpy(yaw=0.0)
    p0, R0 = np.array([0.0, 1.0, 0.78]), rotation_rpy(0.1, -0.2, 2.0)
    p, R = _integrate(p0, R0, p_d, R_d, duration=40.0, dt=1e-2)[-1]
    assert np.linalg.norm(p - p_d) < 1e-3 * np.linalg.norm(p0 - p_d)
    assert np.linalg.norm(pin.log3(R_d.T @ R)) < 1e-6


def test_goal_from_command_is_ahead_in_the_heading():
    R = rotation_rpy(0.05, -0.09, np.pi / 2)  # facing +y
    p = np.array([1.0, 2.0, 0.77])
    np.testing.assert_allclose(
        goal_from_command(p, R, [1.0, 0.0], 2.5), [1.0, 4.5, 0.77], atol=1e-12
    )
    np.testing.assert_allclose(
        goal_from_command(p, R, [0.0, 1.0], 2.0), [-1.0, 2.0, 0.77], atol=1e-12
    )
    assert yaw_of(R) == pytest.approx(np.pi / 2)


def test_carrot_goal_is_the_commanded_displacement_over_the_horizon_ahead():
    R = np.stack([rotation_rpy(0.0, 0.0, np.pi / 2), np.eye(3)])  # facing +y, facing +x
    path = np.array([[1.0, 2.0, 0.77], [0.0, 0.0, 0.8]])
    goal = CarrotGoal(factor=0.25, horizon=1.2)(path, R, np.array([[1.0, 0.0], [0.0, -0.5]]))
    np.testing.assert_allclose(goal, [[1.0, 2.3, 0.77], [0.0, -0.15, 0.8]], atol=1e-12)


def test_reached_goal_radius():
    goal = np.array([1.0, 0.0, 0.77])
    assert reached_goal([0.75, 0.0, 0.5], goal) is True  # height ignored
    assert reached_goal([0.65, 0.0, 0.77], goal) is False
    assert reached_goal([0.65, 0.0, 0.77], goal, radius=0.4) is True
    np.testing.assert_array_equal(
        reached_goal(np.array([[1, 0, 0], [0, 0, 0]]), goal), [True, False]
    )


def test_rotation_rpy_matches_pinocchio():
    expected = pin.rpy.rpyToMatrix(0.1, -0.2, 0.3)
    np.testing.assert_allclose(rotation_rpy(0.1, -0.2, 0.3), expected, atol=1e-12)


def test_planar_variant_ignores_height_and_tilt():
    R = rotation_rpy(0.2, -0.3, 0.7)
    p, p_d = np.array([1.0, 2.0, 0.9]), np.array([0.0, 0.0, 0.7])
    v_c, omega_c = steer(np.zeros(3), np.zeros(3), p, R, p_d, R, K0, K1, planar=True)
    expected = -K0 * rotation_rpy(yaw=0.7).T @ np.array([1.0, 2.0, 0.0])
    np.testing.assert_allclose(v_c, expected, atol=1e-12)
    np.testing.assert_allclose(omega_c, 0.0, atol=1e-12)
    # without tilt and height error both variants agree
    flat = rotation_rpy(yaw=0.7)
    same_height = np.array([0.0, 0.0, 0.9])
    full = steer(np.zeros(3), np.zeros(3), p, flat, same_height, flat, K0, K1)
    planar = steer(np.zeros(3), np.zeros(3), p, flat, same_height, flat, K0, K1, planar=True)
    np.testing.assert_allclose(full[0], planar[0], atol=1e-12)
