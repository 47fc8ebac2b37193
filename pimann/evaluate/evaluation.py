"""The study's evaluation (Sec. IV): rollouts -> tidy metrics, seed statistics, figure data, claims.

Reads the rollouts (layout: pimann.core.rollout_files) and writes under results/
(`write_results`):
metrics.csv (one row per rollout: every pimann.evaluate.metrics value, the gait among them, and
the data's gait at its commanded and achieved speeds, pimann.evaluate.gait),
metrics_summary.json (median, IQR, min, max over the seeds; the data's own level of the sliding
metrics under "data_reference", pimann.evaluate.data_reference), timeseries/*.csv and claims.md
(pimann.evaluate.claims), each with the profile and the params it came from; and the
command-following benchmark (pimann.evaluate.command_following_benchmark):
command_following.csv, .md and .png.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pimann.core.atomic import atomic_path, write_text_atomic
from pimann.core.parallel import pool_map
from pimann.core.params import EvaluateParams, Params, as_dict
from pimann.core.paths import REPO_ROOT
from pimann.core.progress import track
from pimann.core.rollout_files import (
    ADHERENT,
    BASELINE,
    MODELS_FILE,
    STEERING_LABEL,
    RolloutKey,
    find_rollouts,
    is_clip,
    paper_baseline,
    pi_models,
    rollout_columns,
    rollout_path,
    select_rows,
    weight_label,
)
from pimann.evaluate.claims import (
    Claim,
    claims_markdown,
    evaluate_claims,
)
from pimann.evaluate.consistency_measures import with_consistency_columns
from pimann.evaluate.gait import GAIT_SUMMARY, with_data_gait
from pimann.evaluate.metrics import aggregate

log = logging.getLogger(__name__)

# the metrics summarised over seeds in metrics_summary.json (metrics.csv keeps every one)
SUMMARY_METRICS = [
    "support_rmse_paper_linear_total",
    "support_rmse_paper_angular_total",
    "support_rmse_contact_point_total",
    "support_rmse_linear_total",
    "support_rmse_angular_total",
    "support_rmse_linear_world_total",
    "support_rmse_linear_position_total",
    "support_rmse_angular_position_total",
    "support_rmse_linear_position_world_total",
    "support_rmse_linear_mean_per_contact_frame",
    "support_rmse_angular_mean_per_contact_frame",
    "contact_foot_speed_mean",
    "contact_foot_speed_mean_position",
    "skating_ratio",
    "contact_sole_pitch_max_abs",
    "sole_pitch_max_abs",
    "drift_x",
    "drift_y",
    "drift_yaw",
    "drift_y_max_abs",
    "drift_yaw_max_abs",
    "walks",
    *GAIT_SUMMARY,
    # what a contact-consistent variant changes (pimann.evaluate.consistency_measures)
    "penetration_max_m",
    "joint_distance_rms_rad",
    "joint_distance_max_rad",
    "leg_joint_speed_max_rad_s",
    "consistent_residual_max_m",
]
BASE_COLUMNS = ["time", "base_x", "base_y", "base_z", "base_roll", "base_pitch", "base_yaw"]
FOOT_COLUMNS = ["time"] + [
    f"{side}_{name}"
    for name in ("foot_height", "sole_pitch", "contact")
    for side in ("left", "right")
]
# the three conditions of Figs. base_displacement_pid_ablation and ground_projection
DRIFT_CONDITIONS = ("baseline", "pi", "pi_steering")


# ----------------------------------------------------------------------------- metrics


def _metrics_job(job: tuple[Path, Any]) -> dict[str, Any]:
    from pimann.core.robot import load_robot
    from pimann.core.trajectory import read_trajectory
    from pimann.evaluate.metrics import trajectory_metrics

    path, evaluate_params, contact_params = job
    robot = load_robot("retarget")
    return trajectory_metrics(read_trajectory(path), robot, evaluate_params, contact_params)


def collect_metrics(rollouts_dir: str | Path, params: Params, workers: int = 2) -> pd.DataFrame:
    """One row per rollout, the contact-consistent variants (`<scenario>+post|loop`) beside the
    raw ones: the key columns, then every `trajectory_metrics` value (the ADHERENT baseline's
    with `train.adherent` only), then pimann.evaluate.consistency_measures' columns."""
    root = Path(rollouts_dir)
    rollouts = find_rollouts(root, variants=True)  # the contact-consistent ones beside
    if not params.train.adherent:  # not measured: the yaw-only variant is the baseline
        rollouts = [(key, path) for key, path in rollouts if key.model != ADHERENT]
    results = pool_map(
        _metrics_job,
        [(path, params.evaluate, params.contacts) for _, path in rollouts],
        workers,
        "metrics",
    )
    rows = [
        {**columns, **{k: v for k, v in metrics.items() if k != "source"}}
        for columns, metrics in zip(rollout_columns(root, rollouts), results, strict=True)
    ]
    keys = [key for key, _ in rollouts]
    return sort_rows(with_consistency_columns(pd.DataFrame(rows), root, keys, workers))


def sort_rows(frame: pd.DataFrame) -> pd.DataFrame:
    """The baselines first (ADHERENT, then the yaw-only variant), then PI models by weight;
    seeds, scenarios, unsteered first."""
    order = frame.assign(_b=frame["model"].map({ADHERENT: 0, BASELINE: 1}).fillna(2))
    order = order.sort_values(["_b", "pi_weight", "model", "seed", "scenario", "steering"])
    return order.drop(columns="_b").reset_index(drop=True)


def summarise(frame: pd.DataFrame, metrics: Sequence[str] = SUMMARY_METRICS) -> dict[str, Any]:
    """{scenario: {steering label: {model: {metric: median, q1, q3, iqr, min, max, ...}}}} of
    the named scenarios (the benchmark clips' rollouts stay in metrics.csv)."""
    summary: dict[str, Any] = {}
    columns = [m for m in metrics if m in frame]
    frame = frame[~frame["scenario"].map(is_clip)]
    for (scenario, steering, model), group in frame.groupby(
        ["scenario", "steering", "model"], sort=False
    ):
        runs = [{m: _plain(v) for m, v in row.items()} for row in group[columns].to_dict("records")]
        by_model = summary.setdefault(scenario, {}).setdefault(STEERING_LABEL[bool(steering)], {})
        by_model[model] = {
            "pi_weight": float(group["pi_weight"].iloc[0]),
            "variant": str(group["variant"].iloc[0]),
            "seeds": [int(s) for s in group["seed"]],
            "metrics": aggregate(runs),
        }
    return summary


def _plain(value: Any) -> Any:
    """numpy scalars / NaN from pandas back to JSON-friendly Python values."""
    if isinstance(value, np.bool_ | bool):
        return bool(value)
    if isinstance(value, np.integer | np.floating | int | float):
        return None if not math.isfinite(float(value)) else float(value)
    return value


# ----------------------------------------------------------------------------- time series


def representative_seed(
    frame: pd.DataFrame,
    model: str,
    scenario: str,
    steering: bool,
    metric: str = "support_rmse_paper_linear_total",
) -> int | None:
    """The seed whose `metric` is closest to the seeds' median (ties: the lowest seed)."""
    rows = select_rows(frame, scenario, steering, model=model).dropna(subset=[metric])
    if rows.empty:
        return None
    distance = (rows[metric] - rows[metric].median()).abs()
    return int(rows.assign(_d=distance).sort_values(["_d", "seed"])["seed"].iloc[0])


def timeseries_selection(frame: pd.DataFrame, evaluate: EvaluateParams) -> dict[str, RolloutKey]:
    """{csv name: rollout} of the figures' time series: drift (3 conditions), feet per w."""
    scenario = evaluate.scenario
    models = pi_models(frame)
    chosen: dict[str, RolloutKey] = {}
    baseline = paper_baseline(frame)
    seed = representative_seed(frame, baseline, scenario, False)
    if seed is not None:
        chosen["base_baseline"] = RolloutKey(baseline, seed, scenario, False)
    focus = models.get(float(evaluate.pi_weight))
    seed = None if focus is None else representative_seed(frame, focus, scenario, False)
    if seed is not None:
        chosen["base_pi"] = RolloutKey(focus, seed, scenario, False)
        if not select_rows(frame, scenario, True, model=focus, seed=seed).empty:
            chosen["base_pi_steering"] = RolloutKey(focus, seed, scenario, True)
    for weight, model in models.items():
        seed = representative_seed(frame, model, scenario, evaluate.foot_steering)
        if seed is not None:
            key = RolloutKey(model, seed, scenario, evaluate.foot_steering)
            chosen[f"feet_w{weight_label(weight)}"] = key
    return chosen


def write_timeseries(
    rollouts_dir: str | Path, out_dir: str | Path, selection: dict[str, RolloutKey], params: Params
) -> None:
    """results/timeseries/<name>.csv for each selected rollout, only the columns figures use."""
    from pimann.core.robot import load_robot
    from pimann.core.trajectory import read_trajectory
    from pimann.evaluate.metrics import trajectory_time_series

    robot = load_robot("retarget")
    with atomic_path(out_dir) as tmp:
        tmp.mkdir()
        for name, key in track(selection.items(), "time series", "series", logger=log):
            series = trajectory_time_series(
                read_trajectory(rollout_path(rollouts_dir, key)),
                robot,
                params.evaluate,
                params.contacts,
            )
            columns = BASE_COLUMNS if name.startswith("base_") else FOOT_COLUMNS
            table = series[columns].copy()
            for column in columns:
                if table[column].dtype == bool:
                    table[column] = table[column].astype(int)
            table.to_csv(tmp / f"{name}.csv", index=False, float_format="%.6g")


# ----------------------------------------------------------------------------- provenance, all


def provenance(params: Params, rollouts_dir: str | Path | None = None) -> dict[str, Any]:
    """Profile and params of the results, with what the trained models recorded."""
    models: dict[str, Any] = {}
    failed: dict[str, Any] = {}  # {model: {seed: error}} of the rollout stage's failures
    if rollouts_dir is not None:
        for path in sorted(Path(rollouts_dir).glob(f"*/{MODELS_FILE}")):
            record = json.loads(path.read_text())
            models[path.parent.name] = record["seeds"]
            if record.get("failed"):
                failed[path.parent.name] = record["failed"]
    seeds = sorted({int(s) for record in models.values() for s in record})
    seeds_meta = [m for record in models.values() for m in record.values()]
    epochs = sorted({m.get("epochs") for m in seeds_meta if m.get("epochs") is not None})
    clips = sorted({m.get("clips") for m in seeds_meta if m.get("clips") is not None})
    return {
        "profile": params.profile,
        "epochs": epochs[0] if len(epochs) == 1 else (epochs or params.train.epochs),
        "clips": clips[0] if len(clips) == 1 else (clips or None),
        "max_takes": {name: source.max_takes for name, source in params.data.sources.items()},
        "seeds": seeds or list(params.train.seeds),  # those rolled out, else the params'
        "pi_weights": list(params.train.pi_weights),
        "scenario": params.evaluate.scenario,
        "params": {
            name: as_dict(getattr(params, name))
            for name in ("rollout", "contacts", "evaluate", "figures")
        },
        "models": models,
        "rollout_failures": failed,
    }


def write_results(
    frame: pd.DataFrame,
    results_dir: str | Path,
    params: Params,
    info: dict[str, Any],
    timeseries: dict[str, RolloutKey] | None = None,
    data_reference: dict[str, Any] | None = None,
) -> list[Claim]:
    """metrics.csv, metrics_summary.json and claims.md under `results_dir` (atomic each).

    `data_reference`: the data's own level (pimann.evaluate.data_reference), into the summary and
    the claims table when given.
    """
    results_dir = Path(results_dir)
    tidy = frame.assign(profile=info.get("profile"), epochs=info.get("epochs"))
    with atomic_path(results_dir / "metrics.csv") as tmp:
        tidy.to_csv(tmp, index=False, float_format="%.6g")
    claims = evaluate_claims(frame, params.evaluate, params.train.pi_gradient)
    summary = {
        "provenance": info,
        "timeseries": {name: dataclasses.asdict(key) for name, key in (timeseries or {}).items()},
        "summary": summarise(frame),
        "claims": {claim.id: claim.status for claim in claims},  # the key metrics read these
        **({"data_reference": data_reference} if data_reference else {}),
    }
    write_text_atomic(
        results_dir / "metrics_summary.json", json.dumps(summary, indent=2, allow_nan=False) + "\n"
    )
    markdown = claims_markdown(claims, info, data_reference)
    write_text_atomic(results_dir / "claims.md", markdown)
    return claims


def evaluate_all(
    rollouts_dir: str | Path,
    results_dir: str | Path,
    params: Params,
    workers: int = 2,
    data: str | Path | None = None,
) -> list[Claim]:
    """The whole evaluate stage: metrics, summary, time series, the data's level, claims, and
    command following (pimann.evaluate.command_following_benchmark, with the test clips' own level).

    `data`: the retargeted collection the models learn from (default: features.input).
    """
    from pimann.evaluate.command_following_benchmark import collect_following, write_following
    from pimann.evaluate.data_reference import data_reference

    frame = collect_metrics(rollouts_dir, params, workers)
    selection = timeseries_selection(frame, params.evaluate)
    write_timeseries(rollouts_dir, Path(results_dir) / "timeseries", selection, params)
    name = params.features.input if data is None else data
    reference = data_reference(REPO_ROOT / name, params, workers, str(name))
    frame = with_data_gait(frame, reference, params.evaluate.gait_speed_band)  # beside each row
    info = provenance(params, rollouts_dir)
    claims = write_results(frame, results_dir, params, info, selection, reference)
    following = collect_following(rollouts_dir, params, workers, REPO_ROOT / name)
    write_following(following, results_dir, params, info)
    return claims
