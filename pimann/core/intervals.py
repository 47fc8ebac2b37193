"""Runs of True in a flag sequence, as [start, stop) index pairs.

Contacts, swings, double support and standing pauses are all such runs; the retargeting, the
clip cutter and the simulation's footstep plan read them the same way from here.
"""

from __future__ import annotations

import numpy as np


def true_runs(flags: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) pairs of the maximal runs of True in a 1-D bool array, in order."""
    flags = np.asarray(flags, dtype=bool)
    if flags.ndim != 1:
        raise ValueError(f"flags must be 1-D, not of shape {flags.shape}")
    edges = np.flatnonzero(np.diff(np.concatenate([[0], flags.astype(np.int8), [0]])))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True))
