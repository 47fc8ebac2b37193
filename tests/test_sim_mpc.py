"""The online centroidal MPC with real casadi/ipopt, and its closed loop in MuJoCo."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from pimann.core.errors import PimannError
from pimann.core.params import MpcParams, SimulateRun, load_params
from pimann.core.rotations import rot_z
from pimann.sim.centroidal_mpc import (
    GRAVITY,
    CentroidalMPC,
    MpcProblem,
    MpcSolution,
    corners,
    horizon_problem,
    knot_count,
    landing_box,
)
from pimann.sim.synthetic import stepping_plan

SOLE_Z = -0.002
FEET = np.array([[0.0, 0.1, 0.0], [0.0, -0.1, 0.0]])
COM = np.array([0.0, 0.0, 0.7])


SOLVERS = ["ipopt", "fatrop", "rti-piqp", "rti-osqp"]


@pytest.fixture(scope="module", params=SOLVERS)
def mpc(request) -> CentroidalMPC:
    """The MPC with each solver: every test below holds for each."""
    return CentroidalMPC(MpcParams(), request.param)


def _problem(plan, t: float, params: MpcParams, velocity=(0.0, 0.0, 0.0), com=COM) -> MpcProblem:
    nominal = tuple(f.positions.copy() for f in plan.feet)
    reference = np.tile(COM, (knot_count(params) + 1, 1))
    return horizon_problem(
        plan,
        nominal,
        t,
        params,
        np.asarray(com, float),
        np.asarray(velocity, float),
        np.zeros(3),
        reference,
        SOLE_Z,
    )


def _solve(mpc: CentroidalMPC, problem: MpcProblem) -> MpcSolution:
    mpc.previous = None  # every test from the same cold start
    return mpc.solve(problem)


def test_standing_holds_the_com_with_forces_in_the_cone(mpc):
    params = mpc.params
    plan = stepping_plan(FEET, 0, 0.0)
    problem = _problem(plan, 0.0, params)
    assert problem.contact.all()  # both feet carry the robot on every interval
    solution = _solve(mpc, problem)
    assert np.abs(solution.com - COM).max() < 1e-3
    assert np.abs(solution.com_velocity).max() < 1e-2
    # the feet carry the weight, each corner inside the linearised cone, in its foot's frame
    np.testing.assert_allclose(solution.forces[..., 2].sum(axis=(0, 1)), -GRAVITY[2], rtol=0.01)
    bound = params.friction / np.sqrt(2.0)
    for side in (0, 1):
        for knot in range(knot_count(params)):
            local = rot_z(problem.yaw[side, knot]).T @ solution.forces[side, :, knot].T  # (3, 4)
            assert (local[2] >= -1e-6).all()
            assert (np.abs(local[:2]) <= bound * local[2] + 1e-6).all()
    np.testing.assert_allclose(
        solution.feet[:, :, :2], np.repeat(FEET[:, None, :2], 21, 1), atol=1e-9
    )


def _forward_euler(problem: MpcProblem, solution: MpcSolution, params: MpcParams):
    """The states the solution's forces give by forward Euler, integrated here from scratch."""
    dt, local = params.dt, corners(params)
    c, v, angular = problem.com.copy(), problem.com_velocity.copy(), problem.angular_momentum.copy()
    states = [(c, v, angular)]
    for k in range(knot_count(params)):
        force, torque = np.zeros(3), np.zeros(3)
        for side in (0, 1):
            a = problem.contact[side, k]
            for j in range(4):
                f = solution.forces[side, j, k]
                point = rot_z(problem.yaw[side, k]) @ local[j] + solution.feet[side, k]
                force += a * f
                torque += a * np.cross(point - c, f)
        c, v, angular = (
            c + v * dt,
            v + (GRAVITY + force + problem.external_force) * dt,
            (angular + torque * dt),
        )
        states.append((c, v, angular))
    return [np.array(s) for s in zip(*states, strict=True)]


def test_dynamics_match_forward_euler_while_stepping(mpc):
    """A forward step from a moving CoM: the solution obeys the closed-form Euler recursion."""
    params = mpc.params
    plan = stepping_plan(FEET, 2, 0.2)
    problem = _problem(plan, 0.3, params, velocity=(0.2, 0.05, 0.0))
    assert (problem.contact.sum(axis=0) == 1).any()  # a single support inside the horizon
    solution = _solve(mpc, problem)
    com, velocity, angular = _forward_euler(problem, solution, params)
    np.testing.assert_allclose(solution.com, com, atol=1e-6)
    np.testing.assert_allclose(solution.com_velocity, velocity, atol=1e-6)
    np.testing.assert_allclose(solution.angular_momentum, angular, atol=1e-6)
    assert np.abs(angular).max() > 1e-4  # the check saw torques, not zeros


def test_a_commanded_step_lands_inside_its_box(mpc):
    """Pushed forward hard, the right foot's next landing moves to the box's front edge."""
    params = mpc.params
    plan = stepping_plan(FEET, 2, 0.2)  # the right foot steps first: off 0.5 s, on 1.2 s
    problem = _problem(plan, 0.3, params, velocity=(0.5, 0.0, 0.0))
    landing = np.flatnonzero(problem.landing[1])
    assert len(landing) and not problem.landing[0].any()
    solution = _solve(mpc, problem)
    nominal = plan.feet[1].positions[1]
    box = landing_box(params, 1)
    offset = solution.feet[1, landing, :2] - nominal  # yaw 0: the foot frame is the world's
    assert (offset[:, 0] >= box[0, 0] - 1e-6).all() and (offset[:, 0] <= box[0, 1] + 1e-6).all()
    assert (offset[:, 1] >= box[1, 0] - 1e-6).all() and (offset[:, 1] <= box[1, 1] + 1e-6).all()
    assert offset[:, 0].min() > box[0, 1] - 1e-3  # it wanted further: the box held it
    np.testing.assert_allclose(solution.feet[1, landing, 2], SOLE_Z, atol=1e-9)


@pytest.mark.parametrize("direction", [-1.0, 1.0])
def test_a_sideways_push_moves_the_next_footstep_its_way(mpc, direction):
    """A constant sideways force (1.5 m/s^2, beyond what mu = 0.1 can resist): the MPC steps."""
    params = mpc.params
    plan = stepping_plan(FEET, 2, 0.2)
    calm = _solve(mpc, _problem(plan, 0.3, params))
    problem = _problem(plan, 0.3, params)
    problem.external_force = np.array([0.0, 1.5 * direction, 0.0])
    pushed = _solve(mpc, problem)
    landing = np.flatnonzero(problem.landing[1])[0]
    moved = pushed.feet[1, landing, 1] - calm.feet[1, landing, 1]
    assert direction * moved > 0.005


def test_a_frozen_footstep_does_not_move(mpc):
    """Less than freeze_s before touchdown the landing is fixed, whatever the push."""
    params = mpc.params
    plan = stepping_plan(FEET, 2, 0.2)
    problem = _problem(plan, 1.1, params)  # right touchdown at 1.2 s: frozen
    assert not problem.landing[1].any()
    problem.external_force = np.array([0.0, -1.5, 0.0])
    solution = _solve(mpc, problem)
    on = np.flatnonzero(problem.contact[1])
    np.testing.assert_allclose(solution.feet[1, on[-1], :2], plan.feet[1].positions[1], atol=1e-6)


def test_an_unsolvable_horizon_is_an_error():
    """CoM height bounds out of the forces' reach by knot 2 (5 m up): ipopt's status is named."""
    params = dataclasses.replace(MpcParams(), com_z_min=5.0, com_z_max=5.1)
    problem = _problem(stepping_plan(FEET, 0, 0.0), 0.0, params)
    with pytest.raises(PimannError, match="centroidal MPC not solved \\(ipopt: Infeasible"):
        CentroidalMPC(params, "ipopt").solve(problem)
    with pytest.raises(PimannError, match="not solved \\(piqp QP: primal infeasible"):
        CentroidalMPC(params, "rti-piqp").solve(problem)


def test_online_walk_in_mujoco(sim_robot, sim_params):
    """Two steps with the online controller: no fall, the feet land near the plan, MPC timed."""
    from pimann.sim.closed_loop import simulate_trajectory
    from pimann.sim.synthetic import standing_feet, stepping_trajectory
    from pimann.sim.wbc import standing_pose

    fast = dataclasses.replace(
        sim_params, speed_scale=1.0, step_scale=0.5, zmp_hold_s=0.6, end_hold_s=0.3
    )
    feet = standing_feet(sim_robot, standing_pose(sim_robot, sim_params))
    plan = stepping_plan(feet, steps=2, step=0.1, start=0.2, end=0.2)
    result = simulate_trajectory(stepping_trajectory(sim_robot, fast, plan), fast, None, "online")
    assert not result.fallen and result.controller == "online"
    assert result.time[-1] == pytest.approx(result.planned_duration, abs=0.011)
    assert result.foot_slip < 0.01 and result.base_height.min() > 0.7
    np.testing.assert_allclose(result.soles_final[:, :2], result.soles_planned[:, :2], atol=0.015)
    period = sim_params.mpc.dt
    assert len(result.mpc_solve_s) == pytest.approx(result.time[-1] / period, abs=1.0)
    summary = result.summary()
    assert summary["controller"] == "online" and summary["mpc_solve_median_s"] > 0


def test_a_failed_online_run_is_named_and_the_others_finish(tmp_path, sim_robot, sim_params):
    """An online run whose MPC cannot be solved is recorded; the offline run beside it walks."""
    from pimann.core.rollout_files import RolloutKey, rollout_path
    from pimann.core.trajectory import write_trajectory
    from pimann.sim.run_list import simulate_runs
    from pimann.sim.synthetic import standing_feet, stepping_trajectory
    from pimann.sim.wbc import standing_pose

    q0 = standing_pose(sim_robot, sim_params)
    plan = stepping_plan(standing_feet(sim_robot, q0), 2, 0.1, single=0.35, double=0.1)
    walk = stepping_trajectory(sim_robot, sim_params, plan, 25.0)
    rollouts = tmp_path / "rollouts"
    runs = [
        SimulateRun("w10", 0, "forward", True, False, controller=c) for c in ("online", "offline")
    ]
    path = rollout_path(rollouts, RolloutKey("w10", 0, "forward", True))
    path.parent.mkdir(parents=True)
    write_trajectory(path, walk)
    unsolvable = dataclasses.replace(sim_params.mpc, com_z_min=5.0, com_z_max=5.1)
    no_pushes = dataclasses.replace(sim_params.pushes, rollouts=[])
    short = dataclasses.replace(
        sim_params, runs=runs, mpc=unsolvable, zmp_hold_s=0.3, end_hold_s=0.2, pushes=no_pushes
    )
    params = dataclasses.replace(load_params(), simulate=short)
    record = simulate_runs(rollouts, tmp_path / "sim", tmp_path / "summary.json", params)
    assert record["failed_runs"] == ["w10-0-forward-steering-online"]
    failure = record["runs"]["w10-0-forward-steering-online"]
    assert "simulate run w10-0-forward-steering-online" in failure["failed"]
    assert "centroidal MPC not solved" in failure["failed"]
    assert failure["controller"] == "online" and failure["success"] is False
    walked = record["runs"]["w10-0-forward-steering"]
    assert walked["controller"] == "offline" and "failed" not in walked
    assert json.loads((tmp_path / "summary.json").read_text())["failed_runs"] == [
        "w10-0-forward-steering-online"
    ]
    assert (tmp_path / "sim" / "w10-0-forward-steering.h5").is_file()


def test_bisection_finds_the_threshold_from_below():
    from pimann.sim.pushes import largest_survived

    tried = []

    def survives(force: float) -> bool:
        tried.append(force)
        return force <= 123.0

    found = largest_survived(survives, 300.0, 5.0)
    assert 118.0 <= found <= 123.0 and tried[0] == 300.0
    assert largest_survived(lambda force: True, 300.0, 5.0) == 300.0
    assert largest_survived(lambda force: False, 300.0, 5.0) < 5.0


def test_pushes_point_where_they_should():
    """Lateral: toward the swing foot's side; forward: along the stance heading; mid swing."""
    from pimann.sim.pushes import push_at_mid_single_support

    plan = stepping_plan(FEET, 2, 0.2)  # the right foot swings first, 0.5 s to 1.2 s
    lateral = push_at_mid_single_support(plan, "lateral", 100.0, 0.1)
    np.testing.assert_allclose(lateral.force, [0.0, -100.0, 0.0], atol=1e-9)
    assert lateral.start == pytest.approx(0.85 - 0.05)
    np.testing.assert_allclose(lateral.at(0.85), lateral.force)
    np.testing.assert_allclose(lateral.at(0.95), 0.0)
    forward = push_at_mid_single_support(plan, "forward", 50.0, 0.1)
    np.testing.assert_allclose(forward.force, [50.0, 0.0, 0.0], atol=1e-9)


def _two_step_walk(sim_robot, sim_params):
    """(params at full speed, the synthetic 2-step walk, its footstep plan) for the push tests."""
    from pimann.sim.footsteps import extract_footsteps
    from pimann.sim.synthetic import standing_feet, stepping_trajectory
    from pimann.sim.wbc import standing_pose

    fast = dataclasses.replace(
        sim_params, speed_scale=1.0, step_scale=0.5, zmp_hold_s=0.6, end_hold_s=0.3
    )
    q0 = standing_pose(sim_robot, sim_params)
    source = stepping_plan(standing_feet(sim_robot, q0), steps=2, step=0.1, start=0.2, end=0.2)
    walk = stepping_trajectory(sim_robot, fast, source)
    return fast, walk, extract_footsteps(sim_robot, walk, fast, standing_feet(sim_robot, q0))


def test_a_hard_push_fells_the_robot_and_none_does_not(sim_robot, sim_params):
    """The offline controller in MuJoCo: 0 N walks on, a 400 N lateral push knocks it over."""
    from pimann.sim.closed_loop import simulate_trajectory
    from pimann.sim.pushes import push_at_mid_single_support

    fast, walk, plan = _two_step_walk(sim_robot, sim_params)
    outcomes = []
    for force in (0.0, 400.0):
        push = push_at_mid_single_support(plan, "lateral", force, 0.1)
        result = simulate_trajectory(walk, fast, push.start + 1.5, "offline", push)
        outcomes.append(result.fallen)
    assert outcomes == [False, True]


def test_online_controller_steps_out_under_a_lateral_push(sim_robot, sim_params):
    """MuJoCo, 60 N for 0.1 s toward the swing foot: its landing moves out, the robot stays up."""
    from pimann.sim.closed_loop import simulate_trajectory
    from pimann.sim.pushes import push_at_mid_single_support

    fast, walk, plan = _two_step_walk(sim_robot, sim_params)
    swing = int(np.argmin([plan.feet[s].t_off[0] for s in (0, 1)]))
    landings = []
    for force in (0.0, 60.0):
        push = push_at_mid_single_support(plan, "lateral", force, 0.1)
        result = simulate_trajectory(walk, fast, push.start + 0.6, "online", push)
        assert not result.fallen
        landings.append(result.footsteps.feet[swing].positions[1].copy())
    outward = np.array([0.0, 1.0 if swing == 0 else -1.0])
    assert (landings[1] - landings[0]) @ outward > 0.005
    box = landing_box(sim_params.mpc, swing)
    offset = landings[1] - plan.feet[swing].positions[1]
    assert box[1, 0] - 1e-6 <= offset[1] <= box[1, 1] + 1e-6


def test_cli_simulates_with_the_online_controller(tmp_path, capsys, sim_robot, sim_params):
    from pimann.cli import main
    from pimann.core.trajectory import write_trajectory
    from pimann.sim.synthetic import standing_feet, stepping_trajectory
    from pimann.sim.wbc import standing_pose

    q0 = standing_pose(sim_robot, sim_params)
    plan = stepping_plan(standing_feet(sim_robot, q0), 2, 0.1, single=0.35, double=0.1)
    source = tmp_path / "walk.h5"
    write_trajectory(source, stepping_trajectory(sim_robot, sim_params, plan, 25.0))
    argv = [
        "simulate",
        str(source),
        "-o",
        str(tmp_path / "sim.h5"),
        "--duration",
        "0.6",
        "--controller",
        "online",
    ]
    assert main(argv) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["controller"] == "online" and not summary["fallen"]
    assert summary["mpc_solve_median_s"] > 0 and summary["simulated_s"] == pytest.approx(0.6)


def _horizons(params: MpcParams) -> list[MpcProblem]:
    """The horizons of the tests above: standing, stepping from a moving CoM, pushed both ways,
    a frozen footstep."""
    standing = _problem(stepping_plan(FEET, 0, 0.0), 0.0, params)
    plan = stepping_plan(FEET, 2, 0.2)
    problems = [
        standing,
        _problem(plan, 0.3, params, velocity=(0.2, 0.05, 0.0)),
        _problem(plan, 0.3, params, velocity=(0.5, 0.0, 0.0)),
    ]
    for t, push in ((0.3, 1.5), (0.3, -1.5), (1.1, -1.5)):
        problem = _problem(plan, t, params)
        problem.external_force = np.array([0.0, push, 0.0])
        problems.append(problem)
    return problems


# how far a solver's solution may lie from ipopt's on the same horizon: CoM (m), CoM velocity
# (m/s), feet (m), corner forces (per unit mass, m/s^2, of a 9.81 total)
AGREE = {
    "fatrop": {"com": 1e-5, "com_velocity": 1e-5, "footsteps": 1e-5, "forces": 1e-4},
    "rti-piqp": {"com": 1e-4, "com_velocity": 1e-3, "footsteps": 1e-4, "forces": 1e-3},
    "rti-osqp": {"com": 1e-4, "com_velocity": 1e-4, "footsteps": 1e-4, "forces": 1e-4},
}


def _gaps(problem: MpcProblem, a: MpcSolution, b: MpcSolution) -> dict[str, float]:
    """How far two solutions of one horizon lie apart. Footsteps: the soles where they stand or
    land (an airborne sole's path is nearly free: only a 1e-3 weight on its velocity)."""
    ground = np.concatenate([problem.contact, problem.contact[:, -1:]], 1) > 0
    ground |= problem.landing > 0
    return {
        "com": np.abs(a.com - b.com).max(),
        "com_velocity": np.abs(a.com_velocity - b.com_velocity).max(),
        "footsteps": np.abs(a.feet - b.feet)[ground].max(),
        "forces": np.abs(a.forces - b.forces).max(),
    }


@pytest.mark.parametrize("solver", list(AGREE))
def test_each_solver_solves_the_tests_horizons_as_ipopt(solver):
    """Cold, each rti solver iterates its QPs until the step vanishes: ipopt's solution."""
    params = MpcParams()
    reference, other = CentroidalMPC(params, "ipopt"), CentroidalMPC(params, solver)
    for problem in _horizons(params):
        gaps = _gaps(problem, _solve(reference, problem), _solve(other, problem))
        for field, tolerance in AGREE[solver].items():
            assert gaps[field] <= tolerance, (field, gaps[field])


def _holds_cones_and_boxes(problem: MpcProblem, solution: MpcSolution, params: MpcParams):
    bound = params.friction / np.sqrt(2.0)
    for side in (0, 1):
        for knot in range(knot_count(params)):
            local = rot_z(problem.yaw[side, knot]).T @ solution.forces[side, :, knot].T
            assert (local[2] >= -1e-6).all()
            assert (np.abs(local[:2]) <= bound * local[2] + 1e-6).all()
    assert (solution.feet >= problem.lower - 1e-6).all()
    assert (solution.feet <= problem.upper + 1e-6).all()


# on a closed loop's horizons, each solved warm from the last as the loop does: the forces
# of the first interval (what the loop applies, m/s^2 of 9.81), the CoM along the horizon
# (m), the landings the MPC moved (m), the first interval's ZMP (m). A real-time iteration
# is one QP a horizon: its CoM far down the horizon trails the converged one by about 1 mm.
LOOP_AGREE = {
    "fatrop": {"first_forces": 1e-4, "com": 1e-4, "landing": 1e-5, "zmp": 1e-5},
    "rti-piqp": {"first_forces": 1e-3, "com": 3e-3, "landing": 1e-3, "zmp": 2e-4},
    "rti-osqp": {"first_forces": 1e-2, "com": 3e-3, "landing": 1e-3, "zmp": 2e-4},
}


@pytest.fixture(scope="module")
def loop_horizons(sim_robot, sim_params) -> list[MpcProblem]:
    """Every horizon of a 2-step MuJoCo walk under the online controller (params' solver)."""
    from pimann.sim.closed_loop import simulate_trajectory
    from pimann.sim.synthetic import standing_feet, stepping_trajectory
    from pimann.sim.wbc import standing_pose

    fast = dataclasses.replace(
        sim_params, speed_scale=1.0, step_scale=0.5, zmp_hold_s=0.6, end_hold_s=0.3
    )
    feet = standing_feet(sim_robot, standing_pose(sim_robot, sim_params))
    plan = stepping_plan(feet, steps=2, step=0.1, start=0.2, end=0.2)
    result = simulate_trajectory(stepping_trajectory(sim_robot, fast, plan), fast, None, "online")
    assert not result.fallen and len(result.mpc_horizons) == len(result.mpc_solve_s) > 30
    return result.mpc_horizons


@pytest.fixture(scope="module")
def loop_reference(loop_horizons, sim_params) -> list[MpcSolution]:
    """ipopt's solutions of the closed loop's horizons, each warm from the last."""
    reference = CentroidalMPC(sim_params.mpc, "ipopt")
    return [reference.solve(problem) for problem in loop_horizons]


@pytest.mark.parametrize("solver", list(LOOP_AGREE))
def test_each_solver_follows_ipopt_along_a_closed_loops_horizons(
    solver, loop_horizons, loop_reference, sim_params
):
    params = sim_params.mpc
    other = CentroidalMPC(params, solver)
    worst = dict.fromkeys(LOOP_AGREE[solver], 0.0)
    moved = 0
    for problem, a in zip(loop_horizons, loop_reference, strict=True):
        b = other.solve(problem)
        _holds_cones_and_boxes(problem, b, params)
        landing = problem.landing > 0
        moved += int(landing.any())
        gaps = {
            "first_forces": np.abs(a.forces[:, :, 0] - b.forces[:, :, 0]).max(),
            "com": np.abs(a.com - b.com).max(),
            "landing": np.abs(a.feet - b.feet)[landing].max() if landing.any() else 0.0,
            "zmp": np.abs(a.zmp(problem, params) - b.zmp(problem, params)).max(),
        }
        worst = {k: max(worst[k], gaps[k]) for k in worst}
    assert moved > 5  # the comparison saw landings the MPC may move
    for field, tolerance in LOOP_AGREE[solver].items():
        assert worst[field] <= tolerance, (field, worst[field])
