"""The gait-shape diagnostic against closed forms: a sinusoid's step roughness, and a standing
robot turned in place, whose soles circle the base at radii pinocchio gives."""

from __future__ import annotations

import dataclasses

import numpy as np
import pinocchio as pin
import pytest
from builders import RATE, benchmark_collection, make_trajectory

from diagnostics.gait_shape import COLUMNS, compare, gait_shape
from pimann.core.contacts import true_runs
from pimann.core.params import load_params
from pimann.core.robot import LEFT_SOLE, RIGHT_SOLE, STANDING_JOINTS
from pimann.core.rollout_files import HELD_OUT
from pimann.core.rotations import tilt_of
from pimann.core.trajectory import write_trajectory
from pimann.generate.benchmark_clips import benchmark_clips
from pimann.learn.motion_classes import class_counts, majority_class


def standing_kinematics(robot):
    """(q, pinocchio data with the frames placed) of the builders' standing robot."""
    first = make_trajectory(np.zeros((1, 2)))
    q = np.zeros(robot.model.nq)
    q[:3], q[3:7] = first.base_position[0], first.base_quaternion_xyzw[0]
    q[robot.q_index] = STANDING_JOINTS
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    return q, data


def test_high_band_share_of_two_sinusoids_is_their_steps_energy_ratio(robot):
    frames = 501  # 500 steps: whole periods of both
    t = np.arange(frames) / RATE
    joints = np.tile(STANDING_JOINTS, (frames, 1))
    legs = [i for i, n in enumerate(robot.joint_names) if n.endswith(("hip_pitch", "knee"))]
    slow, fast = 0.2 * np.sin(2 * np.pi * 1.0 * t), 0.01 * np.sin(2 * np.pi * 8.0 * t)
    joints[:, legs] += (slow + fast)[:, None]
    shape = gait_shape(make_trajectory(np.zeros((frames, 2)), joints=joints), robot, load_params())
    # the steps of A sin(2 pi f t) are a sinusoid of amplitude 2 A sin(pi f dt)
    slow_steps, fast_steps = 0.2 * np.sin(np.pi * 1.0 / RATE), 0.01 * np.sin(np.pi * 8.0 / RATE)
    expected = fast_steps**2 / (slow_steps**2 + fast_steps**2)
    np.testing.assert_allclose(shape["leg_step_high_share"], expected, rtol=1e-6)
    assert 0.1 < expected < 0.9  # both bands count


def test_a_robot_turned_in_place_twists_its_soles_with_its_base(robot):
    frames, rate = 200, 0.4  # rad/s
    yaw = rate * np.arange(frames) / RATE
    shape = gait_shape(make_trajectory(np.zeros((frames, 2)), yaw=yaw), robot, load_params())
    assert shape["double_support_share"] == 1.0  # flat on the floor throughout
    np.testing.assert_allclose([shape["contact_yaw_rate"], shape["base_yaw_rate"]], rate, rtol=1e-6)
    np.testing.assert_allclose(shape["leg_yaw_rate"], 0.0, atol=1e-6)
    # each sole origin circles the base's vertical axis: speed = rate x its horizontal radius
    q, data = standing_kinematics(robot)
    radii = [
        np.linalg.norm(data.oMf[robot.model.getFrameId(f)].translation[:2] - q[:2])
        for f in (LEFT_SOLE, RIGHT_SOLE)
    ]
    np.testing.assert_allclose(shape["contact_horizontal_speed"], rate * np.mean(radii), rtol=1e-3)
    # turning about the vertical keeps each sole's standing tilt (the median of the two)
    tilts = [
        np.degrees(np.arccos(data.oMf[robot.model.getFrameId(f)].rotation[2, 2]))
        for f in (LEFT_SOLE, RIGHT_SOLE)
    ]
    np.testing.assert_allclose(shape["contact_tilt_deg"], np.median(tilts), atol=1e-6)
    assert np.isnan(shape["leg_step_high_share"])  # legs that never move: no step to judge


def test_a_gliding_robot_travels_in_contact_and_a_lifted_one_peaks_at_its_lift(robot):
    """Slid along x at 0.3 m/s on the floor, each sole is one stance of 0.3 m/s x the clip's
    length, with no swing; lifted 8 cm by a raised cosine and put back, each sole swings
    once, its peak pinocchio's standing sole height + 0.08 m, and travels nothing."""
    frames, speed = 150, 0.3
    xy = np.zeros((frames, 2))
    xy[:, 0] = speed * np.arange(frames) / RATE
    glide = gait_shape(make_trajectory(xy), robot, load_params())
    np.testing.assert_allclose(glide["stance_travel"], speed * (frames - 1) / RATE, rtol=1e-9)
    assert np.isnan(glide["swing_peak_height"])
    lift = np.zeros(frames)
    lift[40:81] = 0.04 * (1 - np.cos(2 * np.pi * np.arange(41) / 40))  # 0 .. 0.08 .. 0
    lifted = gait_shape(make_trajectory(np.zeros((frames, 2)), z=lift), robot, load_params())
    q, data = standing_kinematics(robot)
    heights = [data.oMf[robot.model.getFrameId(f)].translation[2] for f in (LEFT_SOLE, RIGHT_SOLE)]
    np.testing.assert_allclose(lifted["swing_peak_height"], np.median(heights) + 0.08, atol=1e-9)
    np.testing.assert_allclose(lifted["stance_travel"], 0.0, atol=1e-12)
    assert true_runs(np.array([1, 1, 0, 1, 0, 0, 1], bool)) == [(0, 2), (3, 4), (6, 7)]


def test_tilt_is_the_angle_of_the_z_axis_from_the_vertical():
    roll, pitch, yaw = 0.1, -0.2, 1.3
    R = pin.rpy.rpyToMatrix(roll, pitch, yaw)  # pinocchio's, the independent reference
    np.testing.assert_allclose(tilt_of(R), np.arccos(np.cos(roll) * np.cos(pitch)), atol=1e-12)


def test_compare_puts_rollouts_of_the_class_clips_beside_those_clips(params, tmp_path):
    """Rollouts that are the held-out clips themselves measure as the data's row does; a
    rollout of another scenario and the unsteered ones are not counted."""
    data = benchmark_collection(tmp_path / "walking.h5")
    params = dataclasses.replace(
        params, features=dataclasses.replace(params.features, input=str(data), split_seed=0)
    )
    clips = [c for c in benchmark_clips(data, params) if c.split == HELD_OUT]
    assert len(clips) == 2  # c and its mirror
    for seed in (0, 1):
        for clip in clips:
            write_trajectory(
                tmp_path / "rollouts" / "w10" / str(seed) / f"{clip.scenario}-steering.h5",
                clip.trajectory,
            )
        still = make_trajectory(np.zeros((100, 2)))
        write_trajectory(tmp_path / "rollouts" / "w10" / str(seed) / "forward-steering.h5", still)
        write_trajectory(
            tmp_path / "rollouts" / "w10" / str(seed) / f"{clips[0].scenario}-nosteering.h5", still
        )
    majority = majority_class(class_counts(clips[0].trajectory))
    table = compare([tmp_path / "rollouts" / "w10"], majority, HELD_OUT, params)
    rollouts, clips_row = table.iloc[0], table.iloc[1]
    assert (rollouts["count"], clips_row["count"]) == (4, 2)
    assert clips_row["trajectories"] == "data"
    for column in COLUMNS:
        assert rollouts[column] == pytest.approx(clips_row[column], nan_ok=True)
    assert clips_row["contact_horizontal_speed"] == pytest.approx(0.4, rel=0.05)  # slid feet
    unsteered = compare([tmp_path / "rollouts" / "w10"], majority, HELD_OUT, params, False)
    assert unsteered.iloc[0]["count"] == 2
    assert unsteered.iloc[0]["contact_horizontal_speed"] == pytest.approx(0.0, abs=1e-9)
