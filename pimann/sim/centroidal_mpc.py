"""Online centroidal MPC with step adjustment (Romualdi et al.), the paper's second controller.

casadi Opti, multiple shooting, forward Euler, mass normalised to 1. State: CoM c, CoM
velocity, angular momentum L (per unit mass); per foot its position and a velocity used only
in the air; per foot corner a force. Footsteps more than `freeze_s` before their touchdown
may move inside a landing box around the nominal one, so a push is answered by stepping.
The problem is stated stage by stage and built once per solver (`simulate.mpc.solver`):
ipopt or fatrop solve it to convergence, rti-<qp> by one convex QP a horizon
(`SequentialQp`); every solve is warm started from the previous one, one knot on.

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


# each QP solver's options: silent, accurate enough to agree with ipopt's solution, warm
# started in primal and dual where the solver can be
QP_OPTIONS = {
    "osqp": {
        "osqp": {
            "verbose": False,
            "eps_abs": 1e-8,
            "eps_rel": 1e-8,
            "max_iter": 20000,
            "polish": True,
        },
        "warm_start_primal": True,
        "warm_start_dual": True,
    },
    "piqp": {},
}


class SequentialQp:
    """The MPC's NLP by sequential quadratic programming, one convex QP per iteration.

    The cost is quadratic and every constraint linear but the angular momentum's torques,
    bilinear in the CoM, the feet and the forces: linearised at the current point, with the
    cost's own (positive semidefinite) Hessian, every QP is convex, which an exact Lagrangian
    Hessian is not. Full steps: from a warm start (the previous horizon's solution one knot
    on) one iteration is a real-time iteration (Diehl et al.); from a cold start it iterates
    until the step vanishes.
    """

    def __init__(
        self,
        opti: ca.Opti,
        parameters: list,
        variables: list,
        qp_solver: str,
        options: dict,
        iterations: int = 1,
    ):
        x = opti.x
        hessian, gradient = ca.hessian(opti.f, x)
        jacobian = ca.jacobian(opti.g, x)
        offset = opti.g - ca.mtimes(jacobian, x)  # g(x) = offset + J x, near the point
        outputs = [
            hessian,
            gradient - ca.mtimes(hessian, x),
            jacobian,
            opti.lbg - offset,
            opti.ubg - offset,
        ]
        self.data = ca.Function("qp_data", [opti.p, x], outputs).expand()
        self.pack_parameters = ca.Function("pack_parameters", parameters, [opti.p])
        self.pack = ca.Function("pack", variables, [x])
        self.unpack = ca.Function("unpack", [x], variables)
        sparsity = {"h": self.data.sparsity_out(0), "a": self.data.sparsity_out(2)}
        merged = {"error_on_fail": False, **QP_OPTIONS[qp_solver], **options}
        self.qp = ca.conic("mpc_qp", qp_solver, sparsity, merged)
        self.name = qp_solver
        self.warm_iterations, self.cold_iterations, self.tolerance = iterations, 20, 1e-6

    def solve(
        self, parameters: list, guess: list[np.ndarray], multipliers: np.ndarray | None
    ) -> tuple[list[np.ndarray], np.ndarray]:
        """(variables, the last QP's multipliers) from `guess`; raises PimannError when a QP
        fails."""
        p = self.pack_parameters(*parameters)
        x = self.pack(*guess)
        lam = ca.DM.zeros(self.data.size1_out(2)) if multipliers is None else multipliers
        iterations = self.cold_iterations if multipliers is None else self.warm_iterations
        for _ in range(iterations):
            h, g, a, lba, uba = self.data(p, x)
            out = self.qp(h=h, g=g, a=a, lba=lba, uba=uba, x0=x, lam_a0=lam)
            if not self.qp.stats().get("success", False):
                status = self.qp.stats().get("return_status", "unknown status")
                raise PimannError(None, f"centroidal MPC not solved ({self.name} QP: {status})")
            step = float(ca.mmax(ca.fabs(out["x"] - x)))
            x, lam = out["x"], out["lam_a"]
            if step < self.tolerance:
                break
        return [np.asarray(v) for v in self.unpack(x)], np.asarray(lam)


# the stage vectors: state x_k = [c, cdot, L, left sole, right sole, the previous interval's
# corner forces (a copy, so that the force-rate cost couples no two stages)], control u_k =
# [left swing velocity, right swing velocity, corner forces (side-major, 4 corners x 3)]
COM, VELOCITY, MOMENTUM, PREVIOUS = slice(0, 3), slice(3, 6), slice(6, 9), slice(15, 39)
NX, NU = 39, 30


def _sole(side: int) -> slice:
    return slice(9 + 3 * side, 12 + 3 * side)


def _swing(side: int) -> slice:
    return slice(3 * side, 3 * side + 3)


def _force(side: int, corner: int) -> slice:
    start = 6 + 12 * side + 3 * corner
    return slice(start, start + 3)


class CentroidalMPC:
    """The MPC, built and compiled once per parameter set and solver.

    Stated stage by stage, as structure-exploiting solvers need it: the variables in the
    order x_0, u_0, x_1, u_1, ..., x_N; the constraints per stage, [dynamics_k as x_{k+1} -
    F(x_k, u_k) (the next state's coefficient exactly 1), path constraints_k]; the cost a sum
    of terms each within one stage. The solvers: ipopt (the reference), fatrop (the same NLP
    by its Riccati-structured interior point) and rti-<qp> (SequentialQp with piqp or osqp).
    """

    def __init__(
        self, params: MpcParams, solver: str | None = None, solver_options: dict | None = None
    ):
        """`solver`: params.solver unless given (a casadi nlpsol plugin, or rti-<conic>)."""
        self.params = params
        self.n = n = knot_count(params)
        self.solver = solver = solver or params.solver
        self.previous: list | None = None
        opti = ca.Opti()
        dt = params.dt
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
        parameters = [
            p_c0,
            p_dc0,
            p_l0,
            *p_feet0,
            *p_contact,
            *p_cos,
            *p_sin,
            *p_nominal,
            *p_lower,
            *p_upper,
            *p_landing,
            p_com_ref,
            p_l_ref,
            p_external,
        ]
        x, u = [], []
        for k in range(n + 1):  # declared in stage order: x_0, u_0, x_1, ...
            x.append(opti.variable(NX))
            if k < n:
                u.append(opti.variable(NU))
        gravity = ca.DM(GRAVITY)
        local = corners(params)
        mu = params.friction / np.sqrt(2.0)  # inner pyramid of the cone
        rate = ca.DM(params.force_rate_weight)
        wx, wy, wz = params.com_weight
        z_weight = 0.5 * wz * (1.0 + np.exp(-np.arange(n + 1)))
        in_contact = p_contact[0] + p_contact[1]
        cost = 0
        ng = []
        for k in range(n + 1):
            rows = opti.ng
            xk = x[k]
            c = xk[COM]
            if k < n:  # the dynamics of interval k, then stage k's path constraints
                uk = u[k]
                total, torque = ca.MX.zeros(3, 1), ca.MX.zeros(3, 1)
                soles = []
                for side in (0, 1):
                    a = p_contact[side][k]
                    cos, sin = p_cos[side][k], p_sin[side][k]
                    for j in range(4):
                        f = uk[_force(side, j)]
                        arm = ca.vertcat(
                            cos * local[j, 0] - sin * local[j, 1],
                            sin * local[j, 0] + cos * local[j, 1],
                            0.0,
                        )
                        total += a * f
                        torque += a * ca.cross(arm + xk[_sole(side)] - c, f)
                    soles.append(xk[_sole(side)] + (1 - a) * uk[_swing(side)] * dt)
                following = ca.vertcat(
                    c + xk[VELOCITY] * dt,
                    xk[VELOCITY] + (gravity + total + p_external) * dt,
                    xk[MOMENTUM] + torque * dt,
                    *soles,
                    uk[6:],
                )
                opti.subject_to(x[k + 1] == following)  # g = x_{k+1} - F(x_k, u_k)
                rows = opti.ng
            if k == 0:  # the measured state; the force copy before the horizon is unused
                opti.subject_to(xk[COM] == p_c0)
                opti.subject_to(xk[VELOCITY] == p_dc0)
                opti.subject_to(xk[MOMENTUM] == p_l0)
                for side in (0, 1):
                    opti.subject_to(xk[_sole(side)] == p_feet0[side])
                opti.subject_to(xk[PREVIOUS] == 0)
            if k < n:
                for side in (0, 1):
                    a = p_contact[side][k]
                    cos, sin = p_cos[side][k], p_sin[side][k]
                    forces = [uk[_force(side, j)] for j in range(4)]
                    for f in forces:
                        # friction cone and unilaterality in the foot frame; no force in the air
                        fx = cos * f[0] + sin * f[1]
                        fy = -sin * f[0] + cos * f[1]
                        opti.subject_to(opti.bounded(0, f[2], a * 10.0 * -GRAVITY[2]))
                        opti.subject_to(opti.bounded(-mu * f[2], fx, mu * f[2]))
                        opti.subject_to(opti.bounded(-mu * f[2], fy, mu * f[2]))
                        # vertical force toward the weight shared by the corners in contact
                        share = -GRAVITY[2] / (4.0 * ca.fmax(in_contact[k], 1.0))
                        cost += params.force_vertical_weight * a * (f[2] - share) ** 2
                    mean = sum(forces) / 4.0
                    cost += params.force_mean_weight * sum(ca.sumsqr(f - mean) for f in forces)
                    cost += params.swing_velocity_weight * ca.sumsqr(uk[_swing(side)])
                if k > 0:  # the force rate against the copy of interval k-1's forces
                    step = ca.reshape(uk[6:] - xk[PREVIOUS], 3, 8)
                    cost += ca.sum2(ca.sum1(rate * step**2))
            for side in (0, 1):
                sole = xk[_sole(side)]
                opti.subject_to(opti.bounded(p_lower[side][:, k], sole, p_upper[side][:, k]))
                error = sole - p_nominal[side][:, k]
                cost += params.footstep_weight * p_landing[side][k] * ca.sumsqr(error)
            if k >= 2:  # knot 1 follows from the measured state alone (c + cdot dt): bounding
                # it makes the horizon infeasible whenever a push moves the CoM vertically
                opti.subject_to(opti.bounded(params.com_z_min, c[2], params.com_z_max))
            cost += params.angular_momentum_weight * ca.sumsqr(xk[MOMENTUM] - p_l_ref[:, k])
            cost += wx * (c[0] - p_com_ref[0, k]) ** 2 + wy * (c[1] - p_com_ref[1, k]) ** 2
            cost += (z_weight[k] * (c[2] - p_com_ref[2, k])) ** 2
            ng.append(opti.ng - rows)
        opti.minimize(cost)
        self.variables = [v for k in range(n + 1) for v in ([x[k], u[k]] if k < n else [x[k]])]
        self.constraints = opti.ng
        self.structure = {"N": n, "nx": [NX] * (n + 1), "nu": [NU] * n + [0], "ng": ng}
        self.sqp: SequentialQp | None = None
        if solver.startswith("rti-"):
            options = dict(solver_options or {})
            iterations = int(options.pop("iterations", params.sqp_iterations))
            self.sqp = SequentialQp(
                opti, parameters, self.variables, solver[4:], options, iterations
            )
            return
        # expanded to scalar graphs: twice as fast per iteration as the matrix graph; a failed
        # solve is read from the stats (an exception would print every input to stdout)
        options = {"print_time": False, "error_on_fail": False, "expand": True}
        if solver == "ipopt":
            inner = {
                "print_level": 0,
                "sb": "yes",
                "max_iter": params.max_iterations,
                "linear_solver": "mumps",
            }
            options.update(solver_options or {})
            opti.solver("ipopt", options, inner)
        elif solver == "fatrop":
            options["fatrop"] = {"print_level": 0, "max_iter": params.max_iterations}
            options.update(solver_options or {})
            if options.get("structure_detection", "manual") == "manual":
                options.update({"structure_detection": "manual", **self.structure})
            opti.solver("fatrop", options)
        else:
            options.update(solver_options or {})
            opti.solver(solver, options)
        # the constraints' multipliers travel too: ipopt's warm start needs them
        self.function = opti.to_function(
            "centroidal_mpc",
            parameters + self.variables + [opti.lam_g],
            self.variables + [opti.lam_g],
        )

    def _guess(self, problem: MpcProblem) -> list[np.ndarray]:
        """A standing start: the CoM where it is, the weight on the feet in contact."""
        n = self.n
        share = -GRAVITY[2] / (4.0 * np.maximum(problem.contact.sum(axis=0), 1.0))
        forces = np.zeros((n, NU))
        for side in (0, 1):
            for j in range(4):
                forces[:, _force(side, j).start + 2] = problem.contact[side] * share
        guess = []
        for k in range(n + 1):
            state = np.zeros(NX)
            state[COM] = problem.com
            state[9:15] = problem.feet.ravel()
            if k > 0:
                state[PREVIOUS] = forces[k - 1, 6:]
            guess.append(state[:, None])
            if k < n:
                guess.append(forces[k][:, None])
        return guess

    def _shifted(self, values: list[np.ndarray]) -> list[np.ndarray]:
        """The previous horizon's stage vectors one knot on, the last stage's repeated."""
        return values[2:] + values[-2:]

    def solve(self, problem: MpcProblem) -> MpcSolution:
        """Solve one horizon; a failed solve raises PimannError with the solver's status."""
        inputs = [
            problem.com,
            problem.com_velocity,
            problem.angular_momentum,
            *problem.feet,
            *problem.contact[:, None, :],
            *np.cos(problem.yaw)[:, None, :],
            *np.sin(problem.yaw)[:, None, :],
            *problem.nominal.transpose(0, 2, 1),
            *problem.lower.transpose(0, 2, 1),
            *problem.upper.transpose(0, 2, 1),
            *problem.landing[:, None, :],
            problem.com_reference.T,
            problem.angular_momentum_reference.T,
            problem.external_force,
        ]
        start, cpu = time.perf_counter(), time.process_time()
        if self.sqp is not None:
            return self._solve_sqp(inputs, problem, start, cpu)
        out = None
        while out is None:
            warm = self.previous is not None
            if warm:
                *values, multipliers = self.previous
                guess = [*self._shifted(values), multipliers]
            else:
                guess = [*self._guess(problem), np.zeros(self.constraints)]
            out = self.function(*inputs, *guess)
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
        return self._solution(values[:-1], elapsed, cpu)

    def _solve_sqp(
        self, inputs: list, problem: MpcProblem, start: float, cpu: float
    ) -> MpcSolution:
        """solve() by SequentialQp: warm from the previous solution shifted by one knot."""
        assert self.sqp is not None
        if self.previous is None:
            guess, multipliers = self._guess(problem), None
        else:
            *values, multipliers = self.previous
            guess = self._shifted(values)
        try:
            values, multipliers = self.sqp.solve(inputs, guess, multipliers)
        except PimannError:
            if self.previous is None:
                raise
            self.previous = None  # a warm start far from a pushed state: once cold
            return self._solve_sqp(inputs, problem, start, cpu)
        if not all(np.all(np.isfinite(v)) for v in values):
            self.previous = None
            raise PimannError(None, f"centroidal MPC gave non-finite values ({self.solver})")
        self.previous = [*values, multipliers]
        return self._solution(values, time.perf_counter() - start, time.process_time() - cpu)

    def _solution(self, values: list[np.ndarray], elapsed: float, cpu: float) -> MpcSolution:
        """The stage vectors [x_0, u_0, ..., x_N] as trajectories."""
        states = np.hstack(values[0::2]).T  # (N+1, NX)
        controls = np.hstack(values[1::2]).T  # (N, NU)
        feet = np.array([states[:, _sole(side)] for side in (0, 1)])
        forces = np.array([[controls[:, _force(s, j)] for j in range(4)] for s in (0, 1)])
        return MpcSolution(
            states[:, COM], states[:, VELOCITY], states[:, MOMENTUM], feet, forces, elapsed, cpu
        )


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
