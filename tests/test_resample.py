"""Resampling: slerp recovers steady rotations, linear positions, exact decimation."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from pimann.core.errors import PimannError
from pimann.core.robot import SEGMENTS
from pimann.mocap.human_motion import HumanMotion
from pimann.mocap.resample import resample, slerp_quaternions, uniform_grid

N_SEG = len(SEGMENTS)


def motion_from(time: np.ndarray, rotations: Rotation, positions: np.ndarray) -> HumanMotion:
    matrices = rotations.as_matrix().reshape(len(time), N_SEG, 3, 3)
    return HumanMotion(time, matrices, positions.reshape(len(time), N_SEG, 3), "synthetic")


def test_constant_rate_rotation_recovers_the_analytic_angle(rng):
    rate = 2.3  # rad/s about a fixed tilted axis
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    time = np.sort(np.arange(301) / 100.0 + rng.uniform(-0.003, 0.003, 301))  # jittered 100 Hz
    start = Rotation.from_euler("xyz", [0.2, -0.4, 1.0])
    per_frame = Rotation.from_rotvec(
        np.outer(np.repeat(rate * time, N_SEG), axis)
    ) * Rotation.concatenate([start] * (len(time) * N_SEG))
    positions = np.repeat(np.column_stack([time, 2 * time, -time]), N_SEG, axis=0)
    resampled = resample(motion_from(time, per_frame, positions), 50.0)

    grid = resampled.time
    np.testing.assert_allclose(np.diff(grid), 0.02, atol=1e-12)
    assert grid[0] == time[0] and grid[-1] <= time[-1]
    expected = Rotation.from_rotvec(np.outer(rate * grid, axis)) * start
    for k in range(N_SEG):
        error = (Rotation.from_matrix(resampled.orientations[:, k]) * expected.inv()).magnitude()
        assert error.max() < 1e-9
    # positions that are linear in time are reproduced exactly
    np.testing.assert_allclose(resampled.pelvis_position, np.column_stack([grid, 2 * grid, -grid]))


def test_downsampling_uniform_data_keeps_every_other_frame(rng):
    n = 101
    time = 1.5 + np.arange(n) / 100.0
    rotations = Rotation.random(n * N_SEG, random_state=7)
    positions = rng.normal(size=(n * N_SEG, 3))
    motion = motion_from(time, rotations, positions)
    half = resample(motion, 50.0)
    assert half.n_frames == 51
    np.testing.assert_allclose(half.time, time[::2], atol=1e-12)
    np.testing.assert_allclose(half.orientations, motion.orientations[::2], atol=1e-9)
    np.testing.assert_allclose(half.segment_positions, motion.segment_positions[::2], atol=1e-9)
    assert half.rate_hz == pytest.approx(50.0)


def test_slerp_matches_scipy_including_the_long_way_round(rng):
    q0 = Rotation.random(200, random_state=1).as_quat()
    q1 = Rotation.random(200, random_state=2).as_quat()
    q1[::2] *= -1.0  # same rotations, opposite hemisphere: must still take the short arc
    weight = rng.uniform(0, 1, 200)
    ours = Rotation.from_quat(slerp_quaternions(q0, q1, weight))
    for k in range(0, 200, 17):
        pair = Rotation.from_quat(np.stack([q0[k], q1[k]]))
        reference = Slerp([0.0, 1.0], pair)([weight[k]])[0]
        assert (ours[k] * reference.inv()).magnitude() < 1e-9
    # identical quaternions: no division by zero
    same = slerp_quaternions(q0[:3], q0[:3], np.array([0.0, 0.5, 1.0]))
    np.testing.assert_allclose(same, q0[:3], atol=1e-12)


def test_grid_and_bad_rates():
    np.testing.assert_allclose(uniform_grid(0.0, 1.0, 4.0), [0, 0.25, 0.5, 0.75, 1.0])
    time = np.arange(5) / 10.0
    motion = motion_from(time, Rotation.identity(5 * N_SEG), np.zeros((5 * N_SEG, 3)))
    for bad in (0.0, -5.0, np.nan):
        with pytest.raises(PimannError, match="synthetic"):
            resample(motion, bad)
