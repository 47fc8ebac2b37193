"""Contact-consistent trajectories (pimann.generate.contact_consistent): a glide removed, the
swing untouched, the leg IK checked against pinocchio's forward kinematics."""

from __future__ import annotations

import dataclasses
import re

import numpy as np
import pinocchio as pin
import pytest
from builders import GaitModel, roll
from scipy.spatial.transform import Rotation

from pimann.core.contacts import FEET, foot_kinematics, trajectory_configurations, true_runs
from pimann.core.params import MotionSegment, load_params
from pimann.core.robot import LEFT_SOLE, LEG_JOINTS, RIGHT_SOLE
from pimann.generate.contact_consistent import (
    FLAT_SHARE,
    LIFT_SPEED,
    MAX_HOLD_GAP,
    MAX_LIFT_GAP,
    LegSolution,
    LegSolver,
    lift_heights,
    lowest_heights,
    make_consistent,
    post_holds,
    retry_from_neighbours,
    without_yaw,
    world_soles,
)

GLIDE = 0.03  # m the base (and so every foot on the floor) is pushed during one stance


@pytest.fixture(scope="module")
def params():
    return load_params()


@pytest.fixture(scope="module")
def gait(robot, params):
    """A stepping rollout of the analytic gait model (crouched legs: every sole reachable)."""
    script = [MotionSegment(4.0, 0.4, 0.0, 0.0)]
    return roll(GaitModel(robot), script, params, False, robot).trajectory


def _glide(trajectory, start: int, stop: int):
    """The trajectory with its base pushed GLIDE m sideways over frames start..stop (then kept
    there): every foot on the floor then glides GLIDE m."""
    push = np.clip((np.arange(len(trajectory)) - start) / (stop - start), 0.0, 1.0)
    base = trajectory.base_position.copy()
    base[:, 1] += GLIDE * push
    return dataclasses.replace(trajectory, base_position=base)


def _world_soles(robot, trajectory):
    feet = foot_kinematics(robot, trajectory_configurations(robot, trajectory))
    return feet.positions, feet.rotations


def test_a_glide_is_removed_and_the_swing_untouched(robot, params, gait):
    runs = [(a, b) for a, b in true_runs(gait.contacts[:, 0]) if a > 50 and b - a >= 20]
    start, stop = runs[0][0] + 6, runs[0][1] - 6  # inside a left stance, off its blends
    raw = _glide(gait, start, stop)
    out = make_consistent(raw, robot, params.rollout.consistent, params.contacts)
    trajectory = out.trajectory
    positions, rotations = _world_soles(robot, trajectory)
    raw_positions, raw_rotations = _world_soles(robot, raw)
    held = out.held  # (T, 2) both weights 1, on the floor: the foot is held
    # the raw left sole glides the push; ours stays within 1 mm over the whole stance
    stance = np.arange(start, stop + 1)
    assert held[stance, 0].all()
    raw_travel = np.linalg.norm(raw_positions[stance, 0] - raw_positions[start, 0], axis=1)
    assert raw_travel.max() > 0.9 * GLIDE
    for foot in (0, 1):
        for a, b in true_runs(held[:, foot]):
            drift = np.linalg.norm(positions[a:b, foot] - positions[a, foot], axis=1)
            assert drift.max() < 1e-3, (foot, a, b, drift.max())
            # flat on the floor, yaw kept
            np.testing.assert_allclose(positions[a:b, foot, 2], 0.0, atol=1e-3)
            np.testing.assert_allclose(rotations[a:b, foot, 2, 2], 1.0, atol=1e-6)
    assert out.residual[held].max() < params.rollout.consistent.tolerance
    # a foot the hold leaves alone (both weights 0) is the network's to rounding
    free = out.weights.max(axis=-1) <= 0.0
    assert free.sum() > 50
    np.testing.assert_allclose(positions[free], raw_positions[free], atol=1e-9)
    np.testing.assert_allclose(rotations[free], raw_rotations[free], atol=1e-9)
    # the base and every joint but the legs' untouched
    others = np.setdiff1d(np.arange(26), LEG_JOINTS)
    np.testing.assert_array_equal(
        trajectory.joint_positions[:, others], raw.joint_positions[:, others]
    )
    np.testing.assert_array_equal(trajectory.base_position, raw.base_position)
    # joint velocities: the network's plus the correction's change, so a free leg keeps its own
    correction = trajectory.joint_positions - raw.joint_positions
    expected = raw.joint_velocities[1:] + np.diff(correction, axis=0) * raw.rate_hz
    np.testing.assert_allclose(trajectory.joint_velocities[1:], expected, atol=1e-9)
    # touchdown and lift-off blended: the correction's largest change in a frame is well
    # below that of holds switched in one frame (after the start, where the model's first
    # step lifts its foot 6 cm in a frame and the held one rises at `LIFT_SPEED`)
    snapped = dataclasses.replace(params.rollout.consistent, blend_s=0.0)
    snap = make_consistent(raw, robot, snapped, params.contacts).trajectory.joint_positions
    jump = np.abs(np.diff(snap - raw.joint_positions, axis=0)[5:]).max()
    assert np.abs(np.diff(correction, axis=0)[5:]).max() < 0.75 * jump
    assert trajectory.attrs["consistent"] == "post"


def test_the_sliding_falls_where_the_feet_glide(robot, params, real_walks):
    """A real walk, retargeted, whose base drifts sideways at 0.1 m/s: every foot on the floor
    glides; held, the position-level sliding falls back near the walk's own."""
    from pimann.evaluate.metrics import trajectory_metrics

    walk = dataclasses.replace(real_walks["walk"], contacts=None)
    base = walk.base_position.copy()
    base[:, 1] += 0.1 * walk.time
    raw = dataclasses.replace(walk, base_position=base)
    out = make_consistent(raw, robot, params.rollout.consistent, params.contacts)
    key = "support_rmse_linear_position_total"
    own, before, after = (
        trajectory_metrics(t, robot, params.evaluate, params.contacts)[key]
        for t in (walk, raw, out.trajectory)
    )
    assert before > 1.2 * own  # the drift makes the feet glide
    assert after < 0.75 * before, (own, before, after)
    held = out.held
    assert out.residual[held].max() < params.rollout.consistent.tolerance


def test_leg_ik_reaches_pinocchio_placements(robot, params):
    """Soles of perturbed legs (pinocchio FK, base at the origin) reached from the standing
    legs within 1e-6 m and 1e-6 rad."""
    rng = np.random.default_rng(3)
    standing = robot.split_configuration(robot.standing_configuration())[2]
    start = np.tile(standing, (8, 1))
    goal = start.copy()
    goal[:, LEG_JOINTS] += rng.uniform(-0.15, 0.15, size=(8, 12))
    goal[:, [3, 9]] = np.minimum(goal[:, [3, 9]], -0.2)  # knees bent: away from the limit
    targets = np.empty((8, 2, 4, 4))
    for row, joints in enumerate(goal):
        q = robot.configuration([0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0], joints)
        for foot, frame in enumerate((LEFT_SOLE, RIGHT_SOLE)):
            targets[row, foot] = robot.frame_placement(q, frame).homogeneous
    solver = LegSolver(robot, dataclasses.replace(params.rollout.consistent, tolerance=1e-7))
    solution = solver.solve(start, targets, np.ones((8, 2), dtype=bool))
    for row, joints in enumerate(solution.joints):
        q = robot.configuration([0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0], joints)
        for foot, frame in enumerate((LEFT_SOLE, RIGHT_SOLE)):
            error = pin.log6(robot.frame_placement(q, frame).actInv(pin.SE3(targets[row, foot])))
            assert np.abs(error.vector).max() < 1e-6, (row, foot, error.vector)
    assert solution.residual.max() < 1e-6


def _in_loop(robot, params, consistent):
    """The analytic gait model's batch of two (unsteered, steered) stepped through a 4-s walk:
    (world soles of the recorded legs (T, rows, 2, 3), held flags (T, rows, 2) or None, the
    network's inputs (T, rows, in), the generator)."""
    from builders import IDENTITY, LAYOUT

    from pimann.generate.batch_generator import BatchGenerator
    from pimann.generate.command_script import ScriptSteps
    from pimann.learn.standing import StandingPose

    plan = ScriptSteps([[MotionSegment(4.0, 0.4, 0.0, 0.0)]] * 2, LAYOUT.rate_hz)
    generator = BatchGenerator(
        GaitModel(robot),
        LAYOUT,
        IDENTITY,
        params.rollout,
        np.array([False, True]),
        robot,
        params.contacts,
        StandingPose.nominal(),
        consistent,
    )
    network, inputs = generator.network, []

    def recorded(x):
        inputs.append(x.copy())
        return network(x)

    generator.network = recorded
    held, soles = [], []
    for k in range(1, len(plan.active)):
        generator.step(k, *plan.at(k))
        if consistent is not None:  # both weights 1: held flat where it landed
            held.append(generator.hold.weights.min(axis=-1) >= 1.0)
        frame = []
        for row in range(2):
            q = robot.configuration(
                generator.position[row],
                Rotation.from_matrix(generator.rotation[row]).as_quat(),
                generator.held_joints[row] if consistent is not None else generator.joints[row],
            )
            frame.append([robot.frame_placement(q, f).translation for f in FEET])
        soles.append(frame)
    held = np.array(held) if held else None
    return np.array(soles), held, np.array(inputs), generator


def test_in_loop_feeds_the_network_its_own_legs(robot, params):
    """In the loop the network sees what it sees without the hold (its own legs; unsteered, the
    base the leg odometry places on the held feet is not an input), while the legs recorded
    are the held ones: soles held within 1 mm, and the legs really corrected."""
    _, _, raw_inputs, _ = _in_loop(robot, params, None)
    soles, held, inputs, generator = _in_loop(robot, params, params.rollout.consistent)
    np.testing.assert_array_equal(inputs[:, 0], raw_inputs[:, 0])  # the unsteered row
    assert not np.array_equal(generator.held_joints, generator.joints)
    for foot in range(2):
        for a, b in true_runs(held[:, 0, foot]):
            drift = np.linalg.norm(soles[a:b, 0, foot] - soles[a, 0, foot], axis=1)
            assert drift.max() < 1e-3, (foot, a, b, drift.max())
            np.testing.assert_allclose(soles[a:b, 0, foot, 2], 0.0, atol=1e-3)


def test_in_loop_holds_the_soles_it_records(robot, params):
    """Inside the batched generator (the analytic gait model, a batch of two): a sole held (both
    weights 1) stays within 1 mm of where it landed, by pinocchio's FK of the held legs at the
    base the leg odometry placed; the raw rollout's soles glide there."""
    raw_soles = _in_loop(robot, params, None)[0]
    soles, held, _, generator = _in_loop(robot, params, params.rollout.consistent)
    worst, raw_worst = 0.0, 0.0
    for row in range(2):
        for foot in range(2):
            for a, b in true_runs(held[:, row, foot]):
                if b - a < 5:
                    continue
                drift = np.linalg.norm(soles[a:b, row, foot] - soles[a, row, foot], axis=1)
                worst = max(worst, drift.max())
                raw = np.linalg.norm(raw_soles[a:b, row, foot] - raw_soles[a, row, foot], axis=1)
                raw_worst = max(raw_worst, raw.max())
    assert worst < 1e-3 and raw_worst > 0.01, (worst, raw_worst)
    assert generator.hold.residual.max() < params.rollout.consistent.tolerance


def test_the_rollout_stage_writes_and_evaluate_measures_the_variants(tmp_path, params):
    """Tiny models: each seed's raw rollouts unchanged, `+post` and `+loop` beside them for the
    consistent scenarios only; the readers of raw rollouts see only those; metrics.csv has a
    row per variant with its distance to the raw twin."""
    from builders import tiny_models

    from pimann.core.rollout_files import find_rollouts, split_variant
    from pimann.core.trajectory import read_trajectory
    from pimann.evaluate.evaluation import collect_metrics
    from pimann.generate.rollouts import run_rollouts

    walk = [MotionSegment(0.6, 0.5, 0.0, 0.0)]
    rollout = dataclasses.replace(
        params.rollout,
        scenarios={"short": walk, "other": walk},
        scenario_names=["short", "other"],
        benchmark_clips=False,
        benchmark_train_clips=0,
        protocols={},
        consistent=dataclasses.replace(params.rollout.consistent, scenarios=["short"]),
    )
    study = dataclasses.replace(params, rollout=rollout)
    tiny_models(tmp_path / "models" / "w10", 10.0, "full", [0])
    root = tmp_path / "rollouts"
    written = run_rollouts(tmp_path / "models" / "w10", root / "w10", study, workers=1)
    names = sorted(path.name for path in written)
    assert names == sorted(
        f"{scenario}-{steering}.h5"
        for scenario in ("short", "other", "short+post", "short+loop")
        for steering in ("nosteering", "steering")
    )
    assert split_variant("short+post") == ("short", "post")
    assert split_variant("clip_a-b") == ("clip_a-b", "raw")
    assert {key.scenario for key, _ in find_rollouts(root)} == {"short", "other"}
    assert len(find_rollouts(root, variants=True)) == 8
    raw = read_trajectory(root / "w10" / "0" / "short-steering.h5")
    post = read_trajectory(root / "w10" / "0" / "short+post-steering.h5")
    loop = read_trajectory(root / "w10" / "0" / "short+loop-steering.h5")
    assert post.attrs["consistent"] == "post" and loop.attrs["consistent"] == "loop"
    np.testing.assert_array_equal(post.base_position, raw.base_position)
    assert len(loop) == len(raw) and loop.attrs["steering"] is True
    # the raw rollouts are those of a study without variants
    alone = dataclasses.replace(
        study,
        rollout=dataclasses.replace(
            rollout, consistent=dataclasses.replace(rollout.consistent, variants=[])
        ),
    )
    plain = run_rollouts(tmp_path / "models" / "w10", tmp_path / "plain" / "w10", alone, 1)
    assert len(plain) == 4
    np.testing.assert_array_equal(
        read_trajectory(tmp_path / "plain" / "w10" / "0" / "short-steering.h5").joint_positions,
        raw.joint_positions,
    )
    frame = collect_metrics(root, study, workers=1)
    assert len(frame) == 8
    assert sorted(frame["rollout_variant"]) == ["loop"] * 2 + ["post"] * 2 + ["raw"] * 4
    rows = frame.set_index(["scenario", "steering"])
    assert np.isnan(rows.loc[("short", True), "joint_distance_rms_rad"])
    distance = post.joint_positions - raw.joint_positions
    assert rows.loc[("short+post", True), "joint_distance_max_rad"] == pytest.approx(
        np.abs(distance).max()
    )
    assert (frame["penetration_max_m"] >= 0).all()
    # the legs' largest joint speed, raw and held, from the joints' first differences
    for scenario, trajectory in (("short", raw), ("short+post", post)):
        speeds = np.abs(np.diff(trajectory.joint_positions[:, LEG_JOINTS], axis=0)) * 50.0
        assert rows.loc[(scenario, True), "leg_joint_speed_max_rad_s"] == pytest.approx(
            speeds.max()
        )


def test_simulate_runs_read_the_variant_they_name(tmp_path, params):
    """A run with `variant: post` walks `<scenario>+post`, named so in results/sim; one whose
    variant the rollout stage does not make is refused before any simulation."""
    from pimann.core.errors import PimannError
    from pimann.core.params import SimulateRun
    from pimann.sim.run_list import run_key, run_name, simulate_runs

    run = SimulateRun("w10", 0, "forward", True, False, "online", "post")
    assert run_key(run).scenario == "forward+post"
    assert run_name(run) == "w10-0-forward+post-steering-online"
    assert run_name(dataclasses.replace(run, variant="raw")) == "w10-0-forward-steering-online"
    no_pushes = dataclasses.replace(params.simulate.pushes, rollouts=[])
    for runs, message in (
        ([run], re.escape("w10/0/forward+post-steering.h5: rollout not found")),
        ([dataclasses.replace(run, scenario="backward")], "needs rollout.consistent"),
    ):
        study = dataclasses.replace(
            params, simulate=dataclasses.replace(params.simulate, runs=runs, pushes=no_pushes)
        )
        with pytest.raises(PimannError, match=message):
            simulate_runs(tmp_path / "rollouts", tmp_path / "sim", tmp_path / "s.json", study)


def test_a_stalled_leg_is_solved_again_from_its_neighbours(robot, params, gait):
    """A frame whose leg the solver left far from its target (a stall) is solved again from
    the next frame's solved leg, and reaches it as its neighbours do."""
    solver = LegSolver(robot, params.rollout.consistent)
    frames = np.arange(100, 110)
    joints = np.asarray(gait.joint_positions, float)[frames]
    targets = solver.soles(joints)  # reachable: the gait's own soles
    stalled = joints.copy()
    stalled[4, LEG_JOINTS[:6]] += 0.5  # frame 4's left leg far off, as a stall leaves it
    active = np.zeros((len(frames), 2), dtype=bool)
    active[:, 0] = True
    residual = np.zeros(active.shape)
    residual[4, 0] = 0.1
    solution = retry_from_neighbours(
        solver,
        LegSolution(stalled, residual, 3),
        targets,
        active,
        np.zeros(active.shape, dtype=bool),
        params.rollout.consistent.tolerance,
    )
    assert solution.residual[4, 0] <= params.rollout.consistent.tolerance
    np.testing.assert_allclose(solution.joints[4], joints[4], atol=1e-3)
    np.testing.assert_array_equal(solution.joints[[3, 5]], stalled[[3, 5]])


def test_a_lifting_foot_is_leashed_looser_than_one_on_the_floor(params):
    """A stance whose network foot swings forward past MAX_HOLD_GAP from the held middle pose
    at its end: while that foot is up (lowest corner above FLAT_SHARE x the off height) the
    hold stays where it was (within MAX_LIFT_GAP); the same foot flat on the floor drags it."""
    off = float(params.contacts.off_height)
    reach = 0.5 * (MAX_HOLD_GAP + MAX_LIFT_GAP)  # beyond the floor's leash, within the lift's
    contacts = np.zeros((30, 2), dtype=bool)
    contacts[:20] = True
    for height, dragged in ((0.5 * (1.0 + FLAT_SHARE) * off, False), (0.0, True)):
        soles = np.broadcast_to(np.eye(4), (30, 2, 4, 4)).copy()
        soles[15:20, 0, 0, 3] = reach  # the network's left foot off at the stance's end ...
        soles[15:20, 0, 2, 3] = height  # ... up, or on the floor
        _, held, _, _ = post_holds(soles, contacts, 5, params.contacts, 0.02, 0.56)
        moved = held[15:20, 0, 0]
        if dragged:
            np.testing.assert_allclose(moved, reach - MAX_HOLD_GAP, atol=1e-9)
        else:
            np.testing.assert_allclose(moved, 0.0, atol=1e-9)
        np.testing.assert_allclose(held[:15, 0, :2], 0.0, atol=1e-9)


def test_lift_heights_in_closed_form():
    """The held sole's lift: on the floor before the stance's first frame, the network's height
    while it rises slower than off + (k - c + 1) step, that line while the network rises faster
    (c = last + 1 - delay, the network's first frame above the off height), then held."""
    network = np.array([0.0, 0.004, 0.0, 0.015, 0.03, 0.055, 0.08, 0.1])
    out = lift_heights(network, first=2, last=5, delay=2, off_height=0.02, step=0.0112)
    # c = 4: the line is 0.02 + (k - 3) 0.0112 -> k=3: 0.02, k=4: 0.0312, k=5: 0.0424
    np.testing.assert_allclose(out, [0, 0, 0, 0.015, 0.03, 0.0424, 0.0424, 0.0424], atol=1e-12)


def test_a_held_foot_leaves_the_floor_with_the_network_at_lift_speed(robot, params):
    """A gait whose feet rise at about 1.2 m/s: held, each foot crosses the rule's off height
    in the network's frame (the same contacts: the same lift-offs), and in the two frames the
    rule still counts above it stands at off + step and off + 2 step (step = `LIFT_SPEED` x dt),
    well below the network's foot; on the floor before, within the tolerance."""
    script = [MotionSegment(3.0, 0.4, 0.0, 0.0)]
    gait = roll(GaitModel(robot, lift=0.15), script, params, False, robot).trajectory
    consistent = params.rollout.consistent
    out = make_consistent(gait, robot, consistent, params.contacts)
    np.testing.assert_array_equal(out.trajectory.contacts, out.contacts)
    solver = LegSolver(robot, consistent)
    network = lowest_heights(world_soles(solver, gait)[1])
    held = lowest_heights(world_soles(solver, out.trajectory)[1])
    off, step = params.contacts.off_height, LIFT_SPEED / gait.rate_hz
    lift_offs = 0
    for foot in (0, 1):
        for a, b in true_runs(out.contacts[:, foot]):
            if a == 0 or b == len(gait):
                continue
            lift_offs += 1
            assert network[b - 2, foot] > off + step + 0.001  # the network's rises faster
            np.testing.assert_allclose(
                held[b - 2 : b, foot], [off + step, off + 2 * step], atol=consistent.tolerance
            )
            assert (network[b - 1, foot] - held[b - 1, foot]) > 0.01
            np.testing.assert_allclose(held[a + 1 : b - 4, foot], 0.0, atol=consistent.tolerance)
    assert lift_offs >= 4


def test_without_yaw_leaves_roll_and_pitch_in_the_heading_frame():
    """A sole's tilt against scipy's intrinsic z-y-x angles: the heading taken off, roll and
    pitch kept."""
    rng = np.random.default_rng(3)
    angles = rng.uniform([-np.pi, -1.2, -1.2], [np.pi, 1.2, 1.2], size=(20, 3))
    R = Rotation.from_euler("ZYX", angles).as_matrix()
    tilt = without_yaw(R)
    np.testing.assert_allclose(
        Rotation.from_euler("z", np.arctan2(R[:, 1, 0], R[:, 0, 0])[:, None]).as_matrix() @ tilt,
        R,
        atol=1e-12,
    )
    np.testing.assert_allclose(np.arctan2(tilt[:, 1, 0], tilt[:, 0, 0]), 0.0, atol=1e-12)
    expected = Rotation.from_euler("ZYX", np.c_[np.zeros(20), angles[:, 1:]]).as_matrix()
    np.testing.assert_allclose(tilt, expected, atol=1e-12)
