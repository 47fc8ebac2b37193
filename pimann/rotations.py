"""Heading helpers shared by retargeting, features, generation, steering and control.

Rotations are R = Rz(yaw) Ry(pitch) Rx(roll) (pinocchio's rpy convention); the heading of a
rotation is its yaw, and its ground projection keeps only that yaw. The batched helpers
(`roll_pitch`, `exp_so3`) serve generation, which advances many rollouts at once.
"""

from __future__ import annotations

import numpy as np


def yaw_of(R: np.ndarray) -> np.ndarray:
    """Heading (rad) of rotation matrices (..., 3, 3): yaw of R = Rz(yaw) Ry(pitch) Rx(roll)."""
    R = np.asarray(R, dtype=float)
    return np.arctan2(R[..., 1, 0], R[..., 0, 0])


def rot_z(angle: np.ndarray | float) -> np.ndarray:
    """Rz(angle) for each angle: (...) -> (..., 3, 3)."""
    c, s = np.cos(angle), np.sin(angle)
    out = np.zeros((*np.shape(angle), 3, 3))
    out[..., 0, 0], out[..., 0, 1], out[..., 1, 0], out[..., 1, 1] = c, -s, s, c
    out[..., 2, 2] = 1.0
    return out


def yaw_only(rotations: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotations reduced to their heading (ground projection: roll, pitch zeroed)."""
    return rot_z(yaw_of(rotations))


def roll_pitch(rotation: np.ndarray) -> np.ndarray:
    """(B, 2) roll and pitch of rotations (B, 3, 3), as pimann.features.matrix_to_rpy."""
    roll = np.arctan2(rotation[:, 2, 1], rotation[:, 2, 2])
    pitch = np.arctan2(-rotation[:, 2, 0], np.hypot(rotation[:, 0, 0], rotation[:, 1, 0]))
    return np.stack([roll, pitch], axis=1)


def exp_so3(omega: np.ndarray) -> np.ndarray:
    """exp([w]x) of rotation vectors (B, 3): I + (sin t / t) [w]x + ((1 - cos t) / t^2) [w]x^2,
    t = |w|, the second factor as (sin(t/2) / (t/2))^2 / 2; 1e-300 added to t keeps t = 0 exact."""
    theta = np.sqrt((omega * omega).sum(axis=1)) + 1e-300
    half = 0.5 * theta
    a, b = np.sin(theta) / theta, np.sin(half) / half
    skew = np.zeros((len(omega), 3, 3))
    skew[:, 2, 1], skew[:, 0, 2], skew[:, 1, 0] = omega[:, 0], omega[:, 1], omega[:, 2]
    skew[:, 1, 2], skew[:, 2, 0], skew[:, 0, 1] = -omega[:, 0], -omega[:, 1], -omega[:, 2]
    return np.eye(3) + a[:, None, None] * skew + (0.5 * b * b)[:, None, None] * (skew @ skew)
