"""Control-informed steering (Sec. III-C, Eqs. lin_pid, rot_pid) and the goal logic around it.

The network's base velocities drift because of biases in the data; closing a proportional loop
on the base pose towards a user goal removes the drift without retraining:

    v_c     = v_hat     - k0 R^T (p - p_d)             (base frame)
    omega_c = omega_hat - k1 vee(skew(R_d^T R))        (base frame)

With zero network velocities, p_dot = R v_c = -k0 (p - p_d) decays exponentially at rate k0,
and for small orientation errors (R_d^T R ~ I + [theta]x) theta_dot = -k1 theta. The goal is
`factor` times the commanded displacement ahead (`GoalRule`, chosen once per generator); motion
stops within `radius` of it (authors' code: 2.5 and 0.3 m, horizontal distances, heading = base
yaw).
"""

from __future__ import annotations

import dataclasses
from typing import Protocol

import numpy as np

from pimann.core.rotations import rot_z, yaw_of


def steer(
    v_hat: np.ndarray,
    omega_hat: np.ndarray,
    p: np.ndarray,
    R: np.ndarray,
    p_desired: np.ndarray,
    R_desired: np.ndarray,
    k0: float,
    k1: float,
    planar: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """Corrected base velocities (v_c, omega_c), base frame, Eqs. lin_pid and rot_pid.

    p, p_desired (..., 3) and R, R_desired (..., 3, 3) in the inertial frame; v_hat, omega_hat
    (..., 3) in the base frame. Leading axes broadcast, so the same correction can be applied to
    all K future velocities of one prediction ((K, 3) against (3,) and (3, 3)).
    `planar=True` is the authors' code's variant of lin_pid: the horizontal error only, rotated
    by the base's yaw alone (no vertical correction); rot_pid is the same in both.
    """
    R = np.asarray(R, dtype=float)
    position_error = np.asarray(p, dtype=float) - np.asarray(p_desired, dtype=float)
    frame = R
    if planar:
        position_error = position_error * np.array([1.0, 1.0, 0.0])
        yaw = yaw_of(R)
        frame = rot_z(yaw)
    linear = (position_error[..., None, :] @ frame)[..., 0, :]  # R^T (p - p_d)
    relative = np.swapaxes(np.asarray(R_desired, dtype=float), -1, -2) @ R  # R_d^T R
    angular = np.empty(relative.shape[:-1])  # vee(skew_part(R_d^T R)), without the matrices
    angular[..., 0] = relative[..., 2, 1] - relative[..., 1, 2]
    angular[..., 1] = relative[..., 0, 2] - relative[..., 2, 0]
    angular[..., 2] = relative[..., 1, 0] - relative[..., 0, 1]
    return np.asarray(v_hat) - k0 * linear, np.asarray(omega_hat) - (0.5 * k1) * angular


def goal_from_command(
    p: np.ndarray, R: np.ndarray, command_displacement: np.ndarray, factor: float
) -> np.ndarray:
    """Goal position: `factor` x the commanded displacement (heading frame, x forward, y left;
    2 or 3 components, z ignored) ahead of the base, at the base's current height."""
    p = np.asarray(p, dtype=float)
    command = np.asarray(command_displacement, dtype=float)[..., :2] * factor
    yaw = yaw_of(R)
    cos, sin = np.cos(yaw), np.sin(yaw)
    goal = p.copy()
    goal[..., 0] = p[..., 0] + cos * command[..., 0] - sin * command[..., 1]
    goal[..., 1] = p[..., 1] + sin * command[..., 0] + cos * command[..., 1]
    return goal


class GoalRule(Protocol):
    """Where the goal p_d is while a motion command holds: one class per rule, so the
    generator picks its rule once instead of testing a switch every step."""

    def __call__(self, path: np.ndarray, desired: np.ndarray, velocity: np.ndarray) -> np.ndarray:
        """Goals (B, 3) from the commanded path's points (B, 3), the desired orientations R_d
        (B, 3, 3) and the commanded velocities (B, 2, heading frame)."""
        ...


@dataclasses.dataclass(frozen=True)
class CarrotGoal:
    """The authors' goal, kept ahead as a held joystick keeps it: `factor` x the commanded
    displacement over `horizon` s (the output window) ahead of the path's point."""

    factor: float
    horizon: float  # s

    def __call__(self, path: np.ndarray, desired: np.ndarray, velocity: np.ndarray) -> np.ndarray:
        return goal_from_command(path, desired, velocity * self.horizon, self.factor)


def reached_goal(p: np.ndarray, p_goal: np.ndarray, radius: float = 0.3) -> np.ndarray | bool:
    """Whether the base is within `radius` of the goal, horizontally."""
    distance = np.linalg.norm(
        np.asarray(p, float)[..., :2] - np.asarray(p_goal, float)[..., :2], axis=-1
    )
    result = distance <= radius
    return bool(result) if np.ndim(result) == 0 else result
