"""What changes from one training epoch to the next: the learning-rate factor of cosine warm
restarts, each member's sample order, and its dropout seed.

Every one is a function of (seed, epoch) alone, so a run resumed from its per-epoch
checkpoint continues exactly as an uninterrupted one, and a member trains alike in any group.
"""

from __future__ import annotations

import math

import numpy as np

from pimann.core.errors import PimannError


def schedule_factor(epoch: int, period: int, mult: int) -> float:
    """Cosine warm restarts: 0.5 (1 + cos(pi t / T)) at epoch t of the current cycle of T."""
    if period < 1 or mult < 1:
        raise PimannError(None, "train.restart_period and restart_mult must be >= 1")
    t, length = epoch, period
    while t >= length:
        t -= length
        length *= mult
    return 0.5 * (1.0 + math.cos(math.pi * t / length))


def epoch_order(seed: int, epoch: int, n: int) -> np.ndarray:
    """The member's sample order in one epoch: a function of (seed, epoch) only."""
    return np.random.default_rng([seed, epoch]).permutation(n)


# one random stream per purpose, so that a new purpose never shares the dropout masks' draws
_STREAMS = {"dropout": 0x5EED}


def epoch_seed(seed: int, epoch: int, purpose: str) -> int:
    """A member's seed for one epoch and one purpose (a key of `_STREAMS`): a function of
    (seed, epoch) only, so a resumed run needs no saved RNG state."""
    return int(np.random.SeedSequence([seed, epoch, _STREAMS[purpose]]).generate_state(1)[0])
