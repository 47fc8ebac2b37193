"""Resampling a human motion onto a uniform time grid (the paper records 100 Hz, uses 50 Hz).

Positions are interpolated linearly and orientations by slerp (the constant-angular-velocity
path between two samples), so a steady turn stays steady at any rate. Recorded timestamps
jitter; the grid starts at the first sample and never extrapolates past the last one.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from pimann.core.errors import PimannError
from pimann.mocap.human_motion import HumanMotion


def uniform_grid(start: float, stop: float, rate_hz: float) -> np.ndarray:
    """start, start + 1/rate, ... up to stop (a sample within 1e-9 s of stop counts)."""
    n = int(np.floor((stop - start) * rate_hz + 1e-9)) + 1
    return start + np.arange(n) / rate_hz


def slerp_quaternions(q0: np.ndarray, q1: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """(..., 4) unit quaternions on the shorter arc from q0 (weight 0) to q1 (weight 1)."""
    dot = np.sum(q0 * q1, axis=-1, keepdims=True)
    q1 = np.where(dot < 0.0, -q1, q1)  # q and -q are the same rotation: take the short way
    dot = np.abs(dot)
    weight = weight[..., None]
    angle = np.arccos(np.clip(dot, -1.0, 1.0))
    sin_angle = np.sin(angle)
    close = sin_angle < 1e-9  # nearly equal: the linear blend is exact to rounding
    safe = np.where(close, 1.0, sin_angle)
    w0 = np.where(close, 1.0 - weight, np.sin((1.0 - weight) * angle) / safe)
    w1 = np.where(close, weight, np.sin(weight * angle) / safe)
    blended = w0 * q0 + w1 * q1
    return blended / np.linalg.norm(blended, axis=-1, keepdims=True)


def resample(motion: HumanMotion, rate_hz: float) -> HumanMotion:
    """The motion sampled every 1/rate_hz s from its first timestamp."""
    if not np.isfinite(rate_hz) or rate_hz <= 0:
        raise PimannError(motion.source, f"resampling rate must be positive, got {rate_hz}")
    if motion.n_frames < 2:
        raise PimannError(motion.source, f"cannot resample {motion.n_frames} frame(s)")
    time = motion.time
    grid = uniform_grid(float(time[0]), float(time[-1]), rate_hz)
    # interval k holds grid points with time[k] <= t < time[k+1]; the last point uses the last
    upper = np.clip(np.searchsorted(time, grid, side="right"), 1, len(time) - 1)
    lower = upper - 1
    weight = np.clip((grid - time[lower]) / (time[upper] - time[lower]), 0.0, 1.0)

    positions = motion.segment_positions
    w = weight[:, None, None]
    new_positions = (1.0 - w) * positions[lower] + w * positions[upper]

    n_segments = motion.orientations.shape[1]
    quaternions = Rotation.from_matrix(motion.orientations.reshape(-1, 3, 3)).as_quat()
    quaternions = quaternions.reshape(len(time), n_segments, 4)
    blended = slerp_quaternions(
        quaternions[lower], quaternions[upper], np.repeat(weight[:, None], n_segments, axis=1)
    )
    orientations = Rotation.from_quat(blended.reshape(-1, 4)).as_matrix()
    foot_points = None
    if motion.foot_points is not None:
        w4 = weight[:, None, None, None]
        foot_points = (1.0 - w4) * motion.foot_points[lower] + w4 * motion.foot_points[upper]
    return HumanMotion(
        time=grid,
        orientations=orientations.reshape(len(grid), n_segments, 3, 3),
        segment_positions=new_positions,
        source=motion.source,
        mirrored=motion.mirrored,
        foot_points=foot_points,
    )
