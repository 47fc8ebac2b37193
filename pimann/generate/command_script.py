"""Command scripts: as the generator reads them, and from the data.

A script is a list of segments (body-frame velocity and yaw rate for a duration, or 'stand');
generation runs it step by step, and a batch of rollouts runs one script per row, so the
per-step commands of every row are laid out once, before the first step (`Command`,
`scenario_steps`, `ScriptSteps`: one command per 50 Hz step and rollout).

Scripts from the data (the command-following benchmark, beyond the paper):
`clip_commands`: a clip's own base motion (pimann.learn.motion_classes.base_motion: planar
velocity in the heading frame and yaw rate, centred `WINDOW_S` means) cut into
piecewise-constant segments the generator reads (pimann.generate.rollout_batch: `MotionSegment`
vx, vy, yaw_rate, duration, or `StandSegment`). Frame by frame, a segment ends where the smoothed
command departs from the segment's running mean by more than `VELOCITY_STEP` (planar) or
`YAW_RATE_STEP`, or where the frame's motion class differs from that of the mean, once the
segment has lasted `MIN_SEGMENT_S`; the running mean starts one window after a cut (before,
the window still spans the change); a shorter tail joins the segment before it, and
neighbours of one class whose means are within the steps are merged. A window mean is
blurred over half a window on either side of a change, and for a step change it is halfway
between the two levels exactly at the step, so each cut then moves to where the smoothed
command crosses halfway between its two segments' means (within `WINDOW_S` of it). A
segment's command is the mean over its frames less half a window at each cut (those frames
blend in its neighbours), its class that of its mean command (`classify`); a standing segment
is a stand.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np

from pimann.core.contacts import frame_period
from pimann.core.errors import PimannError
from pimann.core.params import MotionSegment, Segment, StandSegment
from pimann.core.trajectory import Trajectory
from pimann.learn.motion_classes import CLASSES, WINDOW_S, base_motion, classify


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

    def at(self, k: int) -> tuple[np.ndarray, ...]:
        """Step k's command per row, as `BatchGenerator.step` takes it after k: velocity, yaw
        rate, stand, changed, active."""
        return self.velocity[k], self.yaw_rate[k], self.stand[k], self.changed[k], self.active[k]


# cutting a clip into commands
VELOCITY_STEP = 0.15  # m/s: a sixth of the data's walking speed (0.9 m/s), 1.5x the standing
#   threshold, above the ~0.05 m/s a stride-long window mean of mocap walking still wobbles
YAW_RATE_STEP = 0.15  # rad/s: half the data's turning rate (0.3 rad/s), under the 0.25 rad/s
#   that makes walking 'turning', so a turn that starts mid-walk is its own segment
MIN_SEGMENT_S = 1.0  # s: one stride (two steps) and the smoothing window; the generator's
#   future window (1.2 s) is as long, so shorter commands are never followed in full
COMMAND_DIGITS = 3  # commands rounded to mm/s and mrad/s (as a script in params.yaml reads)

STANDING = "standing"


def command_class(vx: float, vy: float, yaw_rate: float) -> str:
    """The motion class (`CLASSES`) of a constant command."""
    return CLASSES[int(classify(np.array([[vx, vy]]), np.array([yaw_rate]))[0])]


def segment_class(segment: Segment) -> str:
    """A script segment's motion class; a stand (or an all-zero command) is standing."""
    if isinstance(segment, StandSegment):
        return STANDING
    return command_class(segment.vx, segment.vy, segment.yaw_rate)


def _departs(value: np.ndarray, mean: np.ndarray, velocity_step: float, yaw_step: float) -> bool:
    return bool(
        math.hypot(*(value[:2] - mean[:2])) > velocity_step or abs(value[2] - mean[2]) > yaw_step
    )


def _class_code(command: np.ndarray) -> int:
    return int(classify(command[None, :2], command[None, 2])[0])


def _segment_means(signal: np.ndarray, cuts: list[int], trim: int) -> np.ndarray:
    """(S, 3) means of the segments [cuts[i], cuts[i + 1]) less `trim` frames at each inner cut
    (the whole segment where that leaves nothing)."""
    ends = [*cuts[1:], len(signal)]
    means = []
    for i, (start, end) in enumerate(zip(cuts, ends, strict=True)):
        lo = start + (trim if i > 0 else 0)
        hi = end - (trim if i < len(cuts) - 1 else 0)
        means.append(signal[lo:hi].mean(axis=0) if hi > lo else signal[start:end].mean(axis=0))
    return np.array(means)


def clip_commands(
    trajectory: Trajectory,
    *,
    window_s: float = WINDOW_S,
    velocity_step: float = VELOCITY_STEP,
    yaw_rate_step: float = YAW_RATE_STEP,
    min_segment_s: float = MIN_SEGMENT_S,
) -> list[Segment]:
    """A data clip's base motion as a command script (module docstring); durations sum to the
    clip's length (frames - 1 periods)."""
    dt = frame_period(trajectory)
    velocity, yaw_rate = base_motion(trajectory, window_s)
    signal = np.column_stack([velocity, yaw_rate])
    classes = classify(velocity, yaw_rate)
    n = len(signal)
    min_frames = max(1, round(min_segment_s / dt))
    half = max(1, round(window_s / 2 / dt))

    cuts, total, count = [0], np.zeros(3), 0
    for k in range(n):
        if count and k - cuts[-1] >= min_frames:
            mean = total / count
            other_class = classes[k] != _class_code(mean)
            if other_class or _departs(signal[k], mean, velocity_step, yaw_rate_step):
                cuts.append(k)
                total, count = np.zeros(3), 0
        if len(cuts) == 1 or k - cuts[-1] >= 2 * half:  # after a cut, once the window is past
            total, count = total + signal[k], count + 1
    if len(cuts) > 1 and n - 1 - cuts[-1] < min_frames:
        cuts.pop()  # a short tail joins the segment before it

    merged = True
    while merged and len(cuts) > 1:  # neighbours of one class and close means are one segment
        merged = False
        means = _segment_means(signal, cuts, half)
        for i in range(1, len(cuts)):
            a, b = means[i - 1], means[i]
            if _class_code(a) == _class_code(b) and (
                CLASSES[_class_code(a)] == STANDING
                or not _departs(b, a, velocity_step, yaw_rate_step)
            ):
                del cuts[i]
                merged = True
                break

    means = _segment_means(signal, cuts, half)
    scale = np.array([1 / velocity_step, 1 / velocity_step, 1 / yaw_rate_step])
    for i in range(1, len(cuts)):  # each cut to the halfway crossing of its segments' means
        step = (means[i] - means[i - 1]) * scale
        if not step.any():
            continue
        progress = ((signal - means[i - 1]) * scale) @ step / (step @ step)
        lo = max(cuts[i - 1] + min_frames, cuts[i] - 2 * half)
        hi = min((cuts[i + 1] if i + 1 < len(cuts) else n - 1) - min_frames, cuts[i] + 2 * half)
        frames = np.arange(max(lo, 1), hi + 1)
        crossing = frames[(progress[frames - 1] < 0.5) & (progress[frames] >= 0.5)]
        if len(crossing):
            cuts[i] = int(crossing[np.argmin(np.abs(crossing - cuts[i]))])
    means = _segment_means(signal, cuts, half)

    script: list[Segment] = []
    for start, end, mean in zip(cuts, [*cuts[1:], n - 1], means, strict=True):
        duration = round((end - start) * dt, 9)
        vx, vy, yaw = (round(float(v), COMMAND_DIGITS) + 0.0 for v in mean)  # no -0.0
        if CLASSES[_class_code(mean)] == STANDING or not (vx or vy or yaw):
            script.append(StandSegment(duration, True))
        else:
            script.append(MotionSegment(duration, vx, vy, yaw))
    return script
