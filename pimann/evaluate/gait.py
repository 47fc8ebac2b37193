"""The gait of a trajectory: how far and how fast it walks, how it steps, and whether it glides.

The sliding metrics say how much a foot in contact moves; these say what the walking looks like,
measured alike on a rollout (over its last `evaluate.gait_window_s`, after the start-up) and on
windows of the retargeted data (`data_gait_windows`), with the evaluate stage's contact rule on
each sole's lowest corner (pimann.core.contacts: the generated feet land pitched, so a sole
origin can stay above the contact height through a stance its corner makes):

- travel along the command: the base's planar displacement, frame to frame, projected on the
  commanded direction in the base's current heading frame (a joystick's command is the robot's
  own), summed over the window; speed = travel / window duration, against the commanded
  speed (the mean |(vx, vy)| of the script over the window);
- heading change: base yaw (unwrapped) at the window's end less at its start; heading error:
  the largest |yaw - commanded yaw| over the window, the commanded yaw being the start's yaw
  plus the integral of the commanded yaw rate;
- a swing: a maximal run of frames in which a foot is not in contact, with a contact frame on
  each side inside the trajectory (a lift-off and a touchdown); it counts in the window when
  its touchdown does;
- cadence: the counted swings of both feet per second of the window (a pause counts as time
  without steps, so a model that stops half the time has half the cadence);
- step length: half the horizontal distance between a swinging foot's footprints before and
  after the swing, a footprint being the sole origin's median horizontal position over the
  stance (a foot carried past the other one moves by two steps, so at a steady gait step
  length x cadence = speed); the median over the counted swings;
- swing apex: the median over the counted swings of the lowest corner's highest point;
- standing share: the share of the window's frames with both feet in contact and the base's
  planar speed below `STANDING_SPEED` (pimann.learn.motion_classes);
- glide share: the share of the window's frames in which some foot glides: its lowest corner
  below `evaluate.glide_height` and that corner's horizontal speed (position level, the
  sole's twist moved to the corner, so a foot rolling over its heel or toe does not glide)
  above `evaluate.glide_speed`;
- contact sole pitch: the median |pitch| of the soles in contact over the window.

The data's level at a speed (`gait_level`): the same measures over windows of the data's
forward walking (`data_gait_windows`: every frame forward, pimann.learn.motion_classes; each
from a touchdown to the first touchdown at least `DATA_WINDOW_S` later, so its cadence is not
rounded to whole steps), each window's speed its net planar base displacement over its duration;
at a speed v, the median (and range) of the windows within `evaluate.gait_speed_band` of v. A
rollout commanded forward gets the data's level at its commanded speed beside its own
(`data_gait_*` columns of metrics.csv, `with_data_gait`), and at the speed it achieved
(`gait_speed`) the data's cadence and step length, median and range
(`data_gait_<measure>_at_speed_{median,low,high}`, `AT_SPEED`): `gait_in_data_range` says
whether its cadence and step length both lie inside the data's range at that speed (None where
its achieved speed is under `STANDING_SPEED` or no data window is near), so a rollout walking
slower than commanded is judged against the data's gait at its own speed.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd

from pimann.core.contacts import contacts_from_heights, frame_period, true_runs
from pimann.core.errors import PimannError
from pimann.core.params import ContactParams, EvaluateParams, Segment
from pimann.core.rollout_files import read_script
from pimann.core.trajectory import Trajectory
from pimann.learn.motion_classes import CLASSES, STANDING_SPEED, classify

DATA_WINDOW_S = 2.0  # s: a data window holds 3-4 steps; the data's forward walking comes in
#   runs of 2-5 s (a clip turns, stops or walks back between them)
DATA_WINDOW_HOP = 1  # touchdowns between window starts: windows overlap, one per step
SPEED_BINS = tuple(round(0.1 * k, 1) for k in range(2, 14))  # m/s: the data's level by speed
# the per-window measures, in metrics.csv as `gait_<name>`, and the data's level at the
# commanded speed beside each rollout as `data_gait_<name>` (with `data_gait_windows`)
MEASURES = (
    "cadence",
    "step_length",
    "swing_apex",
    "standing_share",
    "glide_share",
    "contact_sole_pitch",
)
# the measures whose data range at the rollout's achieved speed judges its gait
# (`data_gait_<name>_at_speed_{median,low,high}`, `gait_in_data_range`)
AT_SPEED = ("cadence", "step_length")
FORWARD = CLASSES.index("forward")
# the gait columns summarised over seeds in metrics_summary.json (metrics.csv keeps them all)
GAIT_SUMMARY = [
    *(f"gait_{name}" for name in ("speed_ratio", "heading_change", *MEASURES)),
    *(f"data_gait_{name}" for name in ("cadence", "step_length")),
    *(f"data_gait_{name}_at_speed_median" for name in AT_SPEED),
    "gait_in_data_range",
]


def _none(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def _median(values: Sequence[float] | np.ndarray) -> float | None:
    values = np.asarray(values, dtype=float)
    return float(np.median(values)) if len(values) else None


def swings(contacts: np.ndarray) -> list[tuple[int, int, int]]:
    """(foot, lift-off frame, touchdown frame) of every swing of (T, F) contacts: a run of
    frames out of contact with a contact frame on each side (the touchdown: the first frame
    back in contact), in touchdown order."""
    contacts = np.asarray(contacts, dtype=bool)
    found = [
        (foot, start, stop)
        for foot in range(contacts.shape[1])
        for start, stop in true_runs(~contacts[:, foot])
        if start > 0 and stop < len(contacts)
    ]
    return sorted(found, key=lambda swing: (swing[2], swing[0]))


def _step_lengths(
    positions: np.ndarray, contacts: np.ndarray, counted: list[tuple[int, int, int]]
) -> list[float]:
    """Half the distance between each counted swing's footprints: the sole origin's median
    horizontal position over the stance before it and over the one after it."""
    stances = [true_runs(contacts[:, foot]) for foot in range(contacts.shape[1])]
    ending = [{stop: start for start, stop in runs} for runs in stances]
    starting = [dict(runs) for runs in stances]
    lengths = []
    for foot, off, on in counted:
        before = positions[ending[foot][off] : off, foot, :2]
        after = positions[on : starting[foot][on], foot, :2]
        shift = np.median(after, axis=0) - np.median(before, axis=0)
        lengths.append(0.5 * float(np.linalg.norm(shift)))
    return lengths


def window_gait(
    time: np.ndarray,
    contacts: np.ndarray,
    heights: np.ndarray,
    positions: np.ndarray,
    pitches: np.ndarray,
    corner_speeds: np.ndarray,
    base_xy: np.ndarray,
    window: tuple[int, int],
    params: EvaluateParams,
) -> dict[str, float | int | None]:
    """The command-free measures (module docstring) of the frames [start, stop) of a trajectory.

    time (T,); contacts (T, 2) by the lowest-corner rule; heights (T, 2) lowest-corner heights;
    positions (T, 2, 3) sole origins; pitches (T, 2) sole pitch; corner_speeds (T, 2) the
    lowest corners' horizontal speeds; base_xy (T, 2) planar base position.
    """
    start, stop = window
    if not 0 <= start < stop - 1 < len(time):
        raise PimannError(None, f"gait window [{start}, {stop}) outside {len(time)} frames")
    duration = float(time[stop - 1] - time[start])
    counted = [s for s in swings(contacts) if start < s[2] < stop]  # landed after the start
    lengths = _step_lengths(positions, contacts, counted)
    apexes = [float(heights[off:on, f].max()) for f, off, on in counted]
    frames = slice(start, stop)
    base_speed = np.linalg.norm(np.gradient(base_xy, time, axis=0), axis=-1)[frames]
    standing = contacts[frames].all(axis=1) & (base_speed < STANDING_SPEED)
    gliding = (heights[frames] < params.glide_height) & (corner_speeds[frames] > params.glide_speed)
    pitch = np.abs(pitches[frames])[contacts[frames]]
    return {
        "window_s": duration,
        "swings": len(counted),
        "cadence": len(counted) / duration if duration > 0 else None,
        "step_length": _median(lengths),
        "swing_apex": _median(apexes),
        "standing_share": float(standing.mean()),
        "glide_share": float(gliding.any(axis=1).mean()),
        "contact_sole_pitch": _median(pitch),
    }


def command_frames(script: Sequence[Segment], time: np.ndarray) -> np.ndarray:
    """(T, 3) the commanded [vx, vy, yaw_rate] (heading frame) at each frame of a rollout of
    `script`: frame k >= 1 ends the generator's step k, which runs the segment at (k - 1/2) dt;
    past the script's end and on a stand, zero."""
    time = np.asarray(time, dtype=float)
    ends = np.cumsum([segment.duration for segment in script])
    elapsed = time - time[0] - 0.5 * np.diff(time, prepend=time[0] - (time[1] - time[0]))
    index = np.searchsorted(ends, np.maximum(elapsed, 0.0), side="right")
    table = np.array(
        [
            [getattr(s, "vx", 0.0), getattr(s, "vy", 0.0), getattr(s, "yaw_rate", 0.0)]
            for s in script
        ]
        + [[0.0, 0.0, 0.0]]
    )
    return table[np.minimum(index, len(script))]


def command_following(
    time: np.ndarray,
    base_xy: np.ndarray,
    yaw: np.ndarray,
    command: np.ndarray,
    window: tuple[int, int],
) -> dict[str, float | None]:
    """Travel, speed and heading against the command (module docstring) over [start, stop).

    base_xy (T, 2) planar base position and yaw (T,) unwrapped base yaw, in one world frame;
    command (T, 3) from `command_frames`.
    """
    start, stop = window
    steps = np.arange(start, stop - 1)  # frame k -> k + 1, under frame k + 1's command
    duration = float(time[stop - 1] - time[start])
    velocity = command[steps + 1, :2]
    speed = np.linalg.norm(velocity, axis=-1)
    direction = np.divide(
        velocity, speed[:, None], out=np.zeros_like(velocity), where=speed[:, None] > 0
    )
    cos, sin = np.cos(yaw[steps]), np.sin(yaw[steps])
    world = np.stack(
        [
            cos * direction[:, 0] - sin * direction[:, 1],
            sin * direction[:, 0] + cos * direction[:, 1],
        ],
        -1,
    )
    travel = float(np.sum(np.diff(base_xy[start:stop], axis=0) * world))
    dt = np.diff(time[start:stop])
    command_speed = float(np.sum(speed * dt) / duration) if duration > 0 else math.nan
    commanded_yaw = yaw[start] + np.concatenate([[0.0], np.cumsum(command[steps + 1, 2] * dt)])
    achieved = travel / duration if duration > 0 else math.nan
    return {
        "command_speed": _none(command_speed),
        "travel": travel,
        "speed": _none(achieved),
        "speed_ratio": _none(achieved / command_speed) if command_speed > 0 else None,
        "heading_change": float(yaw[stop - 1] - yaw[start]),
        "heading_error_max_abs": float(np.max(np.abs(yaw[start:stop] - commanded_yaw))),
    }


def commanded_forward(command: np.ndarray, window: tuple[int, int]) -> bool:
    """Whether the window's mean command is forward walking (pimann.learn.motion_classes)."""
    mean = command[window[0] : window[1]].mean(axis=0)
    return int(classify(mean[None, :2], mean[None, 2])[0]) == FORWARD


def corner_speeds(corner_velocities: np.ndarray) -> np.ndarray:
    """(T, 2) horizontal speed of the lowest corners from their (T, 2, 6) twists."""
    return np.linalg.norm(np.asarray(corner_velocities)[..., :2], axis=-1)


def last_window(time: np.ndarray, seconds: float) -> tuple[int, int]:
    """[start, stop) of the frames in the last `seconds` of `time` (the whole of a shorter one)."""
    start = int(np.searchsorted(time, time[-1] - seconds - 1e-9))
    return min(start, len(time) - 2), len(time)


def trajectory_gait(
    trajectory: Trajectory,
    heights: np.ndarray,
    positions: np.ndarray,
    pitches: np.ndarray,
    corner_velocities: np.ndarray,
    base_xy: np.ndarray,
    yaw: np.ndarray,
    params: EvaluateParams,
    contact_params: ContactParams,
    contacts: np.ndarray | None = None,
) -> dict[str, Any]:
    """`gait_<measure>` of a trajectory over its last `evaluate.gait_window_s` (module
    docstring); the command's measures are None for a file that records no script.

    heights, positions, pitches, corner_velocities: the soles (pimann.evaluate.metrics.analyse,
    reused, not recomputed); base_xy (T, 2), yaw (T,) unwrapped, in one world frame; contacts
    (T, 2): the rule's on `heights` where already at hand (a file's own flags never).
    """
    time = np.asarray(trajectory.time, dtype=float)
    if contacts is None:
        contacts = contacts_from_heights(heights, frame_period(trajectory), contact_params)
    window = last_window(time, params.gait_window_s)
    speeds = corner_speeds(corner_velocities)
    out = window_gait(time, contacts, heights, positions, pitches, speeds, base_xy, window, params)
    try:
        command = command_frames(read_script(trajectory), time)
    except PimannError:
        command = None
    following = (
        command_following(time, base_xy, yaw, command, window)
        if command is not None
        else dict.fromkeys(FOLLOWING)
    )
    out.update(following)
    out["heading_change"] = float(yaw[window[1] - 1] - yaw[window[0]])  # no command needed
    out["command_forward"] = None if command is None else commanded_forward(command, window)
    return {f"gait_{name}": value for name, value in out.items()}


FOLLOWING = (
    "command_speed",
    "travel",
    "speed",
    "speed_ratio",
    "heading_change",
    "heading_error_max_abs",
)


# ----------------------------------------------------------------------------- the data's level


def data_gait_windows(
    time: np.ndarray,
    classes: np.ndarray,
    heights: np.ndarray,
    positions: np.ndarray,
    pitches: np.ndarray,
    corner_velocities: np.ndarray,
    base_xy: np.ndarray,
    params: EvaluateParams,
    contact_params: ContactParams,
    window_s: float = DATA_WINDOW_S,
    hop: int = DATA_WINDOW_HOP,
    contacts: np.ndarray | None = None,
) -> list[dict[str, Any]]:
    """The gait of the windows of a clip's forward walking (module docstring), with each
    window's `speed` (net planar base displacement / duration).

    A window runs from a touchdown to the first touchdown at least `window_s` later, every frame
    forward; the next starts `hop` touchdowns after it. Both ends on touchdowns, the counted
    swings over the duration are the cadence with no rounding to whole steps.
    """
    if contacts is None:  # the rule's on `heights`, as `trajectory_gait`
        contacts = contacts_from_heights(heights, float(np.median(np.diff(time))), contact_params)
    speeds = corner_speeds(corner_velocities)
    landings = np.unique([on for _, _, on in swings(contacts)])
    rows = []
    for run_start, run_stop in true_runs(np.asarray(classes) == FORWARD):
        inside = landings[(landings >= run_start) & (landings < run_stop)]
        for i in range(0, len(inside), hop):
            later = np.flatnonzero(time[inside] >= time[inside[i]] + window_s - 1e-9)
            if len(later) == 0:
                break
            window = (int(inside[i]), int(inside[later[0]]) + 1)
            row = window_gait(
                time, contacts, heights, positions, pitches, speeds, base_xy, window, params
            )
            shift = base_xy[window[1] - 1] - base_xy[window[0]]
            row["speed"] = float(np.linalg.norm(shift) / row["window_s"])
            rows.append(row)
    return rows


def gait_level(
    windows: Sequence[dict[str, Any]], speed: float, band: float
) -> dict[str, dict[str, float | int | None]]:
    """{measure: {n, median, min, max}} over the windows within `band` of `speed` (m/s)."""
    near = [w for w in windows if abs(w["speed"] - speed) <= band + 1e-9]
    level: dict[str, dict[str, float | int | None]] = {}
    for name in MEASURES:
        values = np.array([w[name] for w in near if w.get(name) is not None], dtype=float)
        level[name] = {
            "n": len(values),
            "median": _median(values),
            "min": float(values.min()) if len(values) else None,
            "max": float(values.max()) if len(values) else None,
        }
    return level


def gait_reference(windows: Sequence[dict[str, Any]], params: EvaluateParams) -> dict[str, Any]:
    """The data's gait level for metrics_summary.json: the windows (speed and every measure)
    and the level at each of `SPEED_BINS`."""
    columns = ("speed", "window_s", "swings", *MEASURES)
    return {
        "window_s": DATA_WINDOW_S,
        "class": "forward",
        "speed_band": params.gait_speed_band,
        "windows": len(windows),
        "by_speed": {
            f"{speed:.1f}": gait_level(windows, speed, params.gait_speed_band)
            for speed in SPEED_BINS
        },
        "per_window": {c: [w.get(c) for w in windows] for c in columns},
    }


def windows_of(reference: dict[str, Any] | None) -> list[dict[str, Any]]:
    """The data's windows back from `gait_reference`'s record ([] where there is none)."""
    table = (reference or {}).get("per_window") or {}
    if not table:
        return []
    return [dict(zip(table, values, strict=True)) for values in zip(*table.values(), strict=True)]


def _finite(value: Any) -> float | None:
    """A finite float, or None (missing, None or NaN, as pandas gives them back)."""
    if value is None:
        return None
    value = float(value)
    return value if math.isfinite(value) else None


def within(value: Any, low: float, high: float) -> bool:
    """Whether a measure (None or NaN: not measured, so not inside) lies in [low, high]."""
    own = _finite(value)
    return own is not None and low - 1e-9 <= own <= high + 1e-9


def at_achieved_speed(
    row: dict[str, Any], windows: Sequence[dict[str, Any]], band: float
) -> dict[str, Any]:
    """The data's cadence and step length at the speed a rollout achieved (`gait_speed`, along
    its forward command): `data_gait_<measure>_at_speed_{median,low,high}` (median, min and max
    of the windows within `band`), `data_gait_windows_at_speed`, and `gait_in_data_range`:
    True where the rollout's cadence and step length both lie inside [low, high] (a rollout
    without a counted swing has no step length: False), None where it is not commanded forward,
    achieves under `STANDING_SPEED` along the command, or no window is near."""
    columns: dict[str, Any] = {
        f"data_gait_{name}_at_speed_{stat}": None
        for name in AT_SPEED
        for stat in ("median", "low", "high")
    }
    columns["data_gait_windows_at_speed"] = 0
    columns["gait_in_data_range"] = None
    speed = _finite(row.get("gait_speed"))
    if row.get("gait_command_forward") not in (True, 1) or speed is None:
        return columns
    if speed < STANDING_SPEED:
        return columns
    level = gait_level(windows, speed, band)
    columns["data_gait_windows_at_speed"] = level["cadence"]["n"]
    inside = []
    for name in AT_SPEED:
        median, low, high = (level[name][k] for k in ("median", "min", "max"))
        columns.update(
            {
                f"data_gait_{name}_at_speed_median": median,
                f"data_gait_{name}_at_speed_low": low,
                f"data_gait_{name}_at_speed_high": high,
            }
        )
        if low is None:
            return columns
        inside.append(within(row.get(f"gait_{name}"), low, high))
    columns["gait_in_data_range"] = all(inside)
    return columns


def data_gait_columns(
    rows: Sequence[dict[str, Any]], windows: Sequence[dict[str, Any]], band: float
) -> list[dict[str, Any]]:
    """Per metrics.csv row, the data's level at its commanded speed: `data_gait_<measure>`
    (median of the windows within `band`) and `data_gait_windows`; None where the command is
    not forward walking or no window is near. Then the data's level at its achieved speed and
    whether its gait lies inside it (`at_achieved_speed`)."""
    out = []
    for row in rows:
        speed, forward = row.get("gait_command_speed"), row.get("gait_command_forward")
        columns: dict[str, Any] = {f"data_gait_{name}": None for name in MEASURES}
        columns["data_gait_windows"] = 0
        if forward in (True, 1) and speed is not None and math.isfinite(float(speed)):
            level = gait_level(windows, float(speed), band)
            columns.update({f"data_gait_{n}": level[n]["median"] for n in MEASURES})
            columns["data_gait_windows"] = level["cadence"]["n"]
        columns.update(at_achieved_speed(row, windows, band))
        out.append(columns)
    return out


def with_data_gait(
    frame: pd.DataFrame, reference: dict[str, Any] | None, band: float
) -> pd.DataFrame:
    """metrics.csv's rows with the data's level at each commanded and achieved speed
    (`data_gait_columns`) from the data reference's `gait` record beside them."""
    windows = windows_of((reference or {}).get("gait"))
    columns = data_gait_columns(frame.to_dict("records"), windows, band)
    return pd.concat([frame, pd.DataFrame(columns, index=frame.index)], axis=1)
