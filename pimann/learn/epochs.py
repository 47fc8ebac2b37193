"""What changes from one training epoch to the next: the learning-rate factor of cosine warm
restarts, each member's sample order, and its seeds for dropout and input noise.

Every one is a function of (seed, epoch) alone, so a run resumed from its per-epoch
checkpoint continues exactly as an uninterrupted one, and a member trains alike in any group.
"""

from __future__ import annotations

import math

import numpy as np
import torch

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


# one random stream per purpose, so input noise and dropout masks never share draws
_STREAMS = {"dropout": 0x5EED, "input_noise": 0x401, "rollout_states": 0x2011}


def epoch_seed(seed: int, epoch: int, purpose: str) -> int:
    """A member's seed for one epoch and one purpose (a key of `_STREAMS`): a function of
    (seed, epoch) only, so a resumed run needs no saved RNG state."""
    return int(np.random.SeedSequence([seed, epoch, _STREAMS[purpose]]).generate_state(1)[0])


class InputNoise:
    """train.input_noise: Gaussian noise on the inputs a rollout feeds back from its own
    predictions (FeatureLayout.fed_back_columns), so the network learns to lead a state that
    has drifted off the data back to it. Each member draws from its own seed and epoch."""

    def __init__(self, std: float, columns: np.ndarray, seeds: list[int], device: torch.device):
        self.std, self.seeds, self.device = std, seeds, device
        self.columns = torch.as_tensor(columns, dtype=torch.float32, device=device)
        self.generators: list[torch.Generator] = []

    def start_epoch(self, epoch: int) -> None:
        self.generators = [
            torch.Generator(self.device).manual_seed(epoch_seed(seed, epoch, "input_noise"))
            for seed in self.seeds
        ]

    def __call__(self, x: torch.Tensor) -> torch.Tensor:
        """x (E, B, in) with noise on the fed-back columns; x itself where std is 0."""
        if self.std == 0.0:
            return x
        noise = torch.stack(
            [
                torch.randn(x.shape[1:], generator=g, device=self.device, dtype=x.dtype)
                for g in self.generators
            ]
        )
        return x + self.std * noise * self.columns
