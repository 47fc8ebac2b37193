"""Command scripts as the generator reads them: one command per 50 Hz step and rollout.

A script is a list of segments (body-frame velocity and yaw rate for a duration, or 'stand');
generation runs it step by step, and a batch of rollouts runs one script per row, so the
per-step commands of every row are laid out once, before the first step.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from pimann.core.errors import PimannError
from pimann.core.params import Segment, StandSegment


@dataclasses.dataclass(frozen=True)
class Command:
    """One segment as the generator reads it: velocity (x, y) and yaw rate, or stand."""

    velocity: np.ndarray  # (2,) m/s in the heading frame (x forward, y left)
    yaw_rate: float  # rad/s
    stand: bool

    @classmethod
    def of(cls, segment: Segment) -> Command:
        if isinstance(segment, StandSegment):
            return cls(np.zeros(2), 0.0, True)
        velocity = np.array([segment.vx, segment.vy], dtype=float)
        still = not np.any(velocity) and segment.yaw_rate == 0.0
        return cls(velocity, float(segment.yaw_rate), still)  # a zero command is a stand


def scenario_steps(scenario: Sequence[Segment], rate_hz: float) -> np.ndarray:
    """Segment index of each generated step (step k runs from (k-1) dt to k dt)."""
    if not scenario:
        raise PimannError(None, "the scenario has no segments")
    ends = np.cumsum([segment.duration for segment in scenario])
    if any(segment.duration <= 0 for segment in scenario):
        raise PimannError(None, "scenario segments must have positive durations")
    n_steps = int(round(ends[-1] * rate_hz))
    start_times = np.arange(n_steps) / rate_hz
    return np.minimum(np.searchsorted(ends, start_times + 0.5 / rate_hz), len(scenario) - 1)


class ScriptSteps:
    """Per step k (1..N) and row: the command, whether it starts there, whether the row runs."""

    def __init__(self, scripts: Sequence[Sequence[Segment]], rate_hz: float):
        segments = [scenario_steps(script, rate_hz) for script in scripts]
        self.lengths = np.array([len(s) for s in segments])  # steps of each row
        n, rows = int(self.lengths.max()), len(scripts)
        self.velocity = np.zeros((n + 1, rows, 2))
        self.yaw_rate = np.zeros((n + 1, rows))
        self.stand = np.ones((n + 1, rows), dtype=bool)  # past its end a row stands
        self.changed = np.zeros((n + 1, rows), dtype=bool)
        for row, (script, steps) in enumerate(zip(scripts, segments, strict=True)):
            commands = [Command.of(segment) for segment in script]
            frames = slice(1, len(steps) + 1)
            self.velocity[frames, row] = [commands[s].velocity for s in steps]
            self.yaw_rate[frames, row] = [commands[s].yaw_rate for s in steps]
            self.stand[frames, row] = [commands[s].stand for s in steps]
            self.changed[frames, row] = np.diff(steps, prepend=-1) != 0
        self.active = np.arange(n + 1)[:, None] <= self.lengths[None, :]
