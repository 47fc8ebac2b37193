"""Real-time factor of the MuJoCo closed loop (goal >= 1x) and of its parts.

Runs the paper's offline controller (0.33x speed, 0.4x step size) on a synthetic stepping
trajectory and prints: physics alone, the whole loop (IK + feedback + physics), the DCM plan
time, and the walk's figures (slip, fall, joint tracking).
Usage: python -m benchmarks.sim_speed [steps] [step_length_m] [--smoke]

`--smoke`: the same parts with tiny sizes (500 physics steps, a walk of 1 step unless `steps`
is given), to check that the benchmark still runs.
"""

from __future__ import annotations

import argparse
import sys
import time

import mujoco
import pinocchio as pin

from pimann.core.params import load_params
from pimann.core.robot import load_robot
from pimann.sim.closed_loop import simulate_plan
from pimann.sim.dcm import plan_dcm
from pimann.sim.footsteps import extract_footsteps
from pimann.sim.model import build_sim_model
from pimann.sim.synthetic import standing_feet, stepping_plan, stepping_trajectory
from pimann.sim.wbc import standing_pose


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("steps", type=int, nargs="?", default=None, help="walk steps (6)")
    parser.add_argument("length", type=float, nargs="?", default=0.3, help="step length (m)")
    parser.add_argument("--smoke", action="store_true", help="tiny sizes: check that it runs")
    args = parser.parse_args(argv)
    steps = args.steps if args.steps is not None else 1 if args.smoke else 6
    length = args.length
    params = load_params().simulate
    robot = load_robot("simulation")
    sim = build_sim_model(params)
    q0 = standing_pose(robot, params)

    data = sim.new_data()
    sim.set_configuration(data, robot, q0)
    n = 500 if args.smoke else 10000
    start = time.perf_counter()
    for _ in range(n):
        mujoco.mj_step(sim.model, data)
    physics = n * params.timestep / (time.perf_counter() - start)
    print(f"physics only (standing, {n} steps of {params.timestep * 1e3:.0f} ms): {physics:.1f}x")

    feet = standing_feet(robot, q0)
    # a human-like generated walk: 0.35 s single + 0.1 s double support, steps of `length`
    source = stepping_plan(feet, steps, length, single=0.35, double=0.1, start=0.3, end=0.3)
    trajectory = stepping_trajectory(robot, params, source)
    plan = extract_footsteps(robot, trajectory, params, feet)
    start = time.perf_counter()
    dcm = plan_dcm(plan, params, pin.centerOfMass(robot.model, robot.data, q0))
    plan_time = time.perf_counter() - start
    print(f"DCM/ZMP plan over {plan.duration:.1f} s: {plan_time:.2f} s")
    result = simulate_plan(plan, dcm, params, q0, robot=robot, sim=sim)
    print(
        f"closed loop ({result.time[-1]:.1f} s simulated, {steps} steps of "
        f"{length * params.step_scale:.3f} m): {result.real_time_factor:.1f}x real time "
        f"(goal >= 1x: {'met' if result.real_time_factor >= 1 else 'NOT met'})"
    )
    print(
        f"fallen {result.fallen}, slip {result.foot_slip * 100:.2f} cm, joint RMSE "
        f"{result.joint_rmse:.4f} rad, final sole error "
        f"{abs(result.soles_final - result.soles_planned)[:, :2].max() * 100:.2f} cm"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
