"""The ADHERENT baseline: its features against a closed form, a tiny training, and its BLF rollout
as the inverse of the features (an oracle fed the data's own outputs rebuilds the data's inputs),
with leg odometry that holds the support corner still, and the rollout stage's files."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch
from builders import CONTACT_PARAMS, RATE, SMALL_MODEL, synthetic_collection
from scipy.spatial.transform import Rotation

from pimann.core.params import MotionSegment, ProtocolParams, load_params
from pimann.core.paths import repo_path, repo_relative
from pimann.core.robot import CHEST_FRAME, STANDING_JOINTS, load_robot
from pimann.core.rollout_files import read_script, script_json
from pimann.core.trajectory import Trajectory, read_trajectory
from pimann.generate.adherent_rollout import (
    ADHERENT_CORNERS,
    AdherentGenerator,
    AdherentNetwork,
    AdherentRun,
    command_future,
    generate_adherent,
    run_adherent_rollouts,
)
from pimann.learn.adherent import (
    AdherentLayout,
    BodyFrames,
    adherent_layout,
    build_adherent_dataset,
    clip_samples,
    facing_direction,
    read_adherent_dataset,
)
from pimann.learn.adherent_train import load_adherent_model, train_adherent
from pimann.learn.dataset import write_dataset
from pimann.learn.standing import StandingPose

PARAMS = load_params()
LAYOUT = adherent_layout(PARAMS.features, RATE)
BLOCKS = ("base_positions", "facing_directions", "base_velocities")


@pytest.fixture(autouse=True)
def _one_thread():
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


@pytest.fixture(scope="module")
def frames(robot) -> BodyFrames:
    return BodyFrames(robot)


def planar(angle: float) -> np.ndarray:
    return np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])


def test_layout_is_blfs():
    """BLF MANN.cpp's sizes and order: 3 x 24 + 2 x 26 in, 3 x 12 + 2 x 26 + 3 out."""
    assert LAYOUT.offsets == tuple(range(-50, 61, 10))
    assert (LAYOUT.input_dim, LAYOUT.output_dim) == (124, 91)
    assert list(LAYOUT.x_slices) == [*BLOCKS, "joints", "joint_velocities"]
    assert list(LAYOUT.y_slices)[-1] == "base_twist"
    assert AdherentLayout.from_json(LAYOUT.to_json()) == LAYOUT


def test_features_match_a_closed_form(robot, frames):
    """A base walking at constant world velocity v and yaw rate w (fixed pitch, torso still,
    legs swinging): in the facing frame at the window's frame c, the position at offset o is
    R(-phi_c) v o dt, the direction (cos w o dt, sin w o dt), the velocity R(-phi_c) v; x_i's
    window sits on frame i - 1, y_i's on i; the twist is R(-theta_{i-1}) v and w."""
    n, v, w, dt = 230, np.array([0.5, -0.2]), 0.4, 1.0 / RATE
    t = np.arange(n) * dt
    rotation = Rotation.from_euler("z", (w * t)[:, None]) * Rotation.from_euler("y", 0.3)
    swing = 0.3 * np.sin(2 * np.pi * 0.9 * t)
    joints = np.tile(STANDING_JOINTS, (n, 1))
    joints[:, :12] += swing[:, None]  # the legs only: the chest keeps its place on the base
    clip = Trajectory(
        time=t,
        base_position=np.column_stack([1.0 + v[0] * t, -2.0 + v[1] * t, 0.7 + 0 * t]),
        base_quaternion_xyzw=rotation.as_quat(),
        joint_positions=joints,
        source="walk",
        rate_hz=RATE,
    )
    x, y, steps = clip_samples(clip, LAYOUT, frames)
    assert steps[0] == 52 and steps[-1] == n - 61 and np.all(np.diff(steps) == 1)
    # the facing angle at frame 0, from pinocchio (not the features' kinematics)
    q = robot.configuration(clip.base_position[0], clip.base_quaternion_xyzw[0], joints[0])
    chest = robot.frame_placement(q, CHEST_FRAME).rotation[:2, 0]
    base = rotation[0].as_matrix()[:2, 0]
    facing = chest / np.linalg.norm(chest) + base / np.linalg.norm(base)
    phi0 = np.arctan2(facing[1], facing[0])
    assert abs(phi0) > 1e-3  # the chest counts

    def expected_window(c: int, offsets) -> np.ndarray:
        to_local = planar(phi0 + w * c * dt).T
        o = np.asarray(offsets, dtype=float)
        positions = (to_local @ v)[None] * o[:, None] * dt
        directions = np.column_stack([np.cos(w * o * dt), np.sin(w * o * dt)])
        velocities = np.tile(to_local @ v, (len(o), 1))
        return np.concatenate([positions.ravel(), directions.ravel(), velocities.ravel()])

    xs, ys, future = LAYOUT.x_slices, LAYOUT.y_slices, LAYOUT.future_offsets
    for row in (0, len(steps) // 2, len(steps) - 1):
        i = steps[row]
        assert np.allclose(
            x[row, : xs["joints"].start], expected_window(i - 1, LAYOUT.offsets), atol=1e-9
        )
        assert np.allclose(y[row, : ys["joints"].start], expected_window(i, future), atol=1e-9)
        assert np.allclose(x[row, xs["joints"]], joints[i - 1])
        assert np.allclose(x[row, xs["joint_velocities"]], (joints[i - 1] - joints[i - 2]) / dt)
        assert np.allclose(y[row, ys["joints"]], joints[i])
        assert np.allclose(y[row, ys["joint_velocities"]], (joints[i] - joints[i - 1]) / dt)
        twist = np.append(planar(w * (i - 1) * dt).T @ v, w)
        assert np.allclose(y[row, ys["base_twist"]], twist, atol=1e-9)


@pytest.fixture(scope="module")
def small_params():
    train = dataclasses.replace(
        PARAMS.train, epochs=2, batch_size=64, seeds=[0, 1], max_train_samples=None
    )
    features = dataclasses.replace(PARAMS.features, time_reversed=[])
    return dataclasses.replace(PARAMS, model=SMALL_MODEL, train=train, features=features)


@pytest.fixture(scope="module")
def trained(tmp_path_factory, robot, small_params):
    """(dataset path, models folder): 4 synthetic sources and their 'mirrors', 2 seeds."""
    root = tmp_path_factory.mktemp("adherent")
    clips = synthetic_collection(n_sources=4, frames=200)
    dataset = build_adherent_dataset(clips, small_params.features, robot)
    write_dataset(root / "adherent.h5", dataset)
    train_adherent(root / "adherent.h5", root / "models", [0, 1], small_params, root / "plots")
    return root / "adherent.h5", root / "models"


def test_dataset_round_trip_and_split(trained, small_params):
    """The file reads back with its layout; a clip and its mirror stay on one side; the next
    input's window and joints are this output's (y_i's frame is x_{i+1}'s)."""
    data = read_adherent_dataset(trained[0])
    assert data.layout == LAYOUT and data.x_train.shape[1] == 124 and data.y_test.shape[1] == 91
    sources = {data.sources[k] for k in np.unique(data.test_origin[:, 0])}
    train_sources = {data.sources[k] for k in np.unique(data.train_origin[:, 0])}
    assert sources and train_sources and not sources & train_sources
    x = data.stats.denormalise_x(data.x_train.astype(float))
    y = data.stats.denormalise_y(data.y_train.astype(float))
    same = np.flatnonzero(np.diff(data.train_origin[:, 0]) == 0)  # consecutive samples of a clip
    xs, ys = LAYOUT.x_slices, LAYOUT.y_slices
    for block in BLOCKS:
        ahead = x[same + 1, xs[block]].reshape(len(same), -1, 2)[:, -6:].reshape(len(same), -1)
        assert np.allclose(ahead, y[same, ys[f"{block}_future"]], atol=1e-5)
        now = x[same, xs[block]].reshape(len(same), -1, 2)[:, -6:].reshape(len(same), -1)
        assert np.abs(now - y[same, ys[f"{block}_future"]]).max() > 1e-3  # not a copy
    assert np.allclose(x[same + 1, xs["joints"]], y[same, ys["joints"]], atol=1e-5)


def test_training_writes_models_a_seed_reproduces(trained, small_params, tmp_path):
    """Each seed's folder loads; seed 1 trained alone equals seed 1 of the ensemble."""
    dataset, models = trained
    model, layout, stats, meta = load_adherent_model(models / "1")
    assert layout == LAYOUT and meta["variant"] == "adherent" and meta["pi_weight"] == 0.0
    assert meta["best_epoch"] in (1, 2) and meta["train_samples"] > 100
    assert meta["dataset"] == repo_relative(dataset)  # (absolute here: outside the repository)
    assert repo_path(meta["dataset"]).samefile(dataset)
    assert (models.parent / "plots" / "seed0.csv").read_text().startswith("epoch,train_loss")
    train_adherent(dataset, tmp_path / "alone", [1], small_params)
    alone, *_ = load_adherent_model(tmp_path / "alone" / "1")
    for name, value in model.state_dict().items():
        assert torch.allclose(value, alone.state_dict()[name], atol=1e-6), name
    other, *_ = load_adherent_model(models / "0")
    assert not torch.allclose(other.expert_weight_0, model.expert_weight_0)


class Oracle:
    """Stands in for the network: each step returns the clip's y at the next sample and keeps
    the x it was given."""

    def __init__(self, y: np.ndarray, first: int):
        self.y, self.next, self.inputs = y, first, []

    def __call__(self, x: np.ndarray) -> np.ndarray:
        self.inputs.append(x[0].copy())
        self.next += 1
        return self.y[self.next - 1][None]


def _standing(meta: dict) -> StandingPose:
    return StandingPose.from_json(meta["standing"])


class Stepping:
    """A network in closed form: the legs swing in antiphase at 1 Hz (hip pitch, knee bent on
    the forward swing), the phase read back from the input's left hip (the joint and its
    velocity); the twist walks forward and turns."""

    def __init__(self, layout: AdherentLayout, standing: StandingPose):
        self.layout, self.rest = layout, standing.joints

    def __call__(self, x: np.ndarray) -> np.ndarray:
        xs, ys = self.layout.x_slices, self.layout.y_slices
        dt, omega, amplitude = 1.0 / RATE, 2 * np.pi, 0.35
        s, sdot = x[:, xs["joints"]], x[:, xs["joint_velocities"]]
        phase = np.arctan2(-sdot[:, 0] / omega, s[:, 0] - self.rest[0]) + omega * dt
        joints = np.tile(self.rest, (len(x), 1))
        for hip, knee, shift in ((0, 3, 0.0), (6, 9, np.pi)):
            joints[:, hip] += amplitude * np.cos(phase + shift)
            joints[:, knee] -= amplitude * np.maximum(0.0, np.sin(phase + shift))
        y = np.zeros((len(x), self.layout.output_dim))
        y[:, ys["joints"]] = joints
        y[:, ys["joint_velocities"]] = (joints - s) / dt
        y[:, ys["base_twist"]] = [0.5, 0.0, 0.3]
        return y


@pytest.mark.parametrize("past_velocity", ["twist", "zeros"])
def test_rollout_inverts_the_features(trained, robot, frames, past_velocity):
    """A clip the rollout's own odometry made (the trained model walking forward, after a
    second of standing): fed the clip's outputs y_i (and, as the joystick, their own future),
    the rollout feeds back x_{i+1} exactly, step after step, and rebuilds the clip's base
    path. With BLF's zeros the past base velocities are 0 and every other input the data's."""
    _, layout, _, meta = load_adherent_model(trained[1] / "0")
    walk = [MotionSegment(3.0, 0.6, 0.0, 0.2)]
    run = AdherentRun(walk, "walk", {})
    (made,) = generate_adherent(
        Stepping(layout, _standing(meta)),
        layout,
        [run],
        robot,
        CONTACT_PARAMS,
        _standing(meta),
        past_velocity="twist",
    )
    lead = 60  # standing frames before the rollout's first (frame 0: the start)
    pad = lambda a: np.concatenate([np.repeat(a[:1], lead - 1, axis=0), a])  # noqa: E731
    clip = Trajectory(
        time=np.arange(len(made) + lead - 1) / RATE,
        base_position=pad(made.base_position),
        base_quaternion_xyzw=pad(made.base_quaternion_xyzw),
        joint_positions=pad(made.joint_positions),
        source="made",
        rate_hz=RATE,
    )
    x, y, steps = clip_samples(clip, layout, frames)
    start = int(np.searchsorted(steps, lead))  # sample of the rollout's first frame
    oracle = Oracle(y, start)
    replay = AdherentGenerator(
        oracle, layout, robot, CONTACT_PARAMS, _standing(meta), 1, past_velocity
    )
    n, ys, xs = len(steps) - start, layout.y_slices, layout.x_slices
    positions, supports = [], []
    for _ in range(n):
        desired = np.zeros((1, 3, 6, 2))
        if replay.y is not None:  # the joystick asks what the data did
            desired = np.stack([replay.y[:, ys[f"{b}_future"]].reshape(1, 6, 2) for b in BLOCKS], 1)
        replay.step(desired)
        positions.append(replay.position[0].copy())
        supports.append(replay.support[0])
    fed = np.array(oracle.inputs)  # fed[j] at step j + 1: the clip's x of sample start + j
    wanted = x[start : start + n]
    assert n > 50
    velocity = np.zeros(layout.input_dim, bool)
    velocity[xs["base_velocities"]] = np.repeat(np.array(layout.offsets) <= 0, 2)
    if past_velocity == "zeros":
        assert np.all(fed[1:, velocity] == 0.0)
        assert np.abs(wanted[:, velocity]).max() > 0.1  # the data's are not
        fed[:, velocity] = wanted[:, velocity]
    assert np.abs(fed[1:] - wanted[1:]).max() < 1e-9
    past = np.zeros(layout.input_dim, bool)  # the first input: the standing second before
    past[: xs["joints"].start] = np.tile(np.repeat(np.array(layout.offsets) <= 0, 2), 3)
    assert np.abs(fed[0, past] - wanted[0, past]).max() < 1e-9
    frames_made = clip.base_position[lead : lead + n]
    assert np.abs(np.array(positions) - frames_made).max() < 1e-9
    assert np.ptp(frames_made[:, 0]) > 0.3  # it walked
    assert (np.diff(supports) != 0).sum() >= 4  # and the feet took turns


def test_leg_odometry_holds_the_support_corner(trained, robot):
    """While a foot stays the support, its pinned corner (ADHERENT's (+-0.08, +-0.03)) does not
    move and sits on the floor; the support foot is the one with the lowest corner."""
    _, layout, _, meta = load_adherent_model(trained[1] / "1")
    generator = AdherentGenerator(
        Stepping(layout, _standing(meta)), layout, robot, CONTACT_PARAMS, _standing(meta), 2
    )
    desired = command_future(
        np.array([[0.6, 0.0], [0.0, 0.2]]), np.array([0.3, 0.0]), layout.future_offsets, RATE
    )
    held, previous, changes = [], None, 0
    for _ in range(120):
        generator.step(desired)
        corner = generator.support_corner_world()
        world, _ = generator._corners(
            generator.rotation, generator.position, generator.joints, ADHERENT_CORNERS
        )
        lowest = world[..., 2].min(axis=2)  # (rows, feet)
        assert np.all(lowest[[0, 1], generator.support] <= lowest[[0, 1], 1 - generator.support])
        assert np.allclose(corner[:, 2], 0.0, atol=1e-12)
        if previous is not None:
            same = generator.support == previous[0]
            changes += (~same).sum()
            held.append(np.abs(corner - previous[1])[same].max(initial=0.0))
        previous = (generator.support.copy(), corner)
    assert max(held) < 1e-12
    assert changes >= 4  # the feet took turns
    assert np.linalg.norm(generator.position[:, :2], axis=1).min() > 0.2  # the base walked


def test_rollout_stage_writes_nosteering_files(trained, tmp_path):
    """Every scenario and each protocol, without steering, in the rollout layout, with the
    trajectory contract's attributes and models.json."""
    script = [MotionSegment(0.6, 0.5, 0.0, 0.0)]
    rollout = dataclasses.replace(
        PARAMS.rollout,
        scenarios={"forward": script},
        scenario_names=["forward"],
        benchmark_clips=False,
        benchmark_train_clips=0,
        protocols={
            "authors": ProtocolParams(
                script=[MotionSegment(0.4, 0.4, 0.0, 0.0)], unsteered={}, steered={}
            )
        },
    )
    params = dataclasses.replace(PARAMS, rollout=rollout)
    out = tmp_path / "adherent"
    written = run_adherent_rollouts(trained[1], out, params, workers=1)
    names = sorted(p.relative_to(out).as_posix() for p in written)
    assert names == [  # rollout.consistent: ADHERENT's files get the post-process beside them
        "0/authors+post-nosteering.h5",
        "0/authors-nosteering.h5",
        "0/forward+post-nosteering.h5",
        "0/forward-nosteering.h5",
        "1/authors+post-nosteering.h5",
        "1/authors-nosteering.h5",
        "1/forward+post-nosteering.h5",
        "1/forward-nosteering.h5",
    ]
    assert (out / "models.json").is_file()
    trajectory = read_trajectory(out / "1" / "forward-nosteering.h5")
    assert len(trajectory) == 31 and trajectory.joint_velocities is not None
    assert trajectory.contacts is not None and trajectory.contacts[0].all()
    assert trajectory.attrs["steering"] == False and trajectory.attrs["seed"] == 1  # noqa: E712
    assert trajectory.attrs["pi_weight"] == 0.0
    assert read_script(trajectory) == script and trajectory.attrs["script"] == script_json(script)
    # rollout.adherent_past_velocity picks the loop: BLF's (zeros, standing first input) here
    zeros = dataclasses.replace(
        params, rollout=dataclasses.replace(rollout, adherent_past_velocity="zeros")
    )
    run_adherent_rollouts(trained[1], tmp_path / "blf", zeros, workers=1)
    blf = read_trajectory(tmp_path / "blf" / "1" / "forward-nosteering.h5")
    model, layout, stats, meta = load_adherent_model(trained[1] / "1")
    loops = {
        loop: generate_adherent(
            AdherentNetwork(model, stats),
            layout,
            [AdherentRun(script, "", {})],
            load_robot(),
            params.contacts,
            _standing(meta),
            loop,
            first,
        )[0]
        for loop, first in (("twist", "command"), ("zeros", "still"))
    }
    for written_by, loop in ((trajectory, "twist"), (blf, "zeros")):
        assert np.allclose(written_by.joint_positions, loops[loop].joint_positions, atol=1e-6)
        assert np.allclose(written_by.base_position, loops[loop].base_position, atol=1e-6)
    assert np.abs(blf.joint_positions - trajectory.joint_positions).max() > 1e-4


def test_joystick_enters_the_future_half_as_blf_blends_it(robot):
    """With a network whose future is all zeros, the next input's future sample k is
    ((k + 1) / 6)^tau x the joystick's, tau 1.5 for positions and 1.3 for directions and
    velocities; the joystick's own future is the held command's path (a numeric integral)."""
    standing = StandingPose.nominal()
    generator = AdherentGenerator(
        Stepping(LAYOUT, standing), LAYOUT, robot, CONTACT_PARAMS, standing, 1
    )
    velocity, yaw_rate = np.array([[0.5, 0.2]]), np.array([0.6])
    desired = command_future(velocity, yaw_rate, LAYOUT.future_offsets, RATE)
    for k, offset in enumerate(LAYOUT.future_offsets):
        t = offset / RATE
        s = np.linspace(0.0, t, 2001)
        heading = yaw_rate[0] * s
        path = np.stack(
            [
                np.cos(heading) * velocity[0, 0] - np.sin(heading) * velocity[0, 1],
                np.sin(heading) * velocity[0, 0] + np.cos(heading) * velocity[0, 1],
            ]
        )
        assert np.allclose(desired[0, 0, k], np.trapezoid(path, s, axis=1), atol=1e-6)
        assert np.allclose(desired[0, 1, k], [np.cos(heading[-1]), np.sin(heading[-1])])
        assert np.allclose(desired[0, 2, k], path[:, -1])
    generator.step(desired)
    generator.step(desired)  # its input: the first output's future blended with the joystick's
    fed = generator.x[0]
    weights = (np.arange(1, 7) / 6.0)[None, :] ** np.array([1.5, 1.3, 1.3])[:, None]
    for b, block in enumerate(BLOCKS):
        future = fed[LAYOUT.x_slices[block]].reshape(-1, 2)[-6:]
        assert np.allclose(future, weights[b][:, None] * desired[0, b], atol=1e-12), block


class Recording:
    """The trained network, keeping every input it was given and every output it gave."""

    def __init__(self, network: AdherentNetwork):
        self.network, self.inputs, self.outputs = network, [], []

    def __call__(self, x: np.ndarray) -> np.ndarray:
        y = self.network(x)
        self.inputs.append(x.copy())
        self.outputs.append(y.copy())
        return y


@pytest.mark.parametrize("past_velocity", ["twist", "zeros"])
def test_own_generator_feeds_back_its_twist_and_starts_on_the_command(
    trained, robot, frames, past_velocity
):
    """A tiny trained model, two rows turning opposite ways: the first input's future half is
    the command's own future and its past the standing second; from then on the past velocity
    at offset 0 is the previous output's (vx, vy), from the ground base frame of the state
    before it into the world and then into the new state's facing frame (the features'
    v_i = (p_i - p_{i-1}) / dt in the window's frame, pimann.learn.adherent), and the one at
    offset -10 the twist of 10 steps before, in the same new frame; BLF's zeros push 0."""
    model, layout, stats, meta = load_adherent_model(trained[1] / "0")
    network = Recording(AdherentNetwork(model, stats))
    generator = AdherentGenerator(
        network, layout, robot, CONTACT_PARAMS, _standing(meta), 2, past_velocity
    )
    velocity, yaw_rate = np.array([[0.4, 0.0], [0.3, 0.1]]), np.array([0.8, -0.8])
    desired = command_future(velocity, yaw_rate, layout.future_offsets, RATE)
    xs, ys, n = layout.x_slices, layout.y_slices, 40
    offsets = np.array(layout.offsets)
    now, before = int(np.flatnonzero(offsets == 0)[0]), int(np.flatnonzero(offsets == -10)[0])
    world_twists, facing = [], []
    for _ in range(n):
        yaw = generator.yaw.copy()
        generator.step(desired)
        twist = network.outputs[-1][:, ys["base_twist"]][:, :2]
        world_twists.append(np.einsum("bij,bj->bi", np.stack([planar(a) for a in yaw]), twist))
        _, rotations = frames(generator.joints)
        f = facing_direction(generator.rotation, rotations[:, 2])
        facing.append(np.arctan2(f[:, 1], f[:, 0]))
    first = network.inputs[0]
    for b, block in enumerate(BLOCKS):
        window = first[:, xs[block]].reshape(2, -1, 2)
        assert np.allclose(window[:, -6:], desired[:, b], atol=1e-12), block
        assert np.allclose(window[:, :-6], [0.0, 0.0] if b != 1 else [1.0, 0.0], atol=1e-9)
    turned = 0.0
    for step in range(1, n):
        x = network.inputs[step]
        past = x[:, xs["base_velocities"]].reshape(2, -1, 2)
        to_local = np.stack([planar(a).T for a in facing[step - 1]])
        if past_velocity == "zeros":
            assert np.all(past[:, : now + 1] == 0.0)
            continue
        expected = np.einsum("bij,bj->bi", to_local, world_twists[step - 1])
        assert np.abs(past[:, now] - expected).max() < 1e-9
        if step > 10:
            earlier = np.einsum("bij,bj->bi", to_local, world_twists[step - 11])
            assert np.abs(past[:, before] - earlier).max() < 1e-9
        turned = max(turned, np.abs(facing[step - 1]).max())
    if past_velocity == "twist":
        assert np.abs(np.array(world_twists)).max() > 0.05  # the twists pushed are not 0
        assert turned > 0.01  # and the frame they are rotated into is not the world's


def test_still_first_input_is_blfs_reset(trained, robot):
    """`first_input="still"` keeps BLF's reset input: the first future half stands still."""
    model, layout, stats, meta = load_adherent_model(trained[1] / "0")
    network = Recording(AdherentNetwork(model, stats))
    generator = AdherentGenerator(
        network, layout, robot, CONTACT_PARAMS, _standing(meta), 1, "twist", "still"
    )
    desired = command_future(np.array([[0.4, 0.0]]), np.zeros(1), layout.future_offsets, RATE)
    generator.step(desired)
    still = command_future(np.zeros((1, 2)), np.zeros(1), layout.future_offsets, RATE)
    for b, block in enumerate(BLOCKS):
        future = network.inputs[0][:, layout.x_slices[block]].reshape(1, -1, 2)[:, -6:]
        assert np.allclose(future, still[:, b])
        assert b == 1 or not np.allclose(future, desired[:, b])  # directions: straight ahead
