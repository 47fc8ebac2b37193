"""Command following (issue 10, beyond the paper): does a rollout do what its script commands?

Command scripts from the data (`clip_commands`): a clip's own base motion (pimann.
motion_classes.base_motion: planar velocity in the heading frame and yaw rate, centred
`WINDOW_S` means) cut into piecewise-constant segments the generator reads (pimann.generate:
`MotionSegment` vx, vy, yaw_rate, duration, or `StandSegment`). Frame by frame, a segment ends
where the smoothed command departs from the segment's running mean by more than
`VELOCITY_STEP` (planar) or `YAW_RATE_STEP`, or where the frame's motion class differs from
that of the mean, once the segment has lasted `MIN_SEGMENT_S`; the running mean starts one
window after a cut (before, the window still spans the change); a shorter tail joins the
segment before it, and neighbours of one class whose means are within the steps are merged. A window
mean is blurred over half a window on either side of a change, and for a step change it is
halfway between the two levels exactly at the step, so each cut then moves to where the
smoothed command crosses halfway between its two segments' means (within `WINDOW_S` of it).
A segment's command is the mean over its frames less half a window at each cut (those frames
blend in its neighbours), its class that of its mean command (`classify`); a standing segment
is a stand.

Measures per segment of a rollout (`follow_measures`), frame k of a 50 Hz rollout being the
state after step k (pimann.command_script.scenario_steps: segment i runs from its start state, the
last frame of segment i - 1, to its last frame):
- achieved mean planar velocity in the heading frame (per-step displacements rotated by the
  step's mean yaw) and yaw rate over the segment after `settle_s` (default: `SETTLE_FRACTION`
  of the segment, at least `SETTLE_MIN_S`, at most half of it: 2 s of a 10 s command, whose
  speed is then the mean over its last 8 s); the speed along the command over the commanded
  speed (`speed_ratio`) and the yaw rate ratio;
- heading error against the commanded heading (the yaw at the segment's start plus the
  commanded yaw rate times the time since), final (signed) and largest (absolute), deg;
- touchdowns per foot and whether the feet alternate (counts differ by at most 1, at least one
  each on a motion command), under the evaluate stage's contact rule (the Schmitt trigger of
  pimann.contacts with `evaluate.contact_*`, applied to the trajectory's geometry whatever
  flags the file carries: for a rollout these are the generator's own flags, same rule);
- support-foot sliding: pimann.metrics' per-frame RMS of the sole velocity where in contact
  (`trajectory_time_series`, the same numbers the paper's total RMSE sums), left and right
  averaged, the segment's mean per frame times `PAPER_FRAMES` (the paper's 10 s test);
- on a stand: the base's largest horizontal distance, after the settling time, from where it
  was then, with its limit (`STAND_TRAVEL_M` per `STAND_TRAVEL_S`, scaled to that time), and
  the largest horizontal sole speed (per-step sole displacements over the frame period);
- drift of base roll, base pitch and the pitch of the feet in contact: the mean over the last
  `DRIFT_WINDOW_S` of the segment minus the mean over its first (at most half the segment
  each), deg.

`summarise_following` takes medians over seeds (each seed's segments of a class averaged
first) per model, steering and class, and applies the issue's criteria to them.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd
from scipy.spatial.transform import Rotation

from pimann.command_script import scenario_steps
from pimann.contacts import frame_period
from pimann.errors import PimannError
from pimann.metrics import trajectory_time_series
from pimann.motion_classes import CLASSES, WINDOW_S, base_motion, classify
from pimann.params import EvaluateParams, MotionSegment, Segment, StandSegment
from pimann.robot import Robot
from pimann.rotations import yaw_of
from pimann.trajectory import Trajectory

# ----------------------------------------------------------------------------- thresholds
# cutting a clip into commands
VELOCITY_STEP = 0.15  # m/s: a sixth of the data's walking speed (0.9 m/s), 1.5x the standing
#   threshold, above the ~0.05 m/s a stride-long window mean of mocap walking still wobbles
YAW_RATE_STEP = 0.15  # rad/s: half the data's turning rate (0.3 rad/s), under the 0.25 rad/s
#   that makes walking 'turning', so a turn that starts mid-walk is its own segment
MIN_SEGMENT_S = 1.0  # s: one stride (two steps) and the smoothing window; the generator's
#   future window (1.2 s) is as long, so shorter commands are never followed in full
COMMAND_DIGITS = 3  # commands rounded to mm/s and mrad/s (as a script in params.yaml reads)
# measuring a rollout
SETTLE_MIN_S = 1.0  # s: the command enters the network's future window over 1.2 s
SETTLE_FRACTION = 0.2  # of the segment: 2 s of a 10 s command (speed over its last 8 s)
DRIFT_WINDOW_S = 2.0  # s: mean over the first and the last 2 s (a few steps each)
PAPER_FRAMES = 500  # sliding per frame scaled to the paper's 10 s test at 50 Hz
# the criteria
SPEED_TOLERANCE = 0.25  # achieved speed along the command within 25% of the commanded
HEADING_LIMIT_DEG = 10.0  # largest heading error over the segment
STAND_TRAVEL_M, STAND_TRAVEL_S = 0.05, 5.0  # a stand holds: base moves < 5 cm in 5 s
DRIFT_LIMIT_DEG = 5.0  # base roll, base pitch and contact-foot pitch drift
ALTERNATION_SHARE = 0.5  # the median seed alternates in at least half its segments

STANDING = "standing"
SIDES = ("left", "right")


# ----------------------------------------------------------------------------- scripts


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


# ----------------------------------------------------------------------------- measures


def touchdowns(contacts: np.ndarray) -> np.ndarray:
    """(2,) touchdowns (a foot's contact switching on) per foot over (T, 2) contact flags."""
    contacts = np.asarray(contacts, dtype=bool)
    return np.sum(~contacts[:-1] & contacts[1:], axis=0)


def feet_alternate(counts: Sequence[int], moving: bool) -> bool:
    """Touchdowns per foot differ by at most one, and each foot touches down on a motion."""
    left, right = (int(c) for c in counts)
    return abs(left - right) <= 1 and (not moving or min(left, right) >= 1)


def segment_frames(script: Sequence[Segment], rate_hz: float) -> list[tuple[int, int]]:
    """(start, last) frame of each segment in a rollout of `script` (frame 0: the standing
    start): `start` is the state its command starts from, `last` the final state under it."""
    steps = scenario_steps(script, rate_hz)
    bounds = []
    for i in range(len(script)):
        mine = np.flatnonzero(steps == i)
        if len(mine) == 0:
            raise PimannError(None, f"script segment {i} is shorter than one frame")
        bounds.append((int(mine[0]), int(mine[-1]) + 1))
    return bounds


def _settle(duration: float, settle_s: float | None) -> float:
    if settle_s is not None:
        return min(settle_s, duration / 2)
    return min(max(SETTLE_MIN_S, SETTLE_FRACTION * duration), duration / 2)


def _window_drift(values: np.ndarray, window: int) -> float:
    """Mean of the last `window` values minus the mean of the first (NaN-aware), degrees."""
    first, last = values[:window], values[-window:]
    if np.all(np.isnan(first)) or np.all(np.isnan(last)):
        return math.nan
    return math.degrees(np.nanmean(last) - np.nanmean(first))


def follow_measures(
    rollout: Trajectory,
    script: Sequence[Segment],
    robot: Robot,
    evaluate_params: EvaluateParams,
    *,
    settle_s: float | None = None,
) -> list[dict[str, Any]]:
    """One row of measures per script segment (module docstring), from a rollout of it."""
    dt = frame_period(rollout)
    bounds = segment_frames(script, 1.0 / dt)
    if len(rollout) != bounds[-1][1] + 1:
        raise PimannError(
            rollout.source,
            f"has {len(rollout)} frames, a rollout of the script has {bounds[-1][1] + 1}",
        )
    series = trajectory_time_series(
        dataclasses.replace(rollout, contacts=None), robot, evaluate_params
    )  # contacts by the evaluate rule from the geometry
    position = np.asarray(rollout.base_position, dtype=float)[:, :2]
    yaw = np.unwrap(yaw_of(Rotation.from_quat(rollout.base_quaternion_xyzw).as_matrix()))
    contacts = series[[f"{side}_contact" for side in SIDES]].to_numpy(bool)
    sliding = {
        kind: np.where(contacts, series[[f"{s}_rms_{kind}" for s in SIDES]].to_numpy(), 0.0).mean(1)
        for kind in ("linear", "angular")
    }
    soles = np.stack([series[[f"{s}_sole_x", f"{s}_sole_y"]].to_numpy() for s in SIDES], 1)
    sole_speed = np.linalg.norm(np.diff(soles, axis=0), axis=-1).max(axis=1) / dt  # per step
    pitches = series[[f"{side}_sole_pitch" for side in SIDES]].to_numpy()
    contact_pitch = np.full(len(rollout), np.nan)
    down = contacts.any(axis=1)
    contact_pitch[down] = np.sum(np.where(contacts, pitches, 0.0), 1)[down] / contacts.sum(1)[down]
    roll, pitch = series["base_roll"].to_numpy(), series["base_pitch"].to_numpy()

    rows = []
    for i, (segment, (a, b)) in enumerate(zip(script, bounds, strict=True)):
        stand = isinstance(segment, StandSegment)
        command = np.zeros(3) if stand else np.array([segment.vx, segment.vy, segment.yaw_rate])
        name = segment_class(segment)
        duration = (b - a) * dt
        s = min(a + round(_settle(duration, settle_s) / dt), b - 1)
        moved = np.diff(position[s : b + 1], axis=0) / dt
        mid = (yaw[s:b] + yaw[s + 1 : b + 1]) / 2
        cos, sin = np.cos(mid), np.sin(mid)
        achieved = np.stack(
            [cos * moved[:, 0] + sin * moved[:, 1], -sin * moved[:, 0] + cos * moved[:, 1]], -1
        ).mean(axis=0)
        achieved_yaw_rate = (yaw[b] - yaw[s]) / ((b - s) * dt)
        speed = math.hypot(*command[:2])
        along = float(achieved @ command[:2] / speed) if speed > 0 else math.nan
        commanded_heading = yaw[a] + command[2] * np.arange(b - a + 1) * dt
        heading_error = np.degrees(yaw[a : b + 1] - commanded_heading)
        counts = touchdowns(contacts[a : b + 1])
        window = max(1, min(round(DRIFT_WINDOW_S / dt), (b - a) // 2))
        frames = slice(a + 1, b + 1)  # the frames generated under this command
        travel = np.hypot(*(position[s : b + 1] - position[s]).T).max()
        rows.append(
            {
                "segment": i,
                "class": name,
                "stand": stand,
                "start_s": a * dt,
                "duration_s": duration,
                "settle_s": (s - a) * dt,
                "cmd_vx": float(command[0]),
                "cmd_vy": float(command[1]),
                "cmd_yaw_rate": float(command[2]),
                "cmd_speed": speed,
                "vx": float(achieved[0]),
                "vy": float(achieved[1]),
                "yaw_rate": float(achieved_yaw_rate),
                "speed_along": along,
                "speed_ratio": along / speed if speed > 0 else math.nan,
                "yaw_rate_ratio": float(achieved_yaw_rate / command[2]) if command[2] else math.nan,
                "heading_error_final_deg": float(heading_error[-1]),
                "heading_error_max_deg": float(np.abs(heading_error).max()),
                "touchdowns_left": int(counts[0]),
                "touchdowns_right": int(counts[1]),
                "alternates": feet_alternate(counts, moving=name != STANDING),
                "sliding_linear": PAPER_FRAMES * float(sliding["linear"][frames].mean()),
                "sliding_angular": PAPER_FRAMES * float(sliding["angular"][frames].mean()),
                "base_travel_m": float(travel) if stand else math.nan,
                "base_travel_limit_m": (
                    STAND_TRAVEL_M * (b - s) * dt / STAND_TRAVEL_S if stand else math.nan
                ),
                "foot_speed_max": float(sole_speed[s:b].max()) if stand else math.nan,
                "roll_drift_deg": _window_drift(roll[frames], window),
                "pitch_drift_deg": _window_drift(pitch[frames], window),
                "foot_pitch_drift_deg": _window_drift(contact_pitch[frames], window),
            }
        )
    return rows


# ----------------------------------------------------------------------------- summary

SUMMARY_MEASURES = {  # summary column: (row column, absolute value first)
    "commanded_speed": ("cmd_speed", False),
    "achieved_speed": ("speed_along", False),
    "speed_ratio": ("speed_ratio", False),
    "commanded_yaw_rate": ("cmd_yaw_rate", False),
    "achieved_yaw_rate": ("yaw_rate", False),
    "yaw_rate_ratio": ("yaw_rate_ratio", False),
    "heading_error_deg": ("heading_error_max_deg", False),
    "heading_error_final_deg": ("heading_error_final_deg", True),
    "alternation_share": ("alternates", False),
    "sliding_linear": ("sliding_linear", False),
    "sliding_angular": ("sliding_angular", False),
    "base_travel_m": ("base_travel_m", False),
    "base_travel_ratio": ("base_travel_ratio", False),
    "foot_speed_max": ("foot_speed_max", False),
    "roll_drift_deg": ("roll_drift_deg", True),
    "pitch_drift_deg": ("pitch_drift_deg", True),
    "foot_pitch_drift_deg": ("foot_pitch_drift_deg", True),
}
CRITERIA = ("speed_pass", "heading_pass", "stand_pass", "alternation_pass", "drift_pass")


def _criteria(row: pd.Series) -> dict[str, bool | None]:
    """The issue's pass/fail on a class's medians; None where a criterion does not apply."""
    standing = row["class"] == STANDING
    ratio = row["yaw_rate_ratio"] if row["class"] == "turning_in_place" else row["speed_ratio"]
    drifts = [row[c] for c in ("roll_drift_deg", "pitch_drift_deg", "foot_pitch_drift_deg")]
    drifts = [d for d in drifts if np.isfinite(d)]
    out = {
        "speed_pass": None if standing else bool(abs(ratio - 1) <= SPEED_TOLERANCE),
        "heading_pass": bool(row["heading_error_deg"] < HEADING_LIMIT_DEG),
        "stand_pass": bool(row["base_travel_ratio"] < 1) if standing else None,
        "alternation_pass": (
            None if standing else bool(row["alternation_share"] >= ALTERNATION_SHARE)
        ),
        "drift_pass": bool(max(drifts) < DRIFT_LIMIT_DEG) if drifts else None,
    }
    applied = [v for v in out.values() if v is not None]
    out["passes"] = all(applied)
    return out


def summarise_following(rows: pd.DataFrame) -> pd.DataFrame:
    """Medians over seeds per model, steering and class (module docstring), and the criteria.

    `rows`: `follow_measures` rows with columns `model`, `steering`, `seed` (and optionally
    `pi_weight`, `variant`, carried along). A seed's segments of a class are averaged first.
    """
    missing = [c for c in ("model", "steering", "seed", "class") if c not in rows]
    if missing:
        raise PimannError(None, f"command-following rows lack columns {missing}")
    rows = rows.assign(
        base_travel_ratio=rows["base_travel_m"] / rows["base_travel_limit_m"],
        alternates=rows["alternates"].astype(float),
    )
    columns = {name: column for name, (column, _) in SUMMARY_MEASURES.items()}
    for name, (column, absolute) in SUMMARY_MEASURES.items():
        if absolute:
            rows[f"_abs_{column}"] = rows[column].abs()
            columns[name] = f"_abs_{column}"
    keys = [c for c in ("model", "variant", "pi_weight") if c in rows] + ["steering", "class"]
    values = sorted(set(columns.values()))
    per_seed = rows.groupby([*keys, "seed"], sort=False, dropna=False)[values].mean()
    segments = rows.groupby(keys, sort=False, dropna=False).size()
    medians = per_seed.groupby(level=keys, sort=False, dropna=False).median()
    seeds = per_seed.groupby(level=keys, sort=False, dropna=False).size()
    summary = pd.DataFrame({name: medians[column] for name, column in columns.items()})
    summary.insert(0, "segments", segments)
    summary.insert(0, "seeds", seeds)
    summary = summary.reset_index()
    passes = pd.DataFrame([_criteria(row) for _, row in summary.iterrows()], index=summary.index)
    for column in passes:
        summary[column] = pd.array(passes[column].tolist(), dtype="boolean")
    models = {name: k for k, name in enumerate(dict.fromkeys(rows["model"]))}
    classes = {name: k for k, name in enumerate(CLASSES)}
    summary = summary.assign(_m=summary["model"].map(models), _c=summary["class"].map(classes))
    summary = summary.sort_values(["_m", "steering", "_c"], kind="stable")
    return summary.drop(columns=["_m", "_c"]).reset_index(drop=True)
