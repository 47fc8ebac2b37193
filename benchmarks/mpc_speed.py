"""Solve time of the online controller's centroidal MPC per solver, side by side, on one core.

Walks a synthetic stepping plan with the MPC alone, ipopt first; every other solver then
solves the same horizons in the same order, each warm started from its own last solution as
the closed loop does. Per solver: build time, median and 95th percentile per solve (wall, and
this process's CPU time: on a shared machine the wall time includes waiting) against the
period, how far its solutions lie from ipopt's (CoM along the horizon, first-interval
forces), and, without `--smoke`, the MuJoCo closed loop's real-time factor with that solver
(a 2-step walk, whether it fell). The process is pinned to one core.

    python -m benchmarks.mpc_speed [solves] [--solvers ipopt,rti-piqp,...] [--smoke]

`--smoke`: a 4-knot horizon, 3 solves, no closed loop: checks that the benchmark still runs.
The solvers: ipopt (MUMPS; the reference), fatrop (the stage-wise NLP), rti-piqp and
rti-osqp (one convex QP a horizon: pimann.sim.centroidal_mpc.SequentialQp).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import time

import numpy as np

from pimann.core.errors import PimannError
from pimann.core.params import MpcParams, load_params
from pimann.sim.centroidal_mpc import CentroidalMPC, MpcProblem, horizon_problem, knot_count
from pimann.sim.synthetic import stepping_plan

FEET = np.array([[0.0, 0.1, 0.0], [0.0, -0.1, 0.0]])
SOLE_Z = -0.002
SOLVERS = ["ipopt", "fatrop", "rti-piqp", "rti-osqp"]


def _walk(mpc: CentroidalMPC, solves: int, params: MpcParams) -> list[MpcProblem]:
    """The horizons of `solves` MPC periods along a 4-step plan, each from the last solution's
    next knot (solved by `mpc`)."""
    plan = stepping_plan(FEET, 4, 0.2, single=0.7, double=0.2, start=0.3, end=0.5)
    nominal = tuple(f.positions.copy() for f in plan.feet)
    reference = np.tile([0.0, 0.0, 0.7], (knot_count(params) + 1, 1))
    com, velocity, angular = np.array([0.0, 0.0, 0.7]), np.zeros(3), np.zeros(3)
    problems = []
    for k in range(solves):
        problem = horizon_problem(
            plan, nominal, k * params.dt, params, com, velocity, angular, reference, SOLE_Z
        )
        solution = mpc.solve(problem)
        problems.append(problem)
        com, velocity = solution.com[1], solution.com_velocity[1]
        angular = solution.angular_momentum[1]
    return problems


def _closed_loop(solver: str, steps: int = 2) -> tuple[float, float, float, bool]:
    """The MuJoCo loop with the online controller and `solver`: its real-time factor, median
    and p95 solve, and whether the robot fell."""
    from pimann.core.robot import load_robot
    from pimann.sim.closed_loop import simulate_trajectory
    from pimann.sim.synthetic import standing_feet, stepping_trajectory
    from pimann.sim.wbc import standing_pose

    params = load_params().simulate
    mpc = dataclasses.replace(params.mpc, solver=solver)
    fast = dataclasses.replace(
        params, speed_scale=1.0, step_scale=0.5, zmp_hold_s=0.6, end_hold_s=0.3, mpc=mpc
    )
    robot = load_robot("simulation")
    feet = standing_feet(robot, standing_pose(robot, params))
    source = stepping_plan(feet, steps, 0.1, start=0.2, end=0.2)
    result = simulate_trajectory(stepping_trajectory(robot, fast, source), fast, None, "online")
    times = result.mpc_solve_s
    return (
        result.real_time_factor,
        float(np.median(times)),
        float(np.quantile(times, 0.95)),
        result.fallen,
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("solves", type=int, nargs="?", default=None, help="solves (60)")
    parser.add_argument("--solvers", help="comma-separated subset of " + ",".join(SOLVERS))
    parser.add_argument("--smoke", action="store_true", help="tiny sizes: check that it runs")
    args = parser.parse_args(argv)
    core = min(os.sched_getaffinity(0))
    os.sched_setaffinity(0, {core})  # one core, as the robot's controller would have
    params = load_params().simulate.mpc
    if args.smoke:
        params = dataclasses.replace(params, horizon_s=4 * params.dt)
    solves = args.solves if args.solves is not None else 3 if args.smoke else 60
    chosen = args.solvers.split(",") if args.solvers else SOLVERS
    period = params.dt * 1e3
    print(
        f"centroidal MPC: {knot_count(params)} knots of {period:.0f} ms, {solves} warm-started "
        f"solves along a 4-step walk, period {period:.0f} ms, core {core}"
    )
    reference_mpc = CentroidalMPC(params, "ipopt")
    problems = _walk(reference_mpc, solves, params)
    reference_mpc.previous = None
    header = (
        f"{'solver':<10} {'build s':>7} {'median ms':>9} {'p95 ms':>7} {'cpu med':>7} "
        f"{'cpu p95':>7} {'p95<=T/2':>8} {'CoM vs ipopt':>12} "
        f"{'f0 vs ipopt':>11}"
    )
    if not args.smoke:
        header += f" {'loop RTF':>8} {'loop med':>8} {'loop p95':>8}  fell"
    print(header)
    reference = None
    for name in ["ipopt"] + [s for s in chosen if s != "ipopt"]:
        start = time.perf_counter()
        mpc = CentroidalMPC(params, name)
        build = time.perf_counter() - start
        try:
            solutions = [mpc.solve(problem) for problem in problems]
        except PimannError as error:
            print(f"{name:<10} {build:>7.2f}  failed: {error.problem}")
            continue
        if name == "ipopt":
            reference = solutions
        wall = np.array([s.solve_s for s in solutions[1:]]) * 1e3  # the first is cold
        cpu = np.array([s.solve_cpu_s for s in solutions[1:]]) * 1e3
        com = max(np.abs(a.com - b.com).max() for a, b in zip(reference, solutions, strict=True))
        first = max(
            np.abs(a.forces[:, :, 0] - b.forces[:, :, 0]).max()
            for a, b in zip(reference, solutions, strict=True)
        )
        fits = "yes" if np.quantile(wall, 0.95) <= params.dt * 1e3 / 2 else "no"
        line = (
            f"{name:<10} {build:>7.2f} {np.median(wall):>9.1f} {np.quantile(wall, 0.95):>7.1f} "
            f"{np.median(cpu):>7.1f} {np.quantile(cpu, 0.95):>7.1f} {fits:>8} {com:>12.1e} "
            f"{first:>11.1e}"
        )
        if not args.smoke:
            rtf, median, p95, fallen = _closed_loop(name)
            line += f" {rtf:>7.2f}x {median * 1e3:>8.1f} {p95 * 1e3:>8.1f}  {fallen}"
        print(line, flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
