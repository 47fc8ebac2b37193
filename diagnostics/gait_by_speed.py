"""The models' gait against the data's, speed by speed: does a model's step lengthen with its
speed as the data's does, and at which speeds do its steps lie inside the data's range?

    python -m diagnostics.gait_by_speed --model models/w10/0 [--model models/w0/1 ...]
        [--speeds 0.3 0.4 0.5 0.6 0.8 1.0] [--seconds 12]
        [--summary results/metrics_summary.json]

Per model, one batch: the authors' unsteered protocol (`rollout.protocols.authors`, its
unsteered rollout keys, the standing start) with its one forward command at each of --speeds
for --seconds (an ADHERENT model, meta variant `adherent`, through its own generator,
pimann.generate.adherent_rollout, as the rollout stage runs it). Each rollout is measured as
metrics.csv measures it (pimann.evaluate.metrics.trajectory_metrics, whose gait is
pimann.evaluate.gait.trajectory_gait: the last `evaluate.gait_window_s`): achieved speed along
the command, cadence (swings a second), step length, swing apex and glide share; beside it the
data's level at the speed it achieved (pimann.evaluate.gait.at_achieved_speed: median, min and
max of the retargeted data's forward-walking windows within `evaluate.gait_speed_band`, from
the evaluate stage's record `data_reference.gait` in --summary), whether its cadence and its
step length each lie inside the data's range there, and whether both do (`gait_in_data_range`,
metrics.csv's flag).

Then per model the trend: the least-squares slope of its step length on its achieved speed
(m per m/s) over its rollouts that walk (achieved speed at least `STANDING_SPEED`, a step
counted) against the data windows' slope over the same span of speeds (widened by the band),
its step length as a share of the data's median at its speed, and the commanded speeds whose
rollouts lie inside the data's range (step length; both measures).

With --seconds 10 and --speeds 0.4 a model's row is metrics.csv's `authors` unsteered row
(docs/gait_by_speed.md). Outside the pipeline: nothing imports this module.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import torch

from diagnostics.slow_start import _is_adherent
from pimann.core.errors import PimannError
from pimann.core.params import MotionSegment, Params, load_params
from pimann.core.paths import REPO_ROOT
from pimann.core.robot import Robot, load_robot
from pimann.core.rollout_files import SCRIPT_ATTR, script_json
from pimann.core.trajectory import Trajectory
from pimann.evaluate.gait import AT_SPEED, at_achieved_speed, gait_level, windows_of, within
from pimann.evaluate.metrics import trajectory_metrics
from pimann.generate.adherent_rollout import (
    LOOP_FIRST_INPUT,
    AdherentNetwork,
    AdherentRun,
    generate_adherent,
)
from pimann.generate.rollout_batch import RolloutSpec, generate_batch
from pimann.learn.adherent_train import load_adherent_model
from pimann.learn.model_files import load_model
from pimann.learn.motion_classes import STANDING_SPEED
from pimann.learn.standing import StandingPose

SPEEDS = (0.3, 0.4, 0.5, 0.6, 0.8, 1.0)  # m/s, the commanded forward speeds
SECONDS = 12.0  # s: the last evaluate.gait_window_s (8 s) after 4 s of start-up
PROTOCOL = "authors"  # the authors' test's rollout keys, unsteered
# the rollout's measures printed (metrics.csv's gait_<name>)
OWN = ("speed", "cadence", "step_length", "swing_apex", "glide_share")


def speed_script(speed: float, seconds: float) -> list[MotionSegment]:
    """The authors' test's script (one forward command from standing) at another speed."""
    return [MotionSegment(seconds, speed, 0.0, 0.0)]


def _attrs(speed: float, script: Sequence[MotionSegment]) -> dict[str, Any]:
    """A rollout's attrs as the rollout stage records them (the script: the gait's command)."""
    return {"scenario": f"forward {speed:g}", SCRIPT_ATTR: script_json(script)}


def roll_out(
    model_dir: Path, params: Params, speeds: Sequence[float], seconds: float, robot: Robot
) -> list[Trajectory]:
    """One rollout per commanded speed, in one batch: a MANN under the authors' unsteered
    protocol (pimann.generate.rollout_batch.generate_batch, the model's standing pose), an
    ADHERENT model through its own generator (the rollout stage's loop)."""
    scripts = [speed_script(v, seconds) for v in speeds]
    source = str(model_dir)
    if _is_adherent(model_dir):
        model, layout, stats, meta = load_adherent_model(model_dir)
        loop = params.rollout.adherent_past_velocity
        runs = [AdherentRun(s, source, _attrs(v, s)) for v, s in zip(speeds, scripts, strict=True)]
        return generate_adherent(
            AdherentNetwork(model, stats),
            layout,
            runs,
            robot,
            params.contacts,
            StandingPose.from_json(meta.get("standing")),
            loop,
            LOOP_FIRST_INPUT[loop],
        )
    model, layout, stats, meta = load_model(model_dir)
    specs = [
        RolloutSpec(s, False, source, _attrs(v, s)) for v, s in zip(speeds, scripts, strict=True)
    ]
    rollouts = generate_batch(
        model,
        layout,
        stats,
        specs,
        params.rollout.for_protocol(PROTOCOL, False),
        robot,
        contact_params=params.contacts,
        standing=StandingPose.from_json(meta.get("standing")),
    )
    return [rollout.trajectory for rollout in rollouts]


def gait_of(trajectory: Trajectory, params: Params, robot: Robot) -> dict[str, Any]:
    """The `gait_*` columns of the trajectory's metrics.csv row (the evaluate stage's
    `trajectory_metrics`, the retargeting robot as the stage loads it)."""
    metrics = trajectory_metrics(trajectory, robot, params.evaluate, params.contacts)
    return {key: value for key, value in metrics.items() if key.startswith("gait_")}


def _inside(value: Any, low: Any, high: Any) -> bool | None:
    """value in [low, high] as at_achieved_speed judges it; None where the data has no level."""
    if low is None or high is None:
        return None
    return within(value, low, high)


def judged(gait: dict[str, Any], windows: Sequence[dict[str, Any]], band: float) -> dict:
    """One printed row: the rollout's measures (OWN), the data's level at its achieved speed
    (median, low, high of cadence and step length; windows) and the inside flags: each measure
    alone (`<measure>_inside`) and both (`inside`, metrics.csv's `gait_in_data_range`)."""
    data = at_achieved_speed(gait, windows, band)
    row: dict[str, Any] = {name: gait.get(f"gait_{name}") for name in OWN}
    for name in AT_SPEED:
        low, high = (data[f"data_gait_{name}_at_speed_{s}"] for s in ("low", "high"))
        row[f"data_{name}"] = data[f"data_gait_{name}_at_speed_median"]
        row[f"data_{name}_low"], row[f"data_{name}_high"] = low, high
        row[f"{name}_inside"] = _inside(gait.get(f"gait_{name}"), low, high)
    row["windows"] = data["data_gait_windows_at_speed"]
    row["inside"] = data["gait_in_data_range"]
    return row


def gait_table(
    label: str,
    speeds: Sequence[float],
    gaits: Sequence[dict[str, Any]],
    windows: Sequence[dict[str, Any]],
    band: float,
) -> pd.DataFrame:
    """One row per commanded speed of one model (`judged`)."""
    rows = [
        {"model": label, "command": speed, **judged(gait, windows, band)}
        for speed, gait in zip(speeds, gaits, strict=True)
    ]
    return pd.DataFrame(rows)


def _slope(x: np.ndarray, y: np.ndarray) -> float:
    """Least-squares slope of y on x; NaN with under two distinct x."""
    keep = np.isfinite(x) & np.isfinite(y)
    x, y = x[keep], y[keep]
    if len(x) < 2 or np.ptp(x) == 0:
        return float("nan")
    return float(np.polyfit(x, y, 1)[0])


def walking(table: pd.DataFrame) -> pd.DataFrame:
    """The rows that walk: achieved speed at least STANDING_SPEED, a step length counted."""
    speed = pd.to_numeric(table["speed"], errors="coerce")
    step = pd.to_numeric(table["step_length"], errors="coerce")
    return table[(speed >= STANDING_SPEED) & step.notna()]


def trend(table: pd.DataFrame, windows: Sequence[dict[str, Any]], band: float) -> dict[str, Any]:
    """A model's step length against its speed and the data's (module docstring): slopes
    (m per m/s), the achieved span, the median step length / the data's median at the speed,
    and the commanded speeds inside the data's range (step length alone; both measures)."""
    walks = walking(table)
    speed = walks["speed"].to_numpy(float)
    out: dict[str, Any] = {"model": table["model"].iloc[0], "walking": len(walks)}
    out["speed_low"] = float(speed.min()) if len(speed) else float("nan")
    out["speed_high"] = float(speed.max()) if len(speed) else float("nan")
    out["step_slope"] = _slope(speed, walks["step_length"].to_numpy(float))
    data = [
        w
        for w in windows
        if out["speed_low"] - band - 1e-9 <= w["speed"] <= out["speed_high"] + band + 1e-9
        and w.get("step_length") is not None
    ]
    out["data_step_slope"] = _slope(
        np.array([w["speed"] for w in data], dtype=float),
        np.array([w["step_length"] for w in data], dtype=float),
    )
    ratio = walks["step_length"].to_numpy(float) / pd.to_numeric(
        walks["data_step_length"], errors="coerce"
    ).to_numpy(float)
    out["step_over_data"] = float(np.nanmedian(ratio)) if np.isfinite(ratio).any() else np.nan
    out["step_inside_at"] = _speeds(table, "step_length_inside")
    out["inside_at"] = _speeds(table, "inside")
    return out


def _speeds(table: pd.DataFrame, flag: str) -> str:
    """The commanded speeds whose flag is True, as 'a b c' ('-': none)."""
    chosen = [f"{v:g}" for v, f in zip(table["command"], table[flag], strict=True) if f is True]
    return " ".join(chosen) or "-"


def data_by_speed(
    windows: Sequence[dict[str, Any]], speeds: Sequence[float], band: float
) -> pd.DataFrame:
    """The data's cadence and step length (median, min, max) and windows at each speed."""
    rows = []
    for speed in speeds:
        level = gait_level(windows, speed, band)
        row: dict[str, Any] = {"speed": speed, "windows": level["cadence"]["n"]}
        for name in AT_SPEED:
            for stat in ("median", "min", "max"):
                row[f"{name}_{stat}"] = level[name][stat]
        rows.append(row)
    return pd.DataFrame(rows)


def read_windows(summary: Path) -> tuple[list[dict[str, Any]], float]:
    """The data's forward-walking windows and speed band the evaluate stage recorded."""
    try:
        record = json.loads(summary.read_text())["data_reference"]["gait"]
    except (OSError, ValueError, KeyError, TypeError) as error:
        raise PimannError(summary, f"no data_reference.gait ({error!r})") from None
    windows = windows_of(record)
    if not windows:
        raise PimannError(summary, "data_reference.gait records no window")
    return windows, float(record["speed_band"])


def model_label(model_dir: Path) -> str:
    """models/w10/0 -> w10/0."""
    return f"{model_dir.parent.name}/{model_dir.name}"


def _print(frame: pd.DataFrame, digits: int = 3) -> None:
    with pd.option_context("display.width", 250, "display.max_rows", 500):
        print(frame.round(digits).to_string(index=False))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--model", type=Path, action="append", default=[], help="a trained seed's folder"
    )
    parser.add_argument("--speeds", type=float, nargs="+", default=list(SPEEDS), help="m/s")
    parser.add_argument("--seconds", type=float, default=SECONDS)
    parser.add_argument(
        "--summary", type=Path, default=REPO_ROOT / "results" / "metrics_summary.json"
    )
    args = parser.parse_args(argv)
    params = load_params()
    torch.set_num_threads(1)
    try:
        window = params.evaluate.gait_window_s
        if args.seconds <= window:
            print(
                f"gait_by_speed: --seconds {args.seconds} does not leave a start-up before the "
                f"last {window} s measured",
                file=sys.stderr,
            )
        windows, band = read_windows(args.summary)
        print(f"the data's forward walking, {len(windows)} windows, within {band} m/s:")
        _print(data_by_speed(windows, args.speeds, band))
        robot = load_robot("retarget")  # the rollout and evaluate stages' robot
        tables = []
        for model_dir in args.model:
            trajectories = roll_out(model_dir, params, args.speeds, args.seconds, robot)
            gaits = [gait_of(t, params, robot) for t in trajectories]
            table = gait_table(model_label(model_dir), args.speeds, gaits, windows, band)
            print(f"\n{model_dir}: the authors' unsteered test, last {window} s")
            _print(table.drop(columns="model"))
            tables.append(table)
        if tables:
            print("\nstep length against speed (walking rollouts; data over the same span):")
            _print(pd.DataFrame([trend(t, windows, band) for t in tables]))
    except PimannError as error:
        print(f"gait_by_speed: {error}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
