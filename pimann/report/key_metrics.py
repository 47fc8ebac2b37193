"""The study's key numbers as one flat JSON file, results/metrics.json: the pipeline's only
DVC metrics, so that `dvc metrics show` and `dvc metrics diff` read a few dozen numbers.

Built from results/ alone (the report stage, after evaluate and simulate): metrics.csv, the
claims' statuses the evaluate stage recorded in metrics_summary.json (as in claims.md),
command_following.csv and sim_summary.json. Everything else (params, provenance, seed
statistics) stays in metrics_summary.json and sim_summary.json, plain outputs. Keys are flat
and stable from run to run (a value that cannot be had is null):

- `claims.holding`, `claims.total`, `claim.<id>`: each claim's status as a number
  (`STATUS_CODES`: 1 holds, 0.5 within seed spread, 0.25 holds only with a model standing
  still, 0 does not hold, -1 not comparable);
- `<scenario>.<model>.<metric>`: medians over the seeds, unsteered, on evaluate.scenario (the
  authors' forward-walking test): sliding by the authors' metric (support-foot total RMSE,
  linear and angular), ours beside (`HEADLINE`), and the share of seeds that walk; and the
  base drift (max |y|, max |yaw|) of the baseline and the featured PI model
  (evaluate.pi_weight), unsteered and steered;
- `<scenario>.<model>.gait_*` (`GAIT`): the gait's medians over the seeds, unsteered (speed
  over the commanded one, cadence, step length, glide share; pimann.evaluate.gait), and
  `gait_in_data_range` (`GAIT_SHARES`): the share of the seeds whose cadence and step length lie
  inside the data's range at the speed they achieved (of those where it can be judged);
- `data.sliding_*`: the retargeted data's own level of each sliding measure; `data.gait_*`
  (`DATA_GAIT`): the data's gait at the scenario's commanded speed;
- `following.<model>.<steering>`: the share of motion classes whose every criterion passes
  (pimann.evaluate.command_following_measures), on the held-out split, and `following.data` for
  the test clips themselves;
- `sim.runs`, `sim.success_share`, `sim.fallen`: the MuJoCo runs.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pimann.core.params import Params
from pimann.core.rollout_files import (
    ADHERENT,
    BASELINE,
    HELD_OUT,
    STEERING_LABEL,
    paper_baseline,
    pi_models,
    select_rows,
    weight_label,
)
from pimann.evaluate.claims import (
    FAILS,
    HOLDS,
    NOT_COMPARABLE,
    STANDS_STILL,
    WITHIN_SPREAD,
)

METRICS_FILE = "metrics.json"
MAX_VALUES = 150  # `dvc metrics show` stays readable
DIGITS = 4  # significant digits: a seed's spread is far wider than the fifth
STATUS_CODES = {
    HOLDS: 1.0,
    WITHIN_SPREAD: 0.5,
    STANDS_STILL: 0.25,
    FAILS: 0.0,
    NOT_COMPARABLE: -1.0,
}
HEADLINE = {  # key: metrics.csv column, medians per model on the scenario, unsteered
    "sliding_linear": "support_rmse_paper_linear_total",  # the authors' metric
    "sliding_angular": "support_rmse_paper_angular_total",
    # ours beside it: the lowest-corner rule without the lag, the position level, the
    # contact point (pimann.evaluate.metrics)
    "sliding_lowest_corner": "support_rmse_linear_total",
    "sliding_position": "support_rmse_linear_position_total",
    "sliding_contact_point": "support_rmse_contact_point_total",
    "walks": "walks",
}
SLIDING_KEYS = [key for key in HEADLINE if key.startswith("sliding_")]
SHARES = {"walks"}  # headline keys that are the share of the seeds, not their median
# the gait (pimann.evaluate.gait) per model, medians over the seeds, unsteered, on the scenario;
# `data.<key>` the data's level at the scenario's commanded speed (its `data_gait_*` columns)
GAIT = {
    "gait_speed_ratio": "gait_speed_ratio",
    "gait_cadence": "gait_cadence",
    "gait_step_length": "gait_step_length",
    "gait_glide_share": "gait_glide_share",
}
# the share of the seeds (where defined) per model, unsteered, on the scenario
GAIT_SHARES = {"gait_in_data_range": "gait_in_data_range"}
DATA_GAIT = {
    "gait_cadence": "data_gait_cadence",
    "gait_step_length": "data_gait_step_length",
    "gait_glide_share": "data_gait_glide_share",
}
DRIFT = {"drift_y": "drift_y_max_abs", "drift_yaw": "drift_yaw_max_abs"}

Number = float | int | None


def _number(value: Any) -> Number:
    """A finite float to `DIGITS` significant digits, or None (JSON null) for NaN,
    infinities and missing values."""
    if value is None or value is pd.NA:
        return None
    value = float(value)
    return float(f"{value:.{DIGITS}g}") if math.isfinite(value) else None


def _median(rows: pd.DataFrame, column: str) -> Number:
    if column not in rows:
        return None
    values = pd.to_numeric(rows[column], errors="coerce").dropna()
    return _number(values.median()) if len(values) else None


def _share(rows: pd.DataFrame, column: str) -> Number:
    """The mean of a boolean column over the rows where it is defined (None: none is)."""
    if column not in rows:
        return None
    values = rows[column].map({True: 1.0, False: 0.0, "True": 1.0, "False": 0.0}).dropna()
    return _number(values.mean()) if len(values) else None


def claim_metrics(statuses: dict[str, str]) -> dict[str, Number]:
    """`claims.holding`, `claims.total` and each claim's status code, from {id: status}."""
    out: dict[str, Number] = {
        "claims.holding": sum(status == HOLDS for status in statuses.values()),
        "claims.total": len(statuses),
    }
    for claim_id, status in statuses.items():
        out[f"claim.{claim_id}"] = STATUS_CODES.get(status)
    return out


def rollout_metrics(frame: pd.DataFrame, params: Params) -> dict[str, Number]:
    """Medians per model of the headline metrics on evaluate.scenario, and the drifts."""
    scenario = params.evaluate.scenario
    adherent = [ADHERENT] if len(frame) and paper_baseline(frame) == ADHERENT else []
    models = [*adherent, BASELINE, *pi_models(frame).values()] if len(frame) else []
    out: dict[str, Number] = {}
    for model in models:
        rows = select_rows(frame, scenario, False, model=model)
        for key, column in {**HEADLINE, **GAIT}.items():
            summary = _share if key in SHARES else _median
            out[f"{scenario}.{model}.{key}"] = summary(rows, column)
        for key, column in GAIT_SHARES.items():
            out[f"{scenario}.{model}.{key}"] = _share(rows, column)
    unsteered = select_rows(frame, scenario, False) if len(frame) else frame
    for key, column in DATA_GAIT.items():
        out[f"data.{key}"] = _median(unsteered, column)
    featured = pi_models(frame).get(float(params.evaluate.pi_weight)) if len(frame) else None
    label = f"w{weight_label(params.evaluate.pi_weight)}"
    for model, name in ((BASELINE, BASELINE), (featured, label)):
        for steering in (False, True):
            rows = select_rows(frame, scenario, steering, model=model) if model else frame[:0]
            for key, column in DRIFT.items():
                out[f"{scenario}.{name}.{STEERING_LABEL[steering]}.{key}"] = _median(rows, column)
    return out


def data_metrics(summary: dict[str, Any]) -> dict[str, Number]:
    """The retargeted data's own sliding level (metrics_summary.json's data_reference)."""
    subset = (summary.get("data_reference") or {}).get("all") or {}
    metrics = subset.get("metrics") or {}
    return {
        f"data.{key}": _number((metrics.get(HEADLINE[key]) or {}).get("median"))
        for key in SLIDING_KEYS
    }


def following_metrics(rows: pd.DataFrame | None) -> dict[str, Number]:
    """The share of motion classes passing every criterion, per model and steering."""
    if rows is None or rows.empty:
        return {}
    from pimann.evaluate.command_following_benchmark import DATA_MODEL
    from pimann.evaluate.command_following_measures import summarise_following

    if "split" in rows:  # the held-out split: the benchmark's meaning
        rows = rows[rows["split"] == HELD_OUT]
    summary = summarise_following(rows)
    out: dict[str, Number] = {}
    for (model, steering), group in summary.groupby(["model", "steering"], sort=False):
        passes = group["passes"].dropna().astype(bool)
        share = _number(passes.mean()) if len(passes) else None
        name = DATA_MODEL if model == DATA_MODEL else f"{model}.{STEERING_LABEL[bool(steering)]}"
        out[f"following.{name}"] = share
    return out


def sim_metrics(sim_summary: dict[str, Any] | None) -> dict[str, Number]:
    """How many MuJoCo runs there were, the share that succeeded, how many fell."""
    if not sim_summary:
        return {}
    runs = list((sim_summary.get("runs") or {}).values())
    success = [bool(r.get("success")) for r in runs]
    return {
        "sim.runs": len(runs),
        "sim.success_share": _number(np.mean(success)) if runs else None,
        "sim.fallen": sum(bool(r.get("fallen")) for r in runs),
    }


def key_metrics(results_dir: str | Path, params: Params) -> dict[str, Number]:
    """Every key number of module docstring from the files under `results_dir` (the parts
    whose file is missing are left out)."""
    from pimann.evaluate.evaluation_results import read_metrics

    root = Path(results_dir)
    frame = read_metrics(root / "metrics.csv")
    summary = _read_json(root / "metrics_summary.json") or {}
    following = root / "command_following.csv"
    rows = pd.read_csv(following) if following.is_file() else None
    return {
        "epochs": _number((summary.get("provenance") or {}).get("epochs")),
        **claim_metrics(summary.get("claims") or {}),
        **rollout_metrics(frame, params),
        **data_metrics(summary),
        **following_metrics(rows),
        **sim_metrics(_read_json(root / "sim_summary.json")),
    }


def _read_json(path: Path) -> dict[str, Any] | None:
    return json.loads(path.read_text()) if path.is_file() else None


def write_key_metrics(metrics: dict[str, Number], path: str | Path) -> Path:
    """metrics.json, atomically; refuses nesting and more than `MAX_VALUES` values."""
    from pimann.core.atomic import write_text_atomic
    from pimann.core.errors import PimannError

    nested = [k for k, v in metrics.items() if isinstance(v, dict | list)]
    if nested or len(metrics) > MAX_VALUES:
        raise PimannError(path, f"key metrics must be flat and at most {MAX_VALUES} values")
    write_text_atomic(Path(path), json.dumps(metrics, indent=1, allow_nan=False) + "\n")
    return Path(path)
