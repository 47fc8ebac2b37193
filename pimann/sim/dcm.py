"""Offline DCM/ZMP adjustment (Romualdi 2018's offline layer) as one sparse QP in casadi.

Over the whole horizon: the CoM follows the linear inverted pendulum exactly (zero-order
hold on the ZMP, omega = sqrt(g / z_com)), the ZMP stays in the support polygon (the stance
foot's rectangle in single support; the exact convex hull of both rectangles in double
support, written as a Minkowski sum with a split variable), close to the support centres,
smooth, and the CoM starts and ends at rest.
"""

from __future__ import annotations

import dataclasses
import logging

import casadi as ca
import numpy as np

from pimann.core.contacts import true_runs
from pimann.core.errors import PimannError
from pimann.core.params import SimulateParams
from pimann.core.robot import SOLE_HALF_LENGTH, SOLE_HALF_WIDTH
from pimann.sim.footsteps import FootstepPlan

GRAVITY = 9.81
MAX_RESIDUAL = 1e-4  # m, m/s: largest LIPM violation accepted from the QP solver
SHIFT_MAX = 0.5  # s: in long double supports the ZMP reference moves only in the last 0.5 s
# Ipopt solves this QP exactly (LIPM residual ~1e-16); OSQP needs ~1e5 iterations to reach
# 1e-6 on the unstable dynamics over long horizons, and HiGHS' QP reports a solve error.
IPOPT_OPTIONS = {"print_level": 0, "sb": "yes", "tol": 1e-10}
log = logging.getLogger(__name__)


@dataclasses.dataclass
class DCMPlan:
    time: np.ndarray  # (N+1,) knots
    com: np.ndarray  # (N+1, 3)
    com_velocity: np.ndarray  # (N+1, 3)
    zmp: np.ndarray  # (N, 2), constant over [time[k], time[k+1])
    omega: float
    support: np.ndarray  # (N, 2) bool: feet counted in contact on each interval

    @property
    def dcm(self) -> np.ndarray:
        return self.com[:, :2] + self.com_velocity[:, :2] / self.omega

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """CoM, CoM velocity (exact LIPM flow inside the interval) and ZMP at time t."""
        dt = self.time[1] - self.time[0]
        k = int(np.clip(np.floor((t - self.time[0]) / dt), 0, len(self.zmp) - 1))
        tau = float(np.clip(t - self.time[k], 0.0, dt))
        c, s = np.cosh(self.omega * tau), np.sinh(self.omega * tau)
        x, v, p = self.com[k, :2], self.com_velocity[k, :2], self.zmp[k]
        com = self.com[k].copy()
        velocity = np.zeros(3)
        com[:2] = p + (x - p) * c + v * s / self.omega
        velocity[:2] = (x - p) * self.omega * s + v * c
        return com, velocity, p.copy()


def lipm_matrices(omega: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact discrete LIPM per axis: [x, v]_{k+1} = A [x, v]_k + B p_k."""
    c, s = np.cosh(omega * dt), np.sinh(omega * dt)
    return np.array([[c, s / omega], [omega * s, c]]), np.array([1.0 - c, -omega * s])


def lipm_residual(states: np.ndarray, zmp: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    """Largest violation of the discrete LIPM by (4, N+1) states [x, y, vx, vy] and (N, 2) ZMP."""
    worst = 0.0
    for axis in (0, 1):
        pair = states[[axis, axis + 2]]
        error = pair[:, 1:] - (a @ pair[:, :-1] + np.outer(b, zmp[:, axis]))
        worst = max(worst, float(np.abs(error).max()))
    return worst


def zmp_reference(plan: FootstepPlan, times: np.ndarray, support: np.ndarray) -> np.ndarray:
    """Support centre: the stance foot in single support, a ramp between feet in double."""
    centres = np.array(
        [[plan.foot_pose(s, t)[0][:2] for s in (0, 1)] for t in times]
    )  # (N, 2 feet, 2)
    single = support.sum(axis=1) == 1
    ref = np.where(single[:, None], centres[np.arange(len(times)), np.argmax(support, 1)], np.nan)
    double = support.all(axis=1)
    # each double-support run ramps from the previous single-support centre to the next one
    for start, end in true_runs(double):
        mid = centres[start:end].mean(axis=1)
        before = ref[start - 1] if start > 0 else mid[0]
        after = ref[end] if end < len(times) else mid[-1]
        t0 = max(times[start], times[end - 1] - SHIFT_MAX)
        span = max(times[end - 1] - t0, 1e-9)
        w = np.clip((times[start:end] - t0) / span, 0.0, 1.0)[:, None]
        if start == 0:  # initial hold: from the feet's midpoint
            before = mid[0]
        if end == len(times):
            after = mid[-1]
        ref[start:end] = (1.0 - w) * before + w * after
    return ref


def _inside(opti: ca.Opti, points, weight, centres, yaws, half) -> None:
    """points (2, m) inside weight * the rectangles (centre, yaw, half sizes), vectorised."""
    cos, sin = ca.DM(np.cos(yaws)).T, ca.DM(np.sin(yaws)).T
    dx = points[0, :] - weight * ca.DM(centres[:, 0]).T
    dy = points[1, :] - weight * ca.DM(centres[:, 1]).T
    local_x = cos * dx + sin * dy
    local_y = -sin * dx + cos * dy
    opti.subject_to(opti.bounded(-weight * half[0], local_x, weight * half[0]))
    opti.subject_to(opti.bounded(-weight * half[1], local_y, weight * half[1]))


def knot_times(plan: FootstepPlan, params: SimulateParams) -> np.ndarray:
    """The plan's (n+1,) time knots: every plan_dt over the footstep plan's duration."""
    n = int(np.ceil(plan.duration / params.plan_dt))
    return np.arange(n + 1) * params.plan_dt


def plan_dcm(
    plan: FootstepPlan,
    params: SimulateParams,
    com0: np.ndarray,
    com_reference: np.ndarray | None = None,
) -> DCMPlan:
    """Solve the ZMP/CoM QP over the footstep plan; `com0` is the robot's initial CoM (3,)."""
    dt = params.plan_dt
    time = knot_times(plan, params)
    n = len(time) - 1
    omega = float(np.sqrt(GRAVITY / params.com_height))
    a, b = lipm_matrices(omega, dt)
    support = np.array(
        [
            [
                plan.in_contact(s, t) and plan.in_contact(s, min(t + dt, plan.duration))
                for s in (0, 1)
            ]
            for t in time[:-1]
        ]
    )
    if not support.any(axis=1).all():
        k = int(np.argmin(support.any(axis=1)))
        raise PimannError(None, f"no foot in contact at t = {time[k]:.2f} s: cannot plan the ZMP")
    mids = time[:-1] + 0.5 * dt
    feet = [[plan.foot_pose(s, t) for s in (0, 1)] for t in mids]
    ref = zmp_reference(plan, mids, support)

    opti = ca.Opti()
    state = opti.variable(4, n + 1)  # x, y, vx, vy
    zmp = opti.variable(2, n)
    half = np.array([SOLE_HALF_LENGTH, SOLE_HALF_WIDTH]) - params.zmp_margin
    if np.any(half <= 0):
        raise PimannError(None, "zmp_margin leaves no support area")
    opti.subject_to(state[:, 0] == ca.DM([com0[0], com0[1], 0.0, 0.0]))
    opti.subject_to(zmp[:, 0] == ca.DM(com0[:2]))  # start in equilibrium: no ZMP jump at t = 0
    for axis in (0, 1):
        pos, vel = state[axis, :], state[axis + 2, :]
        opti.subject_to(pos[1:] == a[0, 0] * pos[:-1] + a[0, 1] * vel[:-1] + b[0] * zmp[axis, :])
        opti.subject_to(vel[1:] == a[1, 0] * pos[:-1] + a[1, 1] * vel[:-1] + b[1] * zmp[axis, :])
    opti.subject_to(state[2:, n] == 0)
    opti.subject_to(state[:2, n] == zmp[:, n - 1])
    centres = np.array([[f[0][:2] for f in pair] for pair in feet])  # (n, 2 feet, 2)
    yaws = np.array([[f[1] for f in pair] for pair in feet])  # (n, 2 feet)
    single = np.flatnonzero(support.sum(axis=1) == 1)
    double = np.flatnonzero(support.all(axis=1))
    if len(single):
        side = np.argmax(support[single], axis=1)
        _inside(opti, zmp[:, single.tolist()], 1.0, centres[single, side], yaws[single, side], half)
    if len(double):  # convex hull: zmp = u + v, u in share * left foot, v in (1 - share) * right
        split = opti.variable(2, len(double))
        share = opti.variable(1, len(double))
        opti.subject_to(opti.bounded(0, share, 1))
        _inside(opti, split, share, centres[double, 0], yaws[double, 0], half)
        rest = zmp[:, double.tolist()] - split
        _inside(opti, rest, 1 - share, centres[double, 1], yaws[double, 1], half)
    cost = params.plan_zmp_weight * dt * ca.sumsqr(zmp - ca.DM(ref.T))
    cost += params.plan_rate_weight / dt * ca.sumsqr(zmp[:, 1:] - zmp[:, :-1])
    if com_reference is not None and params.plan_com_weight > 0:
        if np.shape(com_reference) != (n + 1, 2):
            raise PimannError(None, f"com_reference must be {(n + 1, 2)}")
        cost += params.plan_com_weight * dt * ca.sumsqr(state[:2, :] - ca.DM(com_reference.T))
    opti.minimize(cost)
    opti.solver("ipopt", {"print_time": False}, IPOPT_OPTIONS)
    try:
        values = opti.solve().value
    except RuntimeError:
        status = opti.stats().get("return_status", "?")
        raise PimannError(None, f"DCM/ZMP plan not solved (ipopt: {status})") from None
    states = np.asarray(values(state)).reshape(4, n + 1)
    zmp_values = np.asarray(values(zmp)).reshape(2, n).T
    residual = lipm_residual(states, zmp_values, a, b)
    if not np.isfinite(residual) or residual > MAX_RESIDUAL:
        raise PimannError(None, f"DCM/ZMP plan violates the LIPM by {residual:.1e}")
    com = np.column_stack([states[0], states[1], np.full(n + 1, params.com_height)])
    velocity = np.column_stack([states[2], states[3], np.zeros(n + 1)])
    log.debug("DCM plan: %d knots over %.1f s", n, plan.duration)
    return DCMPlan(time, com, velocity, zmp_values, omega, support)
