"""The foot-skating ratio of motion-generation work (SPEC 8's field metric), beside the paper's
sliding RMSE in pimann.evaluate.metrics.

Defined at 20 fps: the trajectory's sole positions and lowest-corner heights are linearly
interpolated to `skating_rate_hz`; a pair of adjacent frames skates when some foot is below
`skating_height` in both and its sole origin moves more than `skating_speed_per_frame`
horizontally between them; the ratio is the fraction of pairs that skate.
"""

from __future__ import annotations

import math

import numpy as np

from pimann.core.params import EvaluateParams


def skating_ratio(
    time: np.ndarray, positions: np.ndarray, heights: np.ndarray, params: EvaluateParams
) -> float:
    """Fraction of adjacent frame pairs (at `skating_rate_hz`) in which some foot skates.

    positions (T, 2, 3) sole origins, heights (T, 2) lowest-corner heights.
    """
    grid = np.arange(time[0], time[-1] + 1e-9, 1.0 / params.skating_rate_hz)
    if len(grid) < 2:
        return math.nan
    feet = range(positions.shape[1])
    xy = np.stack(
        [np.stack([np.interp(grid, time, positions[:, f, a]) for a in (0, 1)], -1) for f in feet],
        axis=1,
    )  # (G, 2, 2)
    low = np.stack([np.interp(grid, time, heights[:, f]) for f in feet], 1) < params.skating_height
    moved = np.linalg.norm(np.diff(xy, axis=0), axis=-1) > params.skating_speed_per_frame
    skates = low[:-1] & low[1:] & moved
    return float(np.mean(skates.any(axis=1)))
