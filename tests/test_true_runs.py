"""true_runs against a plain loop over every short flag sequence."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from pimann.core.contacts import true_runs


def _loop_runs(flags: list[bool]) -> list[tuple[int, int]]:
    runs, start = [], None
    for k, flag in enumerate([*flags, False]):
        if flag and start is None:
            start = k
        elif not flag and start is not None:
            runs.append((start, k))
            start = None
    return runs


@pytest.mark.parametrize("length", range(7))
def test_every_sequence_matches_a_loop(length):
    for flags in itertools.product([False, True], repeat=length):
        assert true_runs(np.array(flags, dtype=bool)) == _loop_runs(list(flags))


def test_rejects_2d():
    with pytest.raises(ValueError, match="1-D"):
        true_runs(np.ones((3, 2), bool))
