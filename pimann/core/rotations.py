"""Rotations shared by retargeting, features, generation, steering and control: headings,
roll-pitch-yaw, and the SO(3) algebra (hat, vee, exp).

Rotations are R = Rz(yaw) Ry(pitch) Rx(roll) (pinocchio's rpy convention); the heading of a
rotation is its yaw, and its ground projection keeps only that yaw.
"""

from __future__ import annotations

import numpy as np

_EYE = np.eye(3)


def yaw_of(R: np.ndarray) -> np.ndarray:
    """Heading (rad) of rotation matrices (..., 3, 3): yaw of R = Rz(yaw) Ry(pitch) Rx(roll)."""
    R = np.asarray(R, dtype=float)
    return np.arctan2(R[..., 1, 0], R[..., 0, 0])


def tilt_of(R: np.ndarray) -> np.ndarray:
    """Tilt (rad) of rotation matrices (..., 3, 3): the angle between R's z axis and the
    world's vertical, whatever the heading (0 for a flat sole)."""
    return np.arccos(np.clip(np.asarray(R, dtype=float)[..., 2, 2], -1.0, 1.0))


def rot_z(angle: np.ndarray | float) -> np.ndarray:
    """Rz(angle) for each angle: (...) -> (..., 3, 3)."""
    c, s = np.cos(angle), np.sin(angle)
    out = np.zeros((*np.shape(angle), 3, 3))
    out[..., 0, 0], out[..., 0, 1], out[..., 1, 0], out[..., 1, 1] = c, -s, s, c
    out[..., 2, 2] = 1.0
    return out


def _planar_rotation(vectors, yaw) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A float copy of `vectors` broadcast against `yaw` (...), its x and y, cos and sin yaw."""
    vectors = np.asarray(vectors, dtype=float)
    shape = np.broadcast_shapes(vectors.shape, (*np.shape(yaw), vectors.shape[-1]))
    out = np.broadcast_to(vectors, shape).copy()
    return out, out[..., :2].copy(), np.cos(yaw), np.sin(yaw)


def to_heading_frame(vectors: np.ndarray, yaw: np.ndarray | float) -> np.ndarray:
    """World vectors (..., 2 or 3) in the heading frame of `yaw` (...), x forward, y left: turned
    by -yaw about z, x' = c x + s y, y' = -s x + c y (c, s = cos, sin yaw); z passes unchanged.
    Leading axes broadcast; the inverse of `from_heading_frame`."""
    out, xy, c, s = _planar_rotation(vectors, yaw)
    x, y = xy[..., 0], xy[..., 1]
    out[..., 0] = c * x + s * y
    out[..., 1] = -s * x + c * y
    return out


def from_heading_frame(vectors: np.ndarray, yaw: np.ndarray | float) -> np.ndarray:
    """Heading-frame vectors (..., 2 or 3) of `yaw` (...) in the world frame: turned by yaw
    about z, x' = c x - s y, y' = s x + c y (c, s = cos, sin yaw); z passes unchanged.
    Leading axes broadcast; the inverse of `to_heading_frame`."""
    out, xy, c, s = _planar_rotation(vectors, yaw)
    x, y = xy[..., 0], xy[..., 1]
    out[..., 0] = c * x - s * y
    out[..., 1] = s * x + c * y
    return out


def yaw_only(rotations: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotations reduced to their heading (ground projection: roll, pitch zeroed)."""
    return rot_z(yaw_of(rotations))


def skew_part(matrices: np.ndarray) -> np.ndarray:
    """(A - A^T) / 2 over the last two axes."""
    matrices = np.asarray(matrices, dtype=float)
    return 0.5 * (matrices - np.swapaxes(matrices, -1, -2))


def vee(skew: np.ndarray) -> np.ndarray:
    """The vector w of a skew-symmetric [w]x, over the last two axes."""
    skew = np.asarray(skew, dtype=float)
    return np.stack([skew[..., 2, 1], skew[..., 0, 2], skew[..., 1, 0]], axis=-1)


def hat(vectors: np.ndarray) -> np.ndarray:
    """[w]x, the skew-symmetric matrix of w (..., 3) -> (..., 3, 3)."""
    w = np.asarray(vectors, dtype=float)
    zero = np.zeros_like(w[..., 0])
    return np.stack(
        [
            np.stack([zero, -w[..., 2], w[..., 1]], -1),
            np.stack([w[..., 2], zero, -w[..., 0]], -1),
            np.stack([-w[..., 1], w[..., 0], zero], -1),
        ],
        axis=-2,
    )


def rotation_rpy(
    roll: float | np.ndarray = 0.0, pitch: float | np.ndarray = 0.0, yaw: float | np.ndarray = 0.0
) -> np.ndarray:
    """R = Rz(yaw) Ry(pitch) Rx(roll): e.g. a desired orientation from a commanded heading.

    Angles broadcast: (...) -> (..., 3, 3), so a batch of rollouts gets its rotations at once.
    """
    angles = (np.asarray(a, dtype=float) for a in (roll, pitch, yaw))
    roll, pitch, yaw = np.broadcast_arrays(*angles)
    cr, sr, cp, sp, cy, sy = (f(a) for a in (roll, pitch, yaw) for f in (np.cos, np.sin))
    rows = (
        (cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr),
        (sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr),
        (-sp, cp * sr, cp * cr),
    )
    return np.stack([np.stack(row, axis=-1) for row in rows], axis=-2)


def roll_pitch(rotation: np.ndarray) -> np.ndarray:
    """(B, 2) roll and pitch of rotations (B, 3, 3), as `matrix_to_rpy`: the
    inverse of `rotation_rpy` but for yaw (generation's stop blend and fed-back pose)."""
    roll = np.arctan2(rotation[:, 2, 1], rotation[:, 2, 2])
    pitch = np.arctan2(-rotation[:, 2, 0], np.hypot(rotation[:, 0, 0], rotation[:, 1, 0]))
    return np.stack([roll, pitch], axis=1)


def exp_so3(omega: np.ndarray) -> np.ndarray:
    """exp([w]x) of rotation vectors (B, 3): I + (sin t / t) [w]x + ((1 - cos t) / t^2) [w]x^2,
    t = |w|, the second factor as (sin(t/2) / (t/2))^2 / 2; 1e-300 added to t keeps t = 0 exact.
    Generation integrates the base orientation of every rollout of a batch with it."""
    theta = np.sqrt((omega * omega).sum(axis=1)) + 1e-300
    half = 0.5 * theta
    a, b = np.sin(theta) / theta, np.sin(half) / half
    skew = np.zeros((len(omega), 9))  # [w]x, row-major
    skew[:, [7, 2, 3]], skew[:, [5, 6, 1]] = omega, -omega
    skew = skew.reshape(-1, 3, 3)
    return _EYE + a[:, None, None] * skew + (0.5 * b * b)[:, None, None] * (skew @ skew)


def matrix_to_rpy(rotations: np.ndarray) -> np.ndarray:
    """(T,3) roll, pitch, yaw with R = Rz(yaw) Ry(pitch) Rx(roll), yaw unwrapped along T: the
    features' angles (roll and pitch those of `roll_pitch`, the same operations)."""
    roll = np.arctan2(rotations[:, 2, 1], rotations[:, 2, 2])
    pitch = np.arctan2(-rotations[:, 2, 0], np.hypot(rotations[:, 0, 0], rotations[:, 1, 0]))
    yaw = np.unwrap(np.arctan2(rotations[:, 1, 0], rotations[:, 0, 0]))
    return np.stack([roll, pitch, yaw], axis=1)


def rpy_arcsin_pitch(rotations: np.ndarray) -> np.ndarray:
    """(..., 3) roll, pitch, yaw with R = Rz(yaw) Ry(pitch) Rx(roll), pitch as arcsin(-R[2, 0]):
    the evaluation's base drift. The same angles as `matrix_to_rpy` up to rounding, kept apart
    because the two formulas differ in the last bits and the metrics' outputs follow them."""
    roll = np.arctan2(rotations[..., 2, 1], rotations[..., 2, 2])
    pitch = np.arcsin(np.clip(-rotations[..., 2, 0], -1.0, 1.0))
    yaw = np.arctan2(rotations[..., 1, 0], rotations[..., 0, 0])
    return np.stack([roll, pitch, yaw], axis=-1)


def quaternion_xyzw_matrices(quaternions: np.ndarray) -> np.ndarray:
    """(T, 3, 3) rotations of (T, 4) quaternions (x, y, z, w), normalised first."""
    quaternions = np.asarray(quaternions, dtype=float)
    x, y, z, w = (quaternions / np.linalg.norm(quaternions, axis=1, keepdims=True)).T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=-2,
    )
