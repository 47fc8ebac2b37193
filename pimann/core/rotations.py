"""Heading helpers shared by retargeting, features, generation, steering and control.

Rotations are R = Rz(yaw) Ry(pitch) Rx(roll) (pinocchio's rpy convention); the heading of a
rotation is its yaw, and its ground projection keeps only that yaw.
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
