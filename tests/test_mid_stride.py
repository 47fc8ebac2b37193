"""Gait sustainment from a clip's mid-stride state (diagnostics.mid_stride) on a tiny real
model."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch
from builders import RATE, GaitModel, roll, synthetic_clip, synthetic_collection

from diagnostics.mid_stride import (
    achieved,
    clip_start,
    leg_joint_agreement,
    network_ratio,
    sustainment,
)
from pimann.core.params import ModelParams, MotionSegment, load_params
from pimann.core.trajectory import write_collection
from pimann.generate.rollout_batch import RolloutSpec, generate_batch
from pimann.learn.dataset import write_dataset
from pimann.learn.features import build_dataset
from pimann.learn.mann import MANN
from pimann.learn.model_files import load_model, save_model
from pimann.learn.standing import StandingPose


def test_clip_start_takes_the_middle_frame_and_its_motion():
    clip = synthetic_clip(200, velocity=(0.5, 0.0, 0.0), yaw_rate=0.0)
    name, command, pose, velocities = clip_start(clip, 10.0)
    assert name == "forward"
    assert command.vx == pytest.approx(0.5, abs=1e-6) and abs(command.vy) < 1e-6
    assert command.duration == 10.0 and abs(command.yaw_rate) < 1e-9
    np.testing.assert_array_equal(pose.joints, clip.joint_positions[100])
    # central difference of the sinusoidal joints at frame 100
    expected = (clip.joint_positions[101] - clip.joint_positions[99]) * RATE / 2
    np.testing.assert_allclose(velocities, expected)


def test_achieved_speed_ratio_and_touchdowns_closed_form():
    # a base at 0.3 m/s along y under a 0.6 m/s lateral command; the left foot lands 4 times
    clip = synthetic_clip(500, velocity=(0.0, 0.3, 0.0), yaw_rate=0.0)
    contacts = np.ones((500, 2), bool)
    for k in range(4):
        contacts[100 * k + 50 : 100 * k + 60, 0] = False
    clip = dataclasses.replace(clip, contacts=contacts)
    ratio, touchdowns = achieved(clip, MotionSegment(10.0, 0.0, 0.6, 0.0))
    assert ratio == pytest.approx(0.5, abs=1e-6)
    assert touchdowns == pytest.approx(2.0 * 10.0 / clip.time[-1])  # (4 + 0) / 2 feet


def test_network_velocity_against_the_legs_tells_a_gait_stepping_in_place(robot):
    # the analytic gait echoes the commanded velocity; with stride 0 its legs step in place.
    # Unsteered: the goal pulls a lagging base towards the commanded path, so a steered
    # rollout's fed-back velocity exceeds the command
    params, steering = load_params(), False
    command = MotionSegment(6.0, 0.5, 0.0, 0.0)
    walking = roll(GaitModel(robot), [command], params, steering, robot)
    in_place = roll(GaitModel(robot, stride=0.0), [command], params, steering, robot)
    assert not walking.stopped[1:].any()
    for rollout in (walking, in_place):  # the fed-back velocity: the command, in the world
        assert network_ratio(rollout, command) == pytest.approx(1.0, abs=0.05)
        np.testing.assert_array_equal(rollout.base_velocity[0], 0.0)  # standing at frame 0
    assert achieved(walking.trajectory, command)[0] == pytest.approx(1.0, abs=0.15)
    assert abs(achieved(in_place.trajectory, command)[0]) < 0.05
    # its joint velocities are its joints' differences: the two outputs agree
    assert leg_joint_agreement(walking.trajectory) > 0.95


def test_leg_joint_agreement_reads_still_joints_with_moving_velocities_as_disagreeing():
    clip = synthetic_clip(300, velocity=(0.5, 0.0, 0.0), yaw_rate=0.0)
    # the synthetic joints 0.2 sin(2 pi 1.1 t): their velocities in closed form
    rate = 2 * np.pi * 1.1
    velocities = np.repeat(0.2 * rate * np.cos(rate * clip.time)[:, None], 26, axis=1)
    clip = dataclasses.replace(clip, joint_velocities=velocities)
    assert leg_joint_agreement(clip) > 0.999
    still = clip.joint_positions.copy()
    still[:] = still[0]
    stuck = dataclasses.replace(clip, joint_positions=still)
    assert np.isnan(leg_joint_agreement(stuck))  # the joints do not move: no correlation
    noisy = still + 1e-3 * np.random.default_rng(0).normal(size=still.shape)
    assert abs(leg_joint_agreement(dataclasses.replace(clip, joint_positions=noisy))) < 0.1


def test_rollouts_start_from_the_given_state_and_sustainment_reports_each_clip(tmp_path):
    params = load_params()
    clips = synthetic_collection(n_sources=6, frames=200)
    collection = tmp_path / "walking.h5"
    write_collection(collection, clips)
    dataset = build_dataset(clips, params.features, "full")
    write_dataset(tmp_path / "full.h5", dataset)
    small = ModelParams(2, 8, 2, 16, 2, 0.0, "elu")
    torch.manual_seed(0)
    model = MANN(dataset.layout.input_dim, dataset.layout.output_dim, small, seeds=[0])
    meta = {
        "pi_weight": 0.0,
        "seed": 0,
        "variant": "full",
        "dataset": str(tmp_path / "full.h5"),
        "params": {"model": dataclasses.asdict(small)},
    }
    save_model(tmp_path / "w0" / "0", model, dataset.layout, dataset.stats, meta)

    model, layout, stats, _ = load_model(tmp_path / "w0" / "0")
    pose = StandingPose(clips[0][1].joint_positions[80].copy(), np.zeros(2), "mid-stride")
    velocities = np.linspace(-1.0, 1.0, len(pose.joints))
    (rollout,) = generate_batch(
        model,
        layout,
        stats,
        [RolloutSpec([MotionSegment(1.0, 0.5, 0.0, 0.0)], False)],
        params.rollout,
        contact_params=params.contacts,
        standing=pose,
        start_joint_velocities=velocities,
    )
    np.testing.assert_array_equal(rollout.trajectory.joint_positions[0], pose.joints)
    np.testing.assert_array_equal(rollout.trajectory.joint_velocities[0], velocities)

    table = sustainment(tmp_path / "w0", collection, params, seconds=3.0)
    assert len(table) >= 1 and set(table["class"]) <= {"forward", "turning", "diagonal"}
    assert np.isfinite(table[["ratio_mid", "ratio_stand"]].to_numpy()).all()
    assert np.isfinite(table[["network_mid", "network_stand"]].to_numpy()).all()
    assert (table["speed"] > 0.1).all()


def test_a_folder_without_models_gets_one_line(tmp_path, capsys):
    from diagnostics.mid_stride import main

    assert main(["--models", str(tmp_path / "missing")]) == 2
    error = capsys.readouterr().err
    assert error.startswith("mid_stride: ") and "missing" in error and "not a folder" in error
    assert error.count("\n") == 1
