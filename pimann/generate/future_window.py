"""How a rollout fills the future half of the input's velocity window
(pimann.generate.rollout_batch, step 2): the previous prediction's output window, which is
already one frame ahead (y_i holds the window of frame i + 1, pimann.learn.features), blended
with the command.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from pimann.learn.feature_layout import FeatureLayout


def command_weights(output_offsets: Sequence[int], tau: float | None) -> np.ndarray:
    """(F,) the command's weight w = (t / window end)^tau in each sample of the output window
    (the sample at t = 0 stays the network's own: 0); `tau` None: no blend (w = 0)."""
    offsets = np.asarray(output_offsets, dtype=float)
    if tau is None:
        return np.zeros(len(offsets))
    weights = np.clip(offsets / max(offsets.max(), 1.0), 0, 1) ** tau
    weights[offsets <= 0] = 0.0
    return weights


def next_future_matrix(layout: FeatureLayout) -> np.ndarray:
    """M (F_in, F_out): the next input's future samples from this step's output window,
    M @ f(output offsets) = f(input future offsets). y_i's window is x_{i+1}'s, so where the
    input's future offsets are output offsets (both windows of params.yaml) M only selects
    samples, no interpolation: fed back, a prediction equal to the data's gives the data's
    next input exactly."""
    in_offsets = np.asarray(layout.input_offsets, dtype=float)
    future = in_offsets[len(layout.past_input_offsets()) :]
    return interpolation(future, np.asarray(layout.output_offsets, dtype=float))


def interpolation(targets: np.ndarray, knots: np.ndarray) -> np.ndarray:
    """Matrix M with M @ f(knots) = f(targets), linear between knots, clamped at the ends."""
    matrix = np.zeros((len(targets), len(knots)))
    for row, target in enumerate(np.clip(targets, knots[0], knots[-1])):
        upper = min(int(np.searchsorted(knots, target, side="right")), len(knots) - 1)
        lower = max(upper - 1, 0)
        span = knots[upper] - knots[lower]
        fraction = 0.0 if span == 0 else (target - knots[lower]) / span
        matrix[row, lower] += 1.0 - fraction
        matrix[row, upper] += fraction
    return matrix
