"""The command-following benchmark in the evaluate stage: rollouts -> results/
command_following.csv, command_following.md and command_following.png.

Every rollout (layout: pimann.core.rollout_files) is measured against the script it ran (its
attrs["script"]) by pimann.evaluate.command_following_measures.follow_measures, one row per script
segment, keyed by model, variant, pi_weight, seed, scenario, steering, `kind`: `scenario` (a named
scenario of rollout.scenarios) or `clip` (the benchmark script of a test clip, `clip_<clip name>`,
or of a training clip, `train_<clip name>`) and `split` (pimann.core.rollout_files.scenario_split:
`training` for a training clip's script, `held_out` for the rest, whose commands no training clip
gave). The data's own level: each benchmark clip (pimann.generate.benchmark_clips) measured against
its own script (model `data`, no steering, seed 0). Beside the segment's measures each row carries
its rollout's final base displacement and the script's, in the start heading frame (`rollout_dx_m`,
`rollout_dy_m`, `script_dx_m`, `script_dy_m`).

command_following.md: `summarise_following`'s table (medians over seeds per model, split,
steering and class; on the held-out split named scenarios and test-clip scripts both count;
a class failing on both splits is a motion the model cannot make, on the held-out one alone a
take it does not generalise to), then a short table of the named scenarios
per model and steering.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from matplotlib.figure import Figure
from scipy.spatial.transform import Rotation

from pimann.core.atomic import atomic_path, write_text_atomic
from pimann.core.parallel import pool_map
from pimann.core.params import Params, StandSegment
from pimann.core.robot import load_robot
from pimann.core.rollout_files import (
    BASELINE,
    HELD_OUT,
    STEERING_LABEL,
    TRAINING,
    find_rollouts,
    is_clip,
    read_script,
    rollout_columns,
    scenario_split,
)
from pimann.core.rotations import from_heading_frame, to_heading_frame, yaw_of
from pimann.evaluate import command_following_measures as cf
from pimann.generate.benchmark_clips import benchmark_clips
from pimann.generate.command_script import clip_commands, scenario_steps

log = logging.getLogger(__name__)

DATA_MODEL = "data"  # the data's own rows
KEY_COLUMNS = ["model", "variant", "pi_weight", "seed", "scenario", "steering", "kind", "split"]
NAME = "command_following"


def script_displacement(script: Sequence[cf.Segment], rate_hz: float) -> np.ndarray:
    """(2,) the base displacement a script commands, forward and left of the start heading,
    integrated step by step as the generator's frames run (stands: no motion)."""
    steps = scenario_steps(script, rate_hz)
    dt = 1.0 / rate_hz
    commands = np.array(
        [
            [0.0, 0.0, 0.0] if isinstance(s, StandSegment) else [s.vx, s.vy, s.yaw_rate]
            for s in script
        ]
    )[steps]
    yaw = np.concatenate([[0.0], np.cumsum(commands[:, 2] * dt)])
    mid = (yaw[:-1] + yaw[1:]) / 2
    world = from_heading_frame(commands[:, :2], mid)
    return np.array([np.sum(world[:, 0]), np.sum(world[:, 1])]) * dt


def _rollout_displacement(trajectory) -> np.ndarray:
    """(2,) the base's final displacement, forward and left of its heading at frame 0."""
    xy = np.asarray(trajectory.base_position, dtype=float)[:, :2]
    yaw = yaw_of(Rotation.from_quat(trajectory.base_quaternion_xyzw[0]).as_matrix())
    d = xy[-1] - xy[0]
    return to_heading_frame(d, yaw)


def measure(trajectory, script: Sequence[cf.Segment], params: Params) -> list[dict[str, Any]]:
    """`follow_measures` rows of one trajectory, with its and the script's displacement."""
    rows = cf.follow_measures(
        trajectory, script, load_robot("retarget"), params.evaluate, params.contacts
    )
    achieved = _rollout_displacement(trajectory)
    commanded = script_displacement(script, float(trajectory.rate_hz))
    extra = {
        "rollout_dx_m": float(achieved[0]),
        "rollout_dy_m": float(achieved[1]),
        "script_dx_m": float(commanded[0]),
        "script_dy_m": float(commanded[1]),
    }
    return [{**row, **extra} for row in rows]


def _rollout_job(job: tuple[Path, Params]) -> list[dict[str, Any]]:
    from pimann.core.trajectory import read_trajectory

    path, params = job
    trajectory = read_trajectory(path)
    return measure(trajectory, read_script(trajectory, params), params)


def _data_job(job: tuple[Any, Params]) -> list[dict[str, Any]]:
    trajectory, params = job
    return measure(trajectory, clip_commands(trajectory), params)


def collect_following(
    rollouts_dir: str | Path, params: Params, workers: int = 2, data: str | Path | None = None
) -> pd.DataFrame:
    """Every segment row of every rollout, and (`data`: a retargeted collection) the data's
    own rows: its benchmark clips (test and training) against their own scripts."""

    root = Path(rollouts_dir)
    rollouts = find_rollouts(root)
    jobs = [(path, params) for _, path in rollouts]
    results = pool_map(_rollout_job, jobs, workers, "command following")
    rows = []
    for (key, _), columns, measures in zip(
        rollouts, rollout_columns(root, rollouts), results, strict=True
    ):
        rollout = columns.pop("rollout")  # "kind" before it, as the data rows have it
        kind = "clip" if is_clip(key.scenario) else "scenario"
        columns.update(kind=kind, split=scenario_split(key.scenario), rollout=rollout)
        rows += [{**columns, **row} for row in measures]
    if data is not None:
        clips = benchmark_clips(data, params)
        jobs = [(clip.trajectory, params) for clip in clips]
        results = pool_map(_data_job, jobs, workers, "data following")
        for clip, measures in zip(clips, results, strict=True):
            keys = {
                "model": DATA_MODEL,
                "variant": DATA_MODEL,
                "pi_weight": math.nan,
                "seed": 0,
                "scenario": clip.scenario,
                "steering": False,
                "kind": "clip",
                "split": clip.split,
                "rollout": f"{Path(data).name}:{clip.name}",
            }
            rows += [{**keys, **row} for row in measures]
    frame = pd.DataFrame(rows)
    order = frame["model"].map(lambda m: 0 if m == DATA_MODEL else 1 if m == BASELINE else 2)
    frame = frame.assign(_o=order).sort_values(
        ["_o", "pi_weight", "model", "seed", "kind", "scenario", "steering", "segment"],
        kind="stable",
    )
    return frame.drop(columns="_o").reset_index(drop=True)


# ----------------------------------------------------------------------------- tables


def _number(value: Any, digits: int = 2) -> str:
    if value is None or value is pd.NA or (isinstance(value, float) and not math.isfinite(value)):
        return "–"
    text = f"{float(value):.{digits}f}"
    return text[1:] if text.startswith("-") and not text.strip("-0.") else text  # no -0.00


def _mark(value: Any) -> str:
    if value is None or value is pd.NA:
        return "–"
    return "✓" if bool(value) else "✗"


def _model_label(row: pd.Series) -> str:
    if row["model"] in (DATA_MODEL, BASELINE):
        return str(row["model"])
    weight = row.get("pi_weight")
    return f"{row['model']} (w={weight:g})" if pd.notna(weight) else str(row["model"])


def _table(header: list[str], lines: list[list[str]]) -> list[str]:
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    return out + ["| " + " | ".join(line) + " |" for line in lines]


def _level_key(row: pd.Series) -> tuple:
    return (row["split"], row["class"]) if "split" in row else (row["class"],)


def _sliding(row: pd.Series, data: dict[tuple, pd.Series]) -> str:
    """Both levels of the linear sliding, the data's own levels of the split's class in
    brackets."""
    columns = ("sliding_linear", "sliding_linear_position")
    levels = [_number(row[c], 1) for c in columns]
    level = data.get(_level_key(row))
    own = [_number(None if level is None else level.get(c), 1) for c in columns]
    return f"{' / '.join(levels)} ({' / '.join(own)})"


def summary_table(summary: pd.DataFrame) -> list[str]:
    """`summarise_following`'s rows as markdown, the sliding beside the data's own level."""
    data = {_level_key(r): r for _, r in summary[summary["model"] == DATA_MODEL].iterrows()}
    split = ["split"] if "split" in summary else []
    header = [
        "model",
        *split,
        "steering",
        "class",
        "seeds",
        "segments",
        "cmd speed",
        "speed ratio",
        "heading err (°)",
        "alternation",
        "sliding lin: velocity / position level (data)",
        "stand travel ratio",
        "roll / pitch / foot pitch drift (°)",
        "speed",
        "heading",
        "stand",
        "alternation",
        "drift",
        "passes",
    ]
    lines = []
    for _, row in summary.iterrows():
        in_place = row["class"] == "turning_in_place"
        ratio = row["yaw_rate_ratio"] if in_place else row["speed_ratio"]
        drifts = " / ".join(
            _number(row[c], 1)
            for c in ("roll_drift_deg", "pitch_drift_deg", "foot_pitch_drift_deg")
        )
        lines.append(
            [
                _model_label(row),
                *(str(row[c]) for c in split),
                STEERING_LABEL[bool(row["steering"])],
                row["class"],
                str(int(row["seeds"])),
                str(int(row["segments"])),
                _number(row["commanded_speed"]),
                _number(ratio) + (" (yaw rate)" if in_place else ""),
                _number(row["heading_error_deg"], 1),
                _number(row["alternation_share"]),
                _sliding(row, data),
                _number(row["base_travel_ratio"]),
                drifts,
                *(_mark(row[c]) for c in (*cf.CRITERIA, "passes")),
            ]
        )
    return _table(header, lines)


def scenario_summary(rows: pd.DataFrame) -> pd.DataFrame:
    """The named scenarios per model, steering and scenario: medians over seeds of the final
    displacement (achieved, commanded), the mean speed ratio of the motion segments, the
    touchdowns per foot, and the share of seeds whose every stand held."""
    named = rows[rows["kind"] == "scenario"]
    if named.empty:
        return pd.DataFrame()
    keys = ["model", "pi_weight", "steering", "scenario", "seed"]
    held = named["base_travel_m"] < named["base_travel_limit_m"]
    per_seed = (
        named.assign(_held=held.where(named["stand"]))
        .groupby(keys, sort=False, dropna=False)
        .agg(
            dx=("rollout_dx_m", "first"),
            dy=("rollout_dy_m", "first"),
            cmd_dx=("script_dx_m", "first"),
            cmd_dy=("script_dy_m", "first"),
            speed_ratio=("speed_ratio", "mean"),
            touchdowns_left=("touchdowns_left", "sum"),
            touchdowns_right=("touchdowns_right", "sum"),
            stands=("stand", "sum"),
            stands_held=("_held", "sum"),
        )
    )
    per_seed["stand_held"] = (per_seed["stands_held"] == per_seed["stands"]).where(
        per_seed["stands"] > 0
    )
    per_seed = per_seed.drop(columns=["stands", "stands_held"]).astype(float)
    level = keys[:-1]
    out = per_seed.groupby(level=level, sort=False, dropna=False).median()
    out["stand_held"] = per_seed["stand_held"].groupby(level=level, sort=False, dropna=False).mean()
    out.insert(0, "seeds", per_seed.groupby(level=level, sort=False, dropna=False).size())
    return out.reset_index()


def scenario_table(table: pd.DataFrame) -> list[str]:
    header = [
        "model",
        "steering",
        "scenario",
        "seeds",
        "displacement fwd / left (m)",
        "commanded (m)",
        "speed ratio",
        "touchdowns L / R",
        "stand held",
    ]
    lines = []
    for _, row in table.iterrows():
        held = row["stand_held"]
        lines.append(
            [
                _model_label(row),
                STEERING_LABEL[bool(row["steering"])],
                row["scenario"],
                str(int(row["seeds"])),
                f"{_number(row['dx'])} / {_number(row['dy'])}",
                f"{_number(row['cmd_dx'])} / {_number(row['cmd_dy'])}",
                _number(row["speed_ratio"]),
                f"{_number(row['touchdowns_left'], 0)} / {_number(row['touchdowns_right'], 0)}",
                "–" if pd.isna(held) else f"{held:.0%} of seeds",
            ]
        )
    return _table(header, lines)


def following_markdown(rows: pd.DataFrame, summary: pd.DataFrame, info: dict[str, Any]) -> str:
    clips = rows.loc[rows["kind"] == "clip"]
    held = sorted(set(clips.loc[clips["split"] == HELD_OUT, "scenario"]))
    trained = sorted(set(clips.loc[clips["split"] == TRAINING, "scenario"]))
    named = sorted(set(rows.loc[rows["kind"] == "scenario", "scenario"]))
    seeds = info.get("seeds")
    text = [
        "<!-- generated by `dvc repro evaluate` "
        "(pimann.evaluate.command_following_benchmark); do not edit -->",
        "",
        "# Command following",
        "",
        f"Profile **{info.get('profile')}**, {info.get('epochs')} epochs, seeds {seeds}: "
        f"named scenarios: {', '.join(named) or 'none'}; {len(held)} test-clip scripts (the "
        f"features stage's split, mirrors included) and {len(trained)} training-clip scripts "
        "(a few per motion class, no mirrors). Each segment is measured after "
        "its settling time (pimann.evaluate.command_following_measures). Numbers are medians "
        "over the seeds of "
        "each seed's segments of the class and split: `held_out` the named scenarios and the "
        "test clips together, `training` the training clips. A class failing on both splits "
        "is a motion the model cannot make; on `held_out` alone, takes (styles) it does not "
        "generalise to. The `data` rows are the clips themselves against their own scripts: "
        "the data's level.",
        "",
        "Criteria, on those medians:",
        f"- speed: the achieved speed along the command within ±{cf.SPEED_TOLERANCE:.0%} of the "
        "commanded (turning in place: the yaw rate);",
        f"- heading: the largest heading error over the segment below {cf.HEADING_LIMIT_DEG:g}°;",
        f"- stand: the base moves less than {cf.STAND_TRAVEL_M * 100:g} cm per "
        f"{cf.STAND_TRAVEL_S:g} s after the settling time (stand travel ratio < 1);",
        f"- alternation: the feet alternate (touchdowns per foot differ by at most one; a motion "
        f"steps, each foot in a segment of two {cf.STRIDE_S:g} s strides or more) in at least "
        f"{cf.ALTERNATION_SHARE:.0%} of the segments;",
        f"- drift: base roll, base pitch and the contact feet's pitch drift less than "
        f"{cf.DRIFT_LIMIT_DEG:g}° (last {cf.DRIFT_WINDOW_S:g} s against the first).",
        "",
        "Sliding: the support feet's linear RMSE per frame x 500 (the paper's 10 s test), at "
        "our lowest-corner velocity level (the predicted joint velocities move the feet, the "
        "base holds the lower one still) and the position level (the poses alone: what a "
        "robot would track); the data's levels of the class in brackets (its joint velocities: "
        "the joints' differences).",
        "",
        *summary_table(summary),
        "",
        "## Named scenarios",
        "",
        "Final base displacement forward and left of the start heading, against the script's; "
        "speed ratio: the mean over the motion segments; stand held: the share of seeds whose "
        "every stand held.",
        "",
        *scenario_table(scenario_summary(rows)),
        "",
    ]
    return "\n".join(text)


def write_following(
    rows: pd.DataFrame, results_dir: str | Path, params: Params, info: dict[str, Any]
) -> pd.DataFrame:
    """command_following.csv (every row), .md and .png under `results_dir`; the summary."""
    import matplotlib

    from pimann.evaluate.command_following_figure import fig_command_following
    from pimann.evaluate.figure_style import save_figure, style

    results_dir = Path(results_dir)
    with atomic_path(results_dir / f"{NAME}.csv") as tmp:
        rows.assign(profile=info.get("profile")).to_csv(tmp, index=False, float_format="%.6g")
    summary = cf.summarise_following(rows)
    write_text_atomic(results_dir / f"{NAME}.md", following_markdown(rows, summary, info))
    with matplotlib.rc_context(style(params.figures)):
        fig = fig_command_following(summary, params.figures)
        if fig is None:  # the output still exists, saying why it is empty
            log.info("command following: no motion segments to plot")
            fig = Figure(figsize=(params.figures.width_in, 1.0))
            fig.text(0.5, 0.5, "no motion segments to plot", ha="center", va="center")
        save_figure(fig, results_dir, NAME, info, formats=("png",))
    return summary
