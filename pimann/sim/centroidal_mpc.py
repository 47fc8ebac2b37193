"""Online centroidal MPC with step adjustment (Romualdi et al.), the paper's second controller.

casadi Opti, multiple shooting, forward Euler, mass normalised to 1. State: CoM c, CoM
velocity, angular momentum L (per unit mass); per foot its position and a velocity used only
in the air; per foot corner a force. Footsteps more than `freeze_s` before their touchdown
may move inside a landing box around the nominal one, so a push is answered by stepping.
The problem is built once and compiled with `opti.to_function`; every solve is warm started
from the previous one.

Contacts come from the footstep plan resampled on the MPC's knots: a foot carries forces on
an interval only when both its knots lie in the same contact phase (`a_i`), and then it does
not move.
"""

from __future__ import annotations

import dataclasses
import logging
import time

import casadi as ca
import numpy as np

from pimann.core.errors import PimannError
from pimann.core.params import MpcParams
from pimann.core.rotations import rot_z
from pimann.sim.footsteps import FootstepPlan

GRAVITY = np.array([0.0, 0.0, -9.81])
FREE = 1.0e3  # m: a position bound that never binds
log = logging.getLogger(__name__)


def knot_count(params: MpcParams) -> int:
    return int(round(params.horizon_s / params.dt))


def corners(params: MpcParams) -> np.ndarray:
    """(4, 3) the force corners in the foot frame."""
    x, y = params.corner_x, params.corner_y
    return np.array([[x, y, 0.0], [x, -y, 0.0], [-x, y, 0.0], [-x, -y, 0.0]])


def landing_box(params: MpcParams, side: int) -> np.ndarray:
    """(2, 2) [[x_low, x_high], [y_low, y_high]] in the foot frame; y mirrored for the right."""
    y = np.array(params.box_y, dtype=float)
    return np.array([params.box_x, y if side == 0 else -y[::-1]], dtype=float)


@dataclasses.dataclass
class MpcProblem:
    """One horizon's data, all in the plan's world (N knots intervals, N+1 knots)."""

    com: np.ndarray  # (3,) measured
    com_velocity: np.ndarray  # (3,)
    angular_momentum: np.ndarray  # (3,) per unit mass, about the CoM
    feet: np.ndarray  # (2, 3) sole positions now
    contact: np.ndarray  # (2, N) a_i: the foot carries forces (and stays put) on interval k
    yaw: np.ndarray  # (2, N+1) each foot's yaw at each knot
    nominal: np.ndarray  # (2, N+1, 3) nominal sole position at each knot (its footstep's)
    lower: np.ndarray  # (2, N+1, 3) bounds on the sole positions (landing boxes, world)
    upper: np.ndarray  # (2, N+1, 3)
    landing: np.ndarray  # (2, N+1) 1 where the footstep cost applies (a future footstep)
    com_reference: np.ndarray  # (N+1, 3)
    angular_momentum_reference: np.ndarray  # (N+1, 3)
    external_force: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(3))  # / mass


@dataclasses.dataclass
class MpcSolution:
    com: np.ndarray  # (N+1, 3)
    com_velocity: np.ndarray  # (N+1, 3)
    angular_momentum: np.ndarray  # (N+1, 3)
    feet: np.ndarray  # (2, N+1, 3)
    forces: np.ndarray  # (2, 4, N, 3) corner forces per unit mass, world frame
    solve_s: float  # wall time of the solve
    solve_cpu_s: float = 0.0  # this process's CPU time in it (a loaded machine's wall time lies)

    def zmp(self, problem: MpcProblem, params: MpcParams, knot: int = 0) -> np.ndarray:
        """Where the net contact force of interval `knot`, drawn through the CoM, meets the floor.

        The MPC may also spend its forces on angular momentum (the corner forces' centre of
        pressure, `centre_of_pressure`), but the IK does not track angular momentum: the ZMP
        that goes with the CoM's acceleration when the angular momentum stays put is the one
        the whole-body layer can follow.
        """
        total = self.forces[:, :, knot].sum(axis=(0, 1))
        height = self.com[knot, 2] - problem.feet[:, 2].min()
        return self.com[knot, :2] - height * total[:2] / max(total[2], 1e-9)

    def centre_of_pressure(self, problem: MpcProblem, params: MpcParams, knot: int = 0):
        """The centre of pressure of interval `knot`'s corner forces (flat ground)."""
        local = corners(params)
        points, weights = [], []
        for side in (0, 1):
            rotation = rot_z(problem.yaw[side, knot])
            for j in range(4):
                points.append(self.feet[side, knot, :2] + (rotation @ local[j])[:2])
                weights.append(self.forces[side, j, knot, 2])
        weights = np.clip(weights, 0.0, None)
        return (np.array(points) * weights[:, None]).sum(axis=0) / max(weights.sum(), 1e-9)


class CentroidalMPC:
    """The MPC, built and compiled once per parameter set and solver."""

    def __init__(
        self, params: MpcParams, solver: str = "ipopt", solver_options: dict | None = None
    ):
        self.params = params
        self.n = n = knot_count(params)
        self.solver = solver
        self.previous: list | None = None
        opti = ca.Opti()
        dt = params.dt
        c = opti.variable(3, n + 1)
        dc = opti.variable(3, n + 1)
        angular = opti.variable(3, n + 1)
        feet = [opti.variable(3, n + 1) for _ in (0, 1)]
        swing = [opti.variable(3, n) for _ in (0, 1)]
        forces = [[opti.variable(3, n) for _ in range(4)] for _ in (0, 1)]
        p_c0, p_dc0, p_l0 = opti.parameter(3), opti.parameter(3), opti.parameter(3)
        p_feet0 = [opti.parameter(3) for _ in (0, 1)]
        p_contact = [opti.parameter(1, n) for _ in (0, 1)]
        p_cos = [opti.parameter(1, n + 1) for _ in (0, 1)]
        p_sin = [opti.parameter(1, n + 1) for _ in (0, 1)]
        p_nominal = [opti.parameter(3, n + 1) for _ in (0, 1)]
        p_lower = [opti.parameter(3, n + 1) for _ in (0, 1)]
        p_upper = [opti.parameter(3, n + 1) for _ in (0, 1)]
        p_landing = [opti.parameter(1, n + 1) for _ in (0, 1)]
        p_com_ref = opti.parameter(3, n + 1)
        p_l_ref = opti.parameter(3, n + 1)
        p_external = opti.parameter(3)
        gravity = ca.DM(GRAVITY)
        local = corners(params)
        mu = params.friction / np.sqrt(2.0)  # inner pyramid of the cone
        opti.subject_to(c[:, 0] == p_c0)
        opti.subject_to(dc[:, 0] == p_dc0)
        opti.subject_to(angular[:, 0] == p_l0)
        for side in (0, 1):
            opti.subject_to(feet[side][:, 0] == p_feet0[side])
        cost = 0
        in_contact = p_contact[0] + p_contact[1]
        for k in range(n):
            total = ca.MX.zeros(3, 1)
            torque = ca.MX.zeros(3, 1)
            for side in (0, 1):
                a = p_contact[side][k]
                cos, sin = p_cos[side][k], p_sin[side][k]
                for j in range(4):
                    f = forces[side][j][:, k]
                    arm = (
                        ca.vertcat(
                            cos * local[j, 0] - sin * local[j, 1],
                            sin * local[j, 0] + cos * local[j, 1],
                            0.0,
                        )
                        + feet[side][:, k]
                        - c[:, k]
                    )
                    total += a * f
                    torque += a * ca.cross(arm, f)
                    # friction cone and unilaterality in the foot frame; no force in the air
                    fx = cos * f[0] + sin * f[1]
                    fy = -sin * f[0] + cos * f[1]
                    opti.subject_to(f[2] >= 0)
                    opti.subject_to(f[2] <= a * 10.0 * -GRAVITY[2])
                    opti.subject_to(opti.bounded(-mu * f[2], fx, mu * f[2]))
                    opti.subject_to(opti.bounded(-mu * f[2], fy, mu * f[2]))
                    # vertical force toward the weight shared by the corners in contact
                    share = -GRAVITY[2] / (4.0 * ca.fmax(in_contact[k], 1.0))
                    cost += params.force_vertical_weight * a * (f[2] - share) ** 2
                mean = sum(forces[side][j][:, k] for j in range(4)) / 4.0
                cost += params.force_mean_weight * sum(
                    ca.sumsqr(forces[side][j][:, k] - mean) for j in range(4)
                )
                opti.subject_to(
                    feet[side][:, k + 1] == feet[side][:, k] + (1 - a) * swing[side][:, k] * dt
                )
                cost += params.swing_velocity_weight * ca.sumsqr(swing[side][:, k])
            opti.subject_to(c[:, k + 1] == c[:, k] + dc[:, k] * dt)
            opti.subject_to(dc[:, k + 1] == dc[:, k] + (gravity + total + p_external) * dt)
            opti.subject_to(angular[:, k + 1] == angular[:, k] + torque * dt)
        rate = ca.DM(params.force_rate_weight)
        for side in (0, 1):
            for j in range(4):
                step = forces[side][j][:, 1:] - forces[side][j][:, :-1]
                cost += ca.sum2(ca.sum1(rate * step**2))
            opti.subject_to(opti.bounded(p_lower[side], feet[side], p_upper[side]))
            error = feet[side] - p_nominal[side]
            cost += params.footstep_weight * ca.sum2(p_landing[side] * ca.sum1(error**2))
        cost += params.angular_momentum_weight * ca.sumsqr(angular - p_l_ref)
        wx, wy, wz = params.com_weight
        cost += wx * ca.sumsqr(c[0, :] - p_com_ref[0, :])
        cost += wy * ca.sumsqr(c[1, :] - p_com_ref[1, :])
        decay = ca.DM(0.5 * wz * (1.0 + np.exp(-np.arange(n + 1)))).T
        cost += ca.sumsqr(decay * (c[2, :] - p_com_ref[2, :]))
        # from knot 2: knot 1 follows from the measured state alone (c + cdot dt), and bounding
        # it makes the horizon infeasible whenever a push has the CoM moving vertically
        opti.subject_to(opti.bounded(params.com_z_min, c[2, 2:], params.com_z_max))
        opti.minimize(cost)
        # expanded to scalar graphs: twice as fast per iteration as the matrix graph; a failed
        # solve is read from the stats (an exception would print every input to stdout)
        options = {"print_time": False, "error_on_fail": False, "expand": True}
        if solver == "ipopt":
            inner = {"print_level": 0, "sb": "yes", "max_iter": params.max_iterations,
                     "linear_solver": "mumps"}  # fmt: skip
            options.update(solver_options or {})
            opti.solver("ipopt", options, inner)
        else:
            options.update(solver_options or {})
            opti.solver(solver, options)
        self.variables = [c, dc, angular, *feet, *swing, *[f for side in forces for f in side]]
        parameters = [p_c0, p_dc0, p_l0, *p_feet0, *p_contact, *p_cos, *p_sin, *p_nominal,
                      *p_lower, *p_upper, *p_landing, p_com_ref, p_l_ref, p_external]  # fmt: skip
        # the constraints' multipliers travel too: ipopt's warm start needs them
        self.function = opti.to_function(
            "centroidal_mpc", parameters + self.variables + [opti.lam_g],
            self.variables + [opti.lam_g],
        )  # fmt: skip
        self.constraints = opti.ng

    def _guess(self, problem: MpcProblem) -> list[np.ndarray]:
        """The previous solution, or a standing one: CoM on its reference, weight on the feet."""
        if self.previous is not None:
            return self.previous
        n = self.n
        share = -GRAVITY[2] / (4.0 * np.maximum(problem.contact.sum(axis=0), 1.0))
        force = [np.vstack([np.zeros((2, n)), problem.contact[s] * share]) for s in (0, 1)]
        return [
            np.tile(problem.com[:, None], (1, n + 1)),
            np.zeros((3, n + 1)),
            np.zeros((3, n + 1)),
            *[np.tile(problem.feet[s][:, None], (1, n + 1)) for s in (0, 1)],
            np.zeros((3, n)),
            np.zeros((3, n)),
            *[force[s] for s in (0, 1) for _ in range(4)],
            np.zeros(self.constraints),
        ]

    def solve(self, problem: MpcProblem) -> MpcSolution:
        """Solve one horizon; a failed solve raises PimannError with the solver's status."""
        inputs = [
            problem.com, problem.com_velocity, problem.angular_momentum,
            *problem.feet, *problem.contact[:, None, :],
            *np.cos(problem.yaw)[:, None, :], *np.sin(problem.yaw)[:, None, :],
            *problem.nominal.transpose(0, 2, 1), *problem.lower.transpose(0, 2, 1),
            *problem.upper.transpose(0, 2, 1), *problem.landing[:, None, :],
            problem.com_reference.T, problem.angular_momentum_reference.T,
            problem.external_force,
        ]  # fmt: skip
        start, cpu = time.perf_counter(), time.process_time()
        out = None
        while out is None:
            warm = self.previous is not None
            out = self.function(*inputs, *self._guess(problem))
            stats = self.function.stats()
            if not stats.get("success", False):
                status = stats.get("return_status", "unknown status")
                out = None
                self.previous = None
                if warm:  # a warm start far from the pushed state can stall ipopt: once cold
                    log.debug("centroidal MPC: %s from the warm start; retried cold", status)
                    continue
                raise PimannError(None, f"centroidal MPC not solved ({self.solver}: {status})")
        elapsed, cpu = time.perf_counter() - start, time.process_time() - cpu
        values = [np.asarray(v) for v in out]
        if not all(np.all(np.isfinite(v)) for v in values):
            self.previous = None
            raise PimannError(None, f"centroidal MPC gave non-finite values ({self.solver})")
        self.previous = values
        c, dc, angular, left, right, _, _, *flat, _ = values
        forces = np.array([[flat[4 * s + j].T for j in range(4)] for s in (0, 1)])
        feet = np.array([left.T, right.T])
        return MpcSolution(c.T, dc.T, angular.T, feet, forces, elapsed, cpu)


def horizon_problem(
    plan: FootstepPlan,
    nominal: tuple[np.ndarray, np.ndarray],
    t: float,
    params: MpcParams,
    com: np.ndarray,
    com_velocity: np.ndarray,
    angular_momentum: np.ndarray,
    com_reference: np.ndarray,
    sole_z: float,
) -> MpcProblem:
    """The horizon from robot time t: contacts, yaws and landing boxes from the footstep plan.

    `plan` holds the adjusted footsteps (frozen ones are kept where they are), `nominal` each
    foot's (n, 2) footsteps as first planned (the box centres and the footstep cost's target).
    """
    n = knot_count(params)
    times = t + np.arange(n + 1) * params.dt
    clipped = np.clip(times, 0.0, plan.duration)
    index = np.array([[plan.stance_index(s, u) for u in clipped] for s in (0, 1)], dtype=object)
    contact = np.zeros((2, n))
    yaw = np.zeros((2, n + 1))
    target = np.zeros((2, n + 1, 3))
    lower = np.full((2, n + 1, 3), -FREE)
    upper = np.full((2, n + 1, 3), FREE)
    landing = np.zeros((2, n + 1))
    feet = np.array([plan.foot_pose(s, t)[0] for s in (0, 1)])
    for side in (0, 1):
        steps = plan.feet[side]
        box = landing_box(params, side)
        for k, u in enumerate(clipped):
            m = index[side, k]
            yaw[side, k] = plan.foot_pose(side, u)[1]
            if m is None:
                target[side, k] = plan.foot_pose(side, u)[0]
                continue
            if k < n and index[side, k + 1] == m:
                contact[side, k] = 1.0
            target[side, k] = [*nominal[side][m], sole_z]
            if steps.t_on[m] <= t + 1e-9:  # the stance it stands on now: where it is
                lower[side, k] = upper[side, k] = feet[side]
            elif steps.t_on[m] - t <= params.freeze_s:  # frozen where it was last adjusted
                lower[side, k] = upper[side, k] = [*steps.positions[m], sole_z]
            else:  # inside the landing box, in the nominal footstep's frame
                landing[side, k] = 1.0
                rotation = rot_z(steps.yaws[m])[:2, :2]
                cornered = np.array([rotation @ [x, y] for x in box[0] for y in box[1]])
                lower[side, k] = [*(nominal[side][m] + cornered.min(axis=0)), sole_z]
                upper[side, k] = [*(nominal[side][m] + cornered.max(axis=0)), sole_z]
    return MpcProblem(
        com=np.asarray(com, dtype=float),
        com_velocity=np.asarray(com_velocity, dtype=float),
        angular_momentum=np.asarray(angular_momentum, dtype=float),
        feet=feet,
        contact=contact,
        yaw=yaw,
        nominal=target,
        lower=lower,
        upper=upper,
        landing=landing,
        com_reference=np.asarray(com_reference, dtype=float),
        angular_momentum_reference=np.zeros((n + 1, 3)),
    )
