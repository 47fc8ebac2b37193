"""Velocities of a configuration trajectory by finite differences on the configuration
manifold: what a trajectory's poses alone say about how it moves (pimann.evaluate.metrics' position
level, the data report's sole velocities)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin


def manifold_velocities(model: pin.Model, configurations: np.ndarray, time: np.ndarray):
    """(T, nv) velocities by finite differences of q on the manifold (base twist in body frame).

    Second order everywhere (also for uneven time steps): interior frames combine the tangent
    vectors at q_k towards q_{k-1} and q_{k+1}; the ends use the three-point one-sided formula
    (tangents at the end frame towards its two neighbours). Two frames: a plain difference.
    """
    n = len(configurations)

    def towards(k: int, j: int) -> np.ndarray:
        return pin.difference(model, configurations[k], configurations[j])

    forward = np.array([towards(k, k + 1) for k in range(n - 1)])
    backward = np.array([towards(k, k - 1) for k in range(1, n)])
    steps = np.diff(time)
    velocities = np.empty((n, model.nv))
    if n == 2:
        velocities[0] = forward[0] / steps[0]
        velocities[1] = -backward[0] / steps[0]
        return velocities
    h_b, h_f = steps[:-1, None], steps[1:, None]
    ahead = forward[1:] / h_f  # slope towards k+1, at frames 1..n-2
    behind = -backward[:-1] / h_b  # slope from k-1
    velocities[1:-1] = (h_b * ahead + h_f * behind) / (h_b + h_f)

    def one_sided(near: np.ndarray, far: np.ndarray, a: float, b: float) -> np.ndarray:
        # slope at 0 of the parabola through (0, 0), (a, near), (b, far)
        return (near * b * b - far * a * a) / (a * b * (b - a))

    first, last = steps[0], steps[-1]
    velocities[0] = one_sided(forward[0], towards(0, 2), first, first + steps[1])
    velocities[-1] = -one_sided(backward[-1], towards(n - 1, n - 3), last, last + steps[-2])
    return velocities
