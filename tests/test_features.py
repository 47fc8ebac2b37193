"""Features: closed-form velocities of a synthetic clip, layout, leak-free split, statistics."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from builders import (
    BROKEN_FEATURES,
    PITCH,
    RATE,
    break_features,
    synthetic_clip,
    synthetic_collection,
)
from scipy.spatial.transform import Rotation

from pimann.core.errors import PimannError
from pimann.core.params import load_params
from pimann.core.robot import N_JOINTS
from pimann.core.trajectory import Trajectory
from pimann.learn.dataset import read_dataset, write_dataset
from pimann.learn.feature_layout import FeatureLayout, window_layout
from pimann.learn.features import build_dataset, clip_features, split_sources


@pytest.fixture(scope="module")
def params():
    """The repository's params with the paper's world pose input (the closed forms below), no
    time-reversed clips and no gait phase (the paper's; each tested on its own below)."""
    params = load_params()
    features = dataclasses.replace(
        params.features, pose_input="world", time_reversed=[], gait_phase=False
    )
    return dataclasses.replace(params, features=features)


def test_layout_sizes_and_windows(params):
    layout = window_layout(params.features, RATE, "full")
    assert layout.input_dim == 130 and layout.output_dim == 100
    assert layout.input_offsets == tuple(range(-50, 61, 10))
    assert layout.output_offsets == tuple(range(0, 61, 10))
    assert layout.current_output == 0
    assert len(layout.names("x")) == 130 and len(layout.names("y")) == 100
    assert FeatureLayout.from_json(layout.to_json()) == layout
    paper = dataclasses.replace(params.features, window="paper")
    paper_layout = window_layout(paper, RATE, "full")
    assert paper_layout.input_offsets == (-42, -33, -25, -17, -8, 0, 8, 17, 25, 33, 42, 50)
    assert paper_layout.output_offsets == (0, 8, 17, 25, 33, 42, 50)
    assert paper_layout.input_dim == 130
    with pytest.raises(PimannError, match="window"):
        window_layout(dataclasses.replace(params.features, window="nope"), RATE, "full")


def test_the_gait_phase_adds_two_columns_after_the_pose(params):
    plain = window_layout(params.features, RATE, "full")
    phased = window_layout(
        dataclasses.replace(params.features, gait_phase=True, gait_phase_step_s=0.8), RATE, "full"
    )
    assert (phased.input_dim, phased.output_dim) == (plain.input_dim + 2, plain.output_dim + 2)
    assert phased.names("x")[-2:] == ["gait_phase.cos", "gait_phase.sin"]
    assert phased.names("y")[:-2] == plain.names("y")
    assert phased.names("x")[:-2] == plain.names("x")
    assert FeatureLayout.from_json(phased.to_json()) == phased
    assert "gait_phase" not in plain.to_json()  # layouts without it read as before
    with pytest.raises(PimannError, match="gait_phase_step_s"):
        FeatureLayout.from_json(phased.to_json().replace("0.8", "-1.0"))
    clip = synthetic_clip()
    with pytest.raises(PimannError, match="contacts"):
        clip_features(dataclasses.replace(clip, contacts=None), phased)


def test_constant_velocity_features_match_closed_form(params):
    velocity, yaw_rate = np.array([0.4, 0.1, 0.02]), 1.0
    clip = synthetic_clip(300, velocity, yaw_rate)
    layout = window_layout(params.features, RATE, "full")
    x, y, steps = clip_features(clip, layout)
    # first differences: a full window needs 51 frames before (the difference ending at i-50)
    # and the output's window 61 after (the window of frame i+1)
    assert steps[0] == 51 and steps[-1] == 300 - 1 - 61 and len(x) == len(steps)
    xs, ys = layout.x_slices, layout.y_slices
    time = steps / RATE

    def in_base(at_time):  # the world velocity in the base frame at `at_time`
        yaw = Rotation.from_euler("z", (yaw_rate * at_time)[:, None])
        return (yaw * Rotation.from_euler("y", PITCH)).inv().apply(velocity)

    expected_linear = in_base(time)
    expected_angular = Rotation.from_euler("y", -PITCH).apply([0.0, 0.0, yaw_rate])
    linear = x[:, xs["base_linear_window"]].reshape(len(x), 12, 3)
    angular = x[:, xs["base_angular_window"]].reshape(len(x), 12, 3)
    np.testing.assert_allclose(linear, np.repeat(expected_linear[:, None], 12, 1), atol=1e-9)
    np.testing.assert_allclose(angular, np.broadcast_to(expected_angular, angular.shape), atol=1e-9)
    future = y[:, ys["base_linear_future"]].reshape(len(y), 7, 3)  # in the base frame at i+1
    ahead = in_base(time + 1 / RATE)
    np.testing.assert_allclose(future, np.repeat(ahead[:, None], 7, 1), atol=1e-9)
    assert np.abs(future[:, 0] - expected_linear).max() > 1e-3  # not the input's frame
    # state: x at i-1, y at i
    np.testing.assert_allclose(x[:, xs["joints"]], clip.joint_positions[steps - 1])
    np.testing.assert_allclose(y[:, ys["base_position"]], clip.base_position[steps])
    # a first difference is the derivative half a frame earlier (to (omega dt)^2 / 24)
    analytic = 0.2 * 2 * np.pi * 1.1 * np.cos(2 * np.pi * 1.1 * (time[:, None] - 0.5 / RATE))
    velocities = y[:, ys["joint_velocities"]]
    np.testing.assert_allclose(velocities, np.broadcast_to(analytic, velocities.shape), atol=0.01)
    joints_now = y[:, ys["joints"]]
    np.testing.assert_allclose(joints_now, x[:, xs["joints"]] + velocities / RATE, atol=1e-12)
    # psi against pinocchio's rpy, and yaw unwrapped: continuous past pi
    rpy = y[:, ys["base_rpy"]]
    reference = np.array(
        [
            pin.rpy.matrixToRpy(Rotation.from_quat(q).as_matrix())
            for q in clip.base_quaternion_xyzw[steps]
        ]
    )
    np.testing.assert_allclose(np.angle(np.exp(1j * (rpy - reference))), 0.0, atol=1e-9)
    assert rpy[-1, 2] > np.pi and np.all(np.abs(np.diff(rpy[:, 2]) - yaw_rate / RATE) < 1e-9)


def test_ground_projected_variant_zeroes_roll_and_pitch(params):
    velocity, yaw_rate = np.array([0.4, 0.1, 0.02]), -0.3
    clip = synthetic_clip(200, velocity, yaw_rate)
    layout = window_layout(params.features, RATE, "ground_projected")
    x, y, steps = clip_features(clip, layout)
    xs, ys = layout.x_slices, layout.y_slices
    np.testing.assert_allclose(y[:, ys["base_rpy"]][:, :2], 0.0, atol=1e-12)
    np.testing.assert_allclose(y[:, ys["base_rpy"]][:, 2], yaw_rate * steps / RATE, atol=1e-9)
    np.testing.assert_allclose(y[:, ys["base_position"]][:, 2], clip.base_position[steps, 2])
    yaw = Rotation.from_euler("z", (yaw_rate * steps / RATE)[:, None])
    linear = x[:, xs["base_linear_window"]].reshape(len(x), 12, 3)
    np.testing.assert_allclose(linear[:, 0], yaw.inv().apply(velocity), atol=1e-9)
    angular = x[:, xs["base_angular_window"]].reshape(len(x), 12, 3)
    np.testing.assert_allclose(angular, np.broadcast_to([0, 0, yaw_rate], angular.shape), atol=1e-9)


def test_gravity_pose_input_keeps_height_roll_pitch_and_zeroes_the_rest(params):
    velocity, yaw_rate = np.array([0.4, 0.1, 0.02]), 0.5
    clip = synthetic_clip(200, velocity, yaw_rate)
    world = window_layout(params.features, RATE, "full")
    gravity_params = dataclasses.replace(params.features, pose_input="gravity")
    gravity = window_layout(gravity_params, RATE, "full")
    assert FeatureLayout.from_json(gravity.to_json()) == gravity
    x_world, y_world, _ = clip_features(clip, world)
    x, y, steps = clip_features(clip, gravity)
    for features, reference, slices in (
        (x, x_world, gravity.x_slices),
        (y, y_world, gravity.y_slices),
    ):
        position, rpy = features[:, slices["base_position"]], features[:, slices["base_rpy"]]
        np.testing.assert_array_equal(position[:, :2], 0.0)
        np.testing.assert_array_equal(rpy[:, 2], 0.0)
        np.testing.assert_array_equal(position[:, 2], reference[:, slices["base_position"]][:, 2])
        np.testing.assert_array_equal(rpy[:, :2], reference[:, slices["base_rpy"]][:, :2])
    # everything else is unchanged; the world layout moves with the clip, gravity does not
    rest = np.ones(x.shape[1], bool)
    rest[gravity.x_slices["base_position"]] = rest[gravity.x_slices["base_rpy"]] = False
    np.testing.assert_array_equal(x[:, rest], x_world[:, rest])
    assert np.ptp(x_world[:, world.x_slices["base_position"]][:, 0]) > 0.5
    with pytest.raises((PimannError, ValueError), match="pose_input"):  # params refuse it
        window_layout(dataclasses.replace(params.features, pose_input="nope"), RATE, "full")


def test_split_keeps_mirrors_with_their_clip_and_does_not_leak(params):
    clips = synthetic_collection(n_sources=10)
    features = dataclasses.replace(params.features, test_fraction=0.2)
    dataset = build_dataset(clips, features, "full")
    source_of = dict(zip(dataset.clips, dataset.sources, strict=True))
    train_sources = {source_of[c] for c in dataset.train_clips}
    test_sources = {source_of[c] for c in dataset.test_clips}
    assert not train_sources & test_sources
    # 5 forward and 5 turning sources: 2 of each held out, though 0.2 of 10 is 2
    assert len(test_sources) == 4 and len(train_sources) == 6
    for source in test_sources:  # both the clip and its mirror are held out
        assert {f"{source}", f"{source}_mirror"} <= set(dataset.test_clips)
    # deterministic, and another seed picks another split
    trajectories = [t for _, t in clips]
    assert split_sources(trajectories, 0.2, 0) == test_sources
    assert any(split_sources(trajectories, 0.2, s) != test_sources for s in range(1, 5))
    with pytest.raises(PimannError, match="2 source clips"):
        build_dataset(clips[:2], features, "full")


def class_collection() -> tuple[list[tuple[str, Trajectory]], dict[str, str], dict[str, str]]:
    """Straight-line clips (and 'mirrors') of four classes: 6 forward sources, 4 backward, 3
    side, 1 diagonal, styles repeating within a class; also {source: class}, {source: style}."""
    kinds = {
        "forward": ((0.6, 0.0, 0.0), "aabbcc"),
        "backward": ((-0.5, 0.0, 0.0), "aabb"),
        "side": ((0.0, 0.3, 0.0), "abc"),
        "diagonal": ((0.3, 0.3, 0.0), "a"),
    }
    clips, classes, styles = [], {}, {}
    for name, (velocity, style_of) in kinds.items():
        for k, style in enumerate(style_of):
            source = f"{name}_{style}_{k:03d}.bvh"
            classes[source], styles[source] = name, style
            for mirrored in (False, True):
                clip = synthetic_clip(160, velocity, 0.0, source, mirrored, float(mirrored))
                clip = dataclasses.replace(clip, attrs={"mirrored": mirrored, "style": style})
                clips.append((f"{source[:-4]}{'_mirror' if mirrored else ''}", clip))
    return clips, classes, styles


def test_split_holds_out_every_class_in_different_styles(params):
    clips, classes, styles = class_collection()
    trajectories = [t for _, t in clips]
    test = split_sources(trajectories, 0.1, 0)
    held = {name: sorted(s for s in test if classes[s] == name) for name in set(classes.values())}
    assert len(held["forward"]) == 2 and len(held["backward"]) == 2  # 4 or more sources: 2
    assert len(held["side"]) == 1 and held["diagonal"] == []  # 2-3 sources: 1; one source: 0
    assert len(test) == 5  # 0.1 of 14 sources is 1: the per-class minimum alone
    for name in ("forward", "backward"):  # held out in two styles, not twice the same
        assert len({styles[s] for s in held[name]}) == 2
    assert len(split_sources(trajectories, 0.5, 0)) == 7  # the shuffle fills up to 7 of 14
    # a source's clips, the mirror with them, all on one side of the features stage's split
    features = dataclasses.replace(params.features, test_fraction=0.1, split_seed=0)
    dataset = build_dataset(clips, features, "full")
    assert {name.removesuffix("_mirror") + ".bvh" for name in dataset.test_clips} == test
    assert not set(dataset.test_clips) & set(dataset.train_clips)
    assert len(dataset.test_clips) == 2 * len(test)
    # deterministic for a seed; another seed, another split of the same strata
    assert split_sources(reversed(trajectories), 0.1, 0) == test
    others = [split_sources(trajectories, 0.1, seed) for seed in range(1, 6)]
    assert any(other != test for other in others)
    assert all(sum(classes[s] == "backward" for s in other) == 2 for other in others)


def test_a_clip_class_is_its_walking_majority_unless_it_mostly_stands():
    from pimann.learn.motion_classes import CLASSES, majority_class

    def counts(**frames):
        return np.array([frames.get(name, 0) for name in CLASSES])

    assert majority_class(counts(forward=30, backward=40, standing=45)) == "backward"
    assert majority_class(counts(forward=30, turning_in_place=50, standing=20)) == "forward"
    assert majority_class(counts(forward=30, standing=31)) == "standing"
    assert majority_class(counts(turning_in_place=30, standing=20)) == "turning_in_place"


def test_settled_contacts_drop_frames_around_switches():
    from pimann.learn.features import settled_contacts

    left = np.array([1, 1, 1, 0, 0, 1, 1, 1, 1, 1, 0], bool)
    flags = np.stack([left, np.ones_like(left)], axis=1)
    settled = settled_contacts(flags, 1)
    assert settled[:, 0].tolist() == [1, 1, 0, 0, 0, 0, 1, 1, 1, 0, 0]
    assert settled[:, 1].all()  # never switches: the clip's ends are no switch
    np.testing.assert_array_equal(settled_contacts(flags, 0), flags)


def test_normalisation_uses_training_statistics_only(params, tmp_path):
    from pimann.learn.dataset import write_dataset

    clips = synthetic_collection(n_sources=6)
    dataset = build_dataset(clips, params.features, "full")
    layout = dataset.layout
    raw = {name: clip_features(t, layout) for name, t in clips}
    x_train = np.concatenate([raw[c][0] for c in dataset.train_clips])
    x_all = np.concatenate([raw[c][0] for c in dataset.clips])
    y_train = np.concatenate([raw[c][1] for c in dataset.train_clips])
    np.testing.assert_allclose(dataset.stats.x_mean, x_train.mean(0))
    np.testing.assert_allclose(dataset.stats.y_mean, y_train.mean(0))
    assert not np.allclose(dataset.stats.x_mean, x_all.mean(0))
    constant = x_train.std(0) < 1e-8
    assert constant.any() and np.all(dataset.stats.x_std[constant] == 1.0)
    np.testing.assert_allclose(dataset.x_train.mean(0), 0.0, atol=1e-5)
    np.testing.assert_allclose(dataset.x_train.std(0)[~constant], 1.0, atol=1e-4)
    np.testing.assert_allclose(
        dataset.stats.denormalise_y(dataset.y_train.astype(float)), y_train, atol=1e-4
    )
    path = tmp_path / "full.h5"
    write_dataset(path, dataset)
    back = read_dataset(path)
    assert back.layout == layout and back.test_clips == dataset.test_clips
    np.testing.assert_array_equal(back.x_test, dataset.x_test)
    np.testing.assert_array_equal(back.stats.y_std, dataset.stats.y_std)
    assert N_JOINTS == back.layout.n_joints
    # each sample carries its clip's settled contact flags at its step
    clip_of = dict(clips)
    margin = round(params.features.contact_margin_s * RATE)
    assert margin == 2
    for contacts, origin in (
        (back.train_contacts, back.train_origin),
        (back.test_contacts, back.test_origin),
    ):
        expected = []
        for k, step in origin:
            raw = clip_of[dataset.clips[k]].contacts
            around = raw[max(step - margin, 0) : step + margin + 1]
            expected.append(around.all(axis=0))  # down on every frame within the margin
        np.testing.assert_array_equal(contacts, np.array(expected))
    assert back.train_contacts.all(-1).any() and not back.train_contacts.all()


def write_small_dataset(path: Path) -> Path:
    """A valid feature file: 3 synthetic sources and their 'mirrors'."""
    features = dataclasses.replace(load_params().features, gait_phase=False)  # the paper's
    # layout: 130 inputs, 100 outputs, the sizes the broken files' messages name
    write_dataset(path, build_dataset(synthetic_collection(n_sources=3), features, "full"))
    return path


@pytest.fixture(scope="module")
def small_dataset(tmp_path_factory) -> bytes:
    return write_small_dataset(tmp_path_factory.mktemp("features") / "full.h5").read_bytes()


@pytest.mark.parametrize("kind", BROKEN_FEATURES)
def test_read_dataset_names_the_file_and_what_is_wrong(tmp_path, small_dataset, kind):
    path = tmp_path / "full.h5"
    path.write_bytes(small_dataset)
    assert len(read_dataset(path).x_train) > 0  # the file reads before it is broken
    message = break_features(path, kind)
    with pytest.raises(PimannError, match=message) as raised:
        read_dataset(path)
    assert raised.value.path == str(path) and "\n" not in str(raised.value)


def test_time_reversed_training_clips_walk_backward_beside_their_original(params):
    """Forward clips played backward: the same poses in reverse order, their features those of
    backward walking (the window's velocities negated and reversed), on the original's side of
    the split; test clips are never reversed."""
    from pimann.learn.features import time_reversed

    clip = synthetic_clip(200, np.array([0.5, 0.0, 0.0]), 0.0, source="walker")
    back = time_reversed(clip)
    np.testing.assert_array_equal(back.base_position, clip.base_position[::-1])
    np.testing.assert_array_equal(back.joint_positions[0], clip.joint_positions[-1])
    np.testing.assert_array_equal(back.time, clip.time)
    assert back.source == clip.source
    layout = window_layout(params.features, RATE, "full")
    x, _, steps = clip_features(back, layout)
    linear = x[:, layout.x_slices["base_linear_window"]].reshape(len(x), 12, 3)
    np.testing.assert_allclose(linear[..., 0], -0.5 * np.cos(PITCH), atol=1e-9)  # backward
    clips = synthetic_collection(n_sources=6)
    reversing = dataclasses.replace(params.features, time_reversed=["forward", "turning"])
    dataset = build_dataset(clips, reversing, "full")
    plain = build_dataset(clips, params.features, "full")
    reversed_names = [c for c in dataset.clips if c.endswith("~reversed")]
    assert reversed_names and set(dataset.test_clips) == set(plain.test_clips)
    assert not set(reversed_names) & set(dataset.test_clips)
    assert len(dataset.x_train) > len(plain.x_train)
    sources = dict(zip(dataset.clips, dataset.sources, strict=True))
    for name in reversed_names:
        assert sources[name] == sources[name.removesuffix("~reversed")]
