"""Command following (beyond the paper): does a rollout do what its script commands?

Command scripts from the data: pimann.generate.command_script.

Measures per segment of a rollout (`follow_measures`), frame k of a 50 Hz rollout being the
state after step k (pimann.generate.command_script.scenario_steps: segment i runs from its start
state, the last frame of segment i - 1, to its last frame):
- achieved mean planar velocity in the heading frame (per-step displacements rotated by the
  step's mean yaw) and yaw rate over the segment after `settle_s` (default: `SETTLE_FRACTION`
  of the segment, at least `SETTLE_MIN_S`, at most half of it: 2 s of a 10 s command, whose
  speed is then the mean over its last 8 s); the speed along the command over the commanded
  speed (`speed_ratio`) and the yaw rate ratio;
- heading error against the commanded heading (the yaw at the segment's start plus the
  commanded yaw rate times the time since), final (signed) and largest (absolute), deg;
- touchdowns per foot and whether the feet alternate (counts differ by at most 1; on a motion
  command at least one, and one each in a segment of two strides or more), under the
  shared contact rule (params.yaml `contacts`, the Schmitt trigger of pimann.core.contacts),
  applied to the trajectory's geometry whatever
  flags the file carries: for a rollout these are the generator's own flags, same rule);
- support-foot sliding: pimann.evaluate.metrics' per-frame RMS of the sole velocity where in contact
  (`trajectory_time_series`, the same numbers the paper's total RMSE sums), left and right
  averaged, the segment's mean per frame times `PAPER_FRAMES` (the paper's 10 s test);
- on a stand: the base's largest horizontal distance, after the settling time, from where it
  was then, with its limit (`STAND_TRAVEL_M` per `STAND_TRAVEL_S`, scaled to that time), and
  the largest horizontal sole speed (per-step sole displacements over the frame period);
- drift of base roll, base pitch and the pitch of the feet in contact: the mean over the last
  `DRIFT_WINDOW_S` of the segment minus the mean over its first (at most half the segment
  each), deg.

`summarise_following` takes medians over seeds (each seed's segments of a class averaged
first) per model, split (where the rows have one), steering and class, and applies the benchmark's
criteria to them.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd
from scipy.spatial.transform import Rotation

from pimann.core.contacts import frame_period, touchdowns
from pimann.core.errors import PimannError
from pimann.core.params import ContactParams, EvaluateParams, Segment, StandSegment
from pimann.core.robot import Robot
from pimann.core.rotations import to_heading_frame, yaw_of
from pimann.core.trajectory import Trajectory
from pimann.evaluate.metrics import trajectory_time_series
from pimann.generate.command_script import STANDING, scenario_steps, segment_class
from pimann.learn.motion_classes import CLASSES

# ----------------------------------------------------------------------------- thresholds
# measuring a rollout
SETTLE_MIN_S = 1.0  # s: the command enters the network's future window over 1.2 s
SETTLE_FRACTION = 0.2  # of the segment: 2 s of a 10 s command (speed over its last 8 s)
DRIFT_WINDOW_S = 2.0  # s: mean over the first and the last 2 s (a few steps each)
PAPER_FRAMES = 500  # sliding per frame scaled to the paper's 10 s test at 50 Hz
# the benchmark's criteria
SPEED_TOLERANCE = 0.25  # achieved speed along the command within 25% of the commanded
HEADING_LIMIT_DEG = 10.0  # largest heading error over the segment
STAND_TRAVEL_M, STAND_TRAVEL_S = 0.05, 5.0  # a stand holds: base moves < 5 cm in 5 s
DRIFT_LIMIT_DEG = 5.0  # base roll, base pitch and contact-foot pitch drift
ALTERNATION_SHARE = 0.5  # the median seed alternates in at least half its segments
# the data's stride (one touchdown of each foot): 1.1 s, 0.90 touchdowns a foot per second in
# its forward segments. A segment shorter than two strides may hold one foot's touchdown only:
# the data's own 1.04 s segments do, and a rollout's first segment also starts from standing
STRIDE_S = 1.1

SIDES = ("left", "right")


# ----------------------------------------------------------------------------- measures


def feet_alternate(counts: Sequence[int], moving: bool, duration_s: float = math.inf) -> bool:
    """Touchdowns per foot differ by at most one (the benchmark's rule); on a motion the robot
    steps, and each foot touches down once the segment lasts two strides (`STRIDE_S`)."""
    left, right = (int(c) for c in counts)
    if abs(left - right) > 1:
        return False
    if not moving:
        return True
    return min(left, right) >= 1 if duration_s >= 2 * STRIDE_S else left + right >= 1


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
    contact_params: ContactParams,
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
        dataclasses.replace(rollout, contacts=None), robot, evaluate_params, contact_params
    )  # contacts by the evaluate rule from the geometry
    position = np.asarray(rollout.base_position, dtype=float)[:, :2]
    yaw = np.unwrap(yaw_of(Rotation.from_quat(rollout.base_quaternion_xyzw).as_matrix()))
    contacts = series[[f"{side}_contact" for side in SIDES]].to_numpy(bool)
    sliding = {
        kind: np.where(contacts, series[[f"{s}_rms_{kind}" for s in SIDES]].to_numpy(), 0.0).mean(1)
        for kind in ("linear", "angular", "linear_position")
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
        achieved = to_heading_frame(moved, mid).mean(axis=0)
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
                "alternates": feet_alternate(counts, name != STANDING, duration),
                "sliding_linear": PAPER_FRAMES * float(sliding["linear"][frames].mean()),
                "sliding_angular": PAPER_FRAMES * float(sliding["angular"][frames].mean()),
                "sliding_linear_position": (
                    PAPER_FRAMES * float(sliding["linear_position"][frames].mean())
                ),
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
    "sliding_linear_position": ("sliding_linear_position", False),
    "base_travel_m": ("base_travel_m", False),
    "base_travel_ratio": ("base_travel_ratio", False),
    "foot_speed_max": ("foot_speed_max", False),
    "roll_drift_deg": ("roll_drift_deg", True),
    "pitch_drift_deg": ("pitch_drift_deg", True),
    "foot_pitch_drift_deg": ("foot_pitch_drift_deg", True),
}
CRITERIA = ("speed_pass", "heading_pass", "stand_pass", "alternation_pass", "drift_pass")


def _criteria(row: pd.Series) -> dict[str, bool | None]:
    """The benchmark's pass/fail on a class's medians; None where a criterion does not apply."""
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
    """Medians over seeds per model, split, steering and class (module docstring), and the
    criteria.

    `rows`: `follow_measures` rows with columns `model`, `steering`, `seed` (and optionally
    `pi_weight`, `variant`, carried along, and `split`, kept apart). A seed's segments of a
    class are averaged first.
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
    keys = [c for c in ("model", "variant", "pi_weight", "split") if c in rows]
    keys += ["steering", "class"]
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
    order = ["_m", *(["split"] if "split" in summary else []), "steering", "_c"]
    summary = summary.sort_values(order, kind="stable")
    return summary.drop(columns=["_m", "_c"]).reset_index(drop=True)
