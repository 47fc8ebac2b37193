"""Solve time of the online controller's centroidal MPC against its period, per casadi solver.

Walks a synthetic stepping plan with the MPC alone (each solve starts from the previous
solution's next knot, warm started), on one thread, for every solver casadi ships that takes
this nonlinear problem: ipopt (MUMPS), sqpmethod with each QP solver, fatrop. Prints per
solver the median and 95th percentile per solve against the period (wall time, and this
process's CPU time: on a shared machine the wall time includes waiting), the failures, and how far
its solutions lie from ipopt's (the same problem solved: CoM and footsteps agree). Without
`--smoke` it also times the MuJoCo closed loop with the online controller (real-time factor).
Usage: python -m benchmarks.mpc_speed [solves] [--budget S] [--solvers ipopt,...] [--smoke]

`--smoke`: a 4-knot horizon, 3 solves, no closed loop: checks that the benchmark still runs.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import os
import sys
import time
from collections.abc import Iterator

import casadi as ca
import numpy as np

from pimann.core.errors import PimannError
from pimann.core.params import MpcParams, load_params
from pimann.sim.centroidal_mpc import CentroidalMPC, horizon_problem, knot_count
from pimann.sim.synthetic import stepping_plan

FEET = np.array([[0.0, 0.1, 0.0], [0.0, -0.1, 0.0]])
SOLE_Z = -0.002
# the Hessian of the torques' cross products is indefinite: the QPs get a convexified one
QUIET_SQP = {"print_header": False, "print_iteration": False, "print_status": False,
             "max_iter": 50, "convexify_strategy": "regularize"}  # fmt: skip
# the QP solvers' own options: silent, and a failed QP is left to the SQP's globalisation
QP_OPTIONS = {
    "qpoases": {"printLevel": "none", "error_on_fail": False},
    "osqp": {"osqp": {"verbose": False}, "error_on_fail": False},
    "daqp": {"error_on_fail": False},
    "proxqp": {"error_on_fail": False},
    "highs": {"highs": {"output_flag": False}, "error_on_fail": False},
}


@contextlib.contextmanager
def _quiet() -> Iterator[None]:
    """The solvers' C++ output goes nowhere: fatrop's structure detection warns once per row
    and sqpmethod prints every input of a failed solve; the table says what failed."""
    sys.stdout.flush()
    saved = [os.dup(1), os.dup(2)]
    with open(os.devnull, "w") as null:
        os.dup2(null.fileno(), 1)
        os.dup2(null.fileno(), 2)
        try:
            yield
        finally:
            for fd, copy in zip((1, 2), saved, strict=True):
                os.dup2(copy, fd)
                os.close(copy)


def solver_options() -> dict[str, tuple[str, dict]]:
    """Every solver setup to try: name -> (casadi nlpsol plugin, its options)."""
    setups: dict[str, tuple[str, dict]] = {"ipopt": ("ipopt", {})}
    for qp, options in QP_OPTIONS.items():
        if ca.has_conic(qp):
            setups[f"sqpmethod+{qp}"] = (
                "sqpmethod", {**QUIET_SQP, "qpsol": qp, "qpsol_options": options}
            )  # fmt: skip
    if ca.has_nlpsol("fatrop"):
        setups["fatrop"] = ("fatrop", {"structure_detection": "auto", "fatrop": {"print_level": 0}})
    return setups


def _walk(
    mpc: CentroidalMPC, solves: int, params: MpcParams, budget_s: float
) -> tuple[list[float], list[float], list, str]:
    """Solve `solves` horizons along the plan, each from the last solution's next knot.

    A solver that has spent `budget_s` stops early (the table says after how many solves).
    """
    plan = stepping_plan(FEET, 4, 0.2, single=0.7, double=0.2, start=0.3, end=0.5)
    nominal = tuple(f.positions.copy() for f in plan.feet)
    reference = np.tile([0.0, 0.0, 0.7], (knot_count(params) + 1, 1))
    com, velocity, angular = np.array([0.0, 0.0, 0.7]), np.zeros(3), np.zeros(3)
    times, cpu, solutions, failure = [], [], [], ""
    mpc.previous = None
    for k in range(solves):
        if sum(times) > budget_s:
            failure = f"stopped after {k} solves: over the {budget_s:.0f} s budget"
            break
        t = k * params.dt
        problem = horizon_problem(plan, nominal, t, params, com, velocity, angular, reference,
                                  SOLE_Z)  # fmt: skip
        try:
            solution = mpc.solve(problem)
        except PimannError as error:
            failure = f"t = {t:.2f} s: {error.problem}"
            break
        times.append(solution.solve_s)
        cpu.append(solution.solve_cpu_s)
        solutions.append(solution)
        com, velocity = solution.com[1], solution.com_velocity[1]
        angular = solution.angular_momentum[1]
    return times, cpu, solutions, failure


def _closed_loop_rtf(steps: int) -> tuple[float, float, bool]:
    """Real-time factor of the MuJoCo loop with the online controller, its median solve, fall."""
    from pimann.core.robot import load_robot
    from pimann.sim.run import simulate_trajectory
    from pimann.sim.synthetic import standing_feet, stepping_trajectory
    from pimann.sim.wbc import standing_pose

    params = load_params().simulate
    fast = dataclasses.replace(params, speed_scale=1.0, step_scale=0.5, zmp_hold_s=0.6,
                               end_hold_s=0.3)  # fmt: skip
    robot = load_robot("simulation")
    feet = standing_feet(robot, standing_pose(robot, params))
    source = stepping_plan(feet, steps, 0.1, start=0.2, end=0.2)
    result = simulate_trajectory(stepping_trajectory(robot, fast, source), fast, None, "online")
    return result.real_time_factor, float(np.median(result.mpc_solve_s)), result.fallen


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("solves", type=int, nargs="?", default=None, help="solves (40)")
    parser.add_argument("--budget", type=float, default=60.0, help="s of solving per solver")
    parser.add_argument("--solvers", help="comma-separated subset of the table's solver names")
    parser.add_argument("--smoke", action="store_true", help="tiny sizes: check that it runs")
    args = parser.parse_args(argv)
    params = load_params().simulate.mpc
    if args.smoke:
        params = dataclasses.replace(params, horizon_s=4 * params.dt)
    solves = args.solves if args.solves is not None else 3 if args.smoke else 40
    print(f"centroidal MPC: {knot_count(params)} knots of {params.dt * 1e3:.0f} ms, {solves} "
          f"warm-started solves along a 4-step walk, period {params.dt * 1e3:.0f} ms")  # fmt: skip
    print(f"{'solver':<20} {'build s':>8} {'median ms':>10} {'p95 ms':>8} {'cpu med':>8} "
          f"{'cpu p95':>8} {'real time':>10} {'vs ipopt m':>11}  failure")  # fmt: skip
    reference = None
    chosen = args.solvers.split(",") if args.solvers else None
    for name, (plugin, options) in solver_options().items():
        if chosen is not None and name not in chosen:
            continue
        start = time.perf_counter()
        try:
            with _quiet():
                mpc = CentroidalMPC(params, plugin, options)
        except RuntimeError as error:
            text = str(error)
            why = ("structure detection failed: the problem is not declared stage by stage"
                   if "structure" in text.lower() else text.splitlines()[-1][:80])  # fmt: skip
            print(f"{name:<20} {'-':>8} {'-':>10} {'-':>8} {'-':>8} {'-':>8} {'-':>10} {'-':>11}  "
                  f"build: {why}")  # fmt: skip
            continue
        build = time.perf_counter() - start
        with _quiet():
            times, cpu, solutions, failure = _walk(mpc, solves, params, args.budget)
        if name == "ipopt":
            reference = solutions
        gap = "-"
        if reference and solutions:
            shared = min(len(reference), len(solutions))
            gap = f"{max(np.abs(a.com - b.com).max() for a, b in zip(reference[:shared], solutions[:shared], strict=True)):.1e}"  # noqa: E501
        if times:
            median, p95 = np.median(times) * 1e3, np.quantile(times, 0.95) * 1e3
            cpu_median, cpu_p95 = np.median(cpu) * 1e3, np.quantile(cpu, 0.95) * 1e3
            fits = "yes" if p95 <= params.dt * 1e3 else "no"
            print(f"{name:<20} {build:>8.2f} {median:>10.1f} {p95:>8.1f} {cpu_median:>8.1f} "
                  f"{cpu_p95:>8.1f} {fits:>10} {gap:>11}  {failure or '-'}"[:160])  # fmt: skip
        else:
            print(f"{name:<20} {build:>8.2f} {'-':>10} {'-':>8} {'-':>8} {'-':>8} {'-':>10} "
                  f"{'-':>11}  {failure}")  # fmt: skip
    if not args.smoke:
        rtf, median, fallen = _closed_loop_rtf(2)
        print(f"closed loop (MuJoCo, online controller, 2 steps): real-time factor {rtf:.2f}x, "
              f"median solve {median * 1e3:.0f} ms, fell: {fallen}")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
