"""The study's evaluation (SPEC 8): rollouts -> tidy metrics, seed statistics, figure data, claims.

Layout of the rollouts (stage `rollout`, one file per run, simple to list and to rerun):

    results/rollouts/<model>/<seed>/<scenario>-<steering|nosteering>.h5
    results/rollouts/<model>/models.json      the trained models' meta (pi_weight, variant, ...)

`<model>` is the training output's folder name (`w10`, `baseline`); `baseline` is the
ADHERENT-style model (ground-projected features, no physics term). Everything the figures need
is written by `write_results` under results/: metrics.csv (one row per rollout),
metrics_summary.json (median, IQR, min, max over the seeds), timeseries/*.csv and claims.md,
each with the profile and the params it came from.

Our support-foot RMSE uses LOCAL_WORLD_ALIGNED sole velocities (pimann.metrics) where the
authors' code used another representation, on other data: absolute values are not comparable
with the paper's, the relative claims (model against model) are.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from tqdm import tqdm

from pimann.atomic import atomic_path, write_text_atomic
from pimann.errors import PimannError
from pimann.metrics import aggregate
from pimann.parallel import pool_map
from pimann.params import FiguresParams, Params, as_dict

log = logging.getLogger(__name__)

BASELINE = "baseline"
MODELS_FILE = "models.json"
STEERING_LABEL = {True: "steering", False: "nosteering"}
KEY_COLUMNS = ["model", "variant", "pi_weight", "seed", "scenario", "steering"]
# the metrics summarised over seeds in metrics_summary.json (metrics.csv keeps every one)
SUMMARY_METRICS = [
    "support_rmse_linear_total",
    "support_rmse_angular_total",
    "support_rmse_linear_mean_per_contact_frame",
    "support_rmse_angular_mean_per_contact_frame",
    "contact_foot_speed_mean",
    "skating_ratio",
    "contact_sole_pitch_max_abs",
    "sole_pitch_max_abs",
    "drift_x",
    "drift_y",
    "drift_yaw",
    "drift_y_max_abs",
    "drift_yaw_max_abs",
    "walks",
]
BASE_COLUMNS = ["time", "base_x", "base_y", "base_z", "base_roll", "base_pitch", "base_yaw"]
FOOT_COLUMNS = ["time"] + [
    f"{side}_{name}"
    for name in ("foot_height", "sole_pitch", "contact")
    for side in ("left", "right")
]
# the three conditions of Figs. base_displacement_pid_ablation and ground_projection
DRIFT_CONDITIONS = ("baseline", "pi", "pi_steering")
PAPER_BASELINE_RMSE = {"linear": 22.88, "angular": 17.74}


# ----------------------------------------------------------------------------- rollout layout


@dataclasses.dataclass(frozen=True, order=True)
class RolloutKey:
    model: str
    seed: int
    scenario: str
    steering: bool


def rollout_path(root: str | Path, key: RolloutKey) -> Path:
    return (
        Path(root) / key.model / str(key.seed) / f"{key.scenario}-{STEERING_LABEL[key.steering]}.h5"
    )


def parse_rollout_path(root: str | Path, path: str | Path) -> RolloutKey:
    """The inverse of `rollout_path`; a file elsewhere is a PimannError."""
    parts = Path(path).relative_to(root).parts
    stem = Path(parts[-1]).stem if len(parts) == 3 else ""
    scenario, _, label = stem.rpartition("-")
    steering = {v: k for k, v in STEERING_LABEL.items()}.get(label)
    if steering is None or not scenario or not parts[1].isdigit():
        raise PimannError(path, "not <model>/<seed>/<scenario>-<steering|nosteering>.h5")
    return RolloutKey(parts[0], int(parts[1]), scenario, steering)


def find_rollouts(root: str | Path) -> list[tuple[RolloutKey, Path]]:
    root = Path(root)
    found = sorted((parse_rollout_path(root, p), p) for p in root.glob("*/*/*.h5"))
    if not found:
        raise PimannError(root, "holds no rollout (<model>/<seed>/<scenario>-<steering>.h5)")
    return found


def scenario_names(rollout_params: Any) -> list[str]:
    """The scenarios the rollout stage generates: `rollout.scenario_names` (else every one)."""
    names = getattr(rollout_params, "scenario_names", None)
    if names is not None:
        return list(names)
    scenarios = getattr(rollout_params, "scenarios", None)
    if scenarios is None:
        raise PimannError("params.yaml", "rollout.scenarios is missing")
    if isinstance(scenarios, dict):
        return list(scenarios)
    return [s if isinstance(s, str) else s.name for s in scenarios]


def model_seeds(models_dir: str | Path) -> dict[int, Path]:
    """{seed: folder} of the trained models in a training output (`<seed>/meta.json`)."""
    models_dir = Path(models_dir)
    seeds = {int(p.parent.name): p.parent for p in models_dir.glob("*/meta.json")}
    if not seeds:
        raise PimannError(models_dir, "holds no trained model (<seed>/meta.json)")
    return dict(sorted(seeds.items()))


def models_record(models_dir: str | Path) -> dict[str, Any]:
    """What the rollouts' provenance keeps of each seed's meta.json."""
    record: dict[str, Any] = {}
    for seed, folder in model_seeds(models_dir).items():
        meta = json.loads((folder / "meta.json").read_text())
        record[str(seed)] = {
            "pi_weight": float(meta["pi_weight"]),
            "variant": meta["variant"],
            "best_epoch": meta.get("best_epoch"),
            "best_test_loss": meta.get("best_test_loss"),
            "epochs": meta.get("epochs"),
            "train_samples": meta.get("train_samples"),
            "clips": len(meta.get("train_clips", [])) + len(meta.get("test_clips", [])),
        }
    return record


def _generate(job: tuple[Path, str, Path, bool, Params]) -> Path:
    import torch

    from pimann.generate import generate_file

    torch.set_num_threads(1)  # one process per core
    model_dir, scenario, output, steering, params = job
    generate_file(model_dir, scenario, output, steering, params)
    return output


def run_rollouts(
    models_dir: str | Path, out_dir: str | Path, params: Params, workers: int = 2
) -> list[Path]:
    """Every seed of one training output x every scenario, with and without steering.

    Written into `out_dir` (= results/rollouts/<model>) as a whole, atomically.
    """
    models_dir, out_dir = Path(models_dir), Path(out_dir)
    seeds = model_seeds(models_dir)
    scenarios = scenario_names(params.rollout)
    unknown = [name for name in scenarios if name not in params.rollout.scenarios]
    if unknown:
        raise PimannError("params.yaml", f"rollout.scenario_names: unknown scenario {unknown[0]!r}")
    record = {
        "profile": params.profile,
        "models_dir": models_dir.name,
        "seeds": models_record(models_dir),
    }
    with atomic_path(out_dir) as tmp:
        jobs = [
            (folder, sc, rollout_path(tmp.parent, RolloutKey(tmp.name, seed, sc, st)), st, params)
            for seed, folder in seeds.items()
            for sc in scenarios
            for st in (False, True)
        ]  # fmt: skip
        tmp.mkdir()
        for seed in seeds:
            (tmp / str(seed)).mkdir()
        pool_map(_generate, jobs, workers, f"rollouts {out_dir.name}")
        (tmp / MODELS_FILE).write_text(json.dumps(record, indent=2) + "\n")
    return sorted(out_dir.glob("*/*.h5"))


# ----------------------------------------------------------------------------- metrics


def _model_info(root: Path, model: str) -> dict[str, Any]:
    path = root / model / MODELS_FILE
    try:
        return json.loads(path.read_text())
    except FileNotFoundError:
        raise PimannError(path, "missing: the rollout stage records the models here") from None


_WORKER: dict[str, Any] = {}


def _metrics_job(job: tuple[Path, Any]) -> dict[str, Any]:
    from pimann.metrics import trajectory_metrics
    from pimann.robot import load_robot
    from pimann.trajectory import read_trajectory

    path, evaluate_params = job
    if "robot" not in _WORKER:
        _WORKER["robot"] = load_robot("retarget")
    return trajectory_metrics(read_trajectory(path), _WORKER["robot"], evaluate_params)


def collect_metrics(rollouts_dir: str | Path, params: Params, workers: int = 2) -> pd.DataFrame:
    """One row per rollout: the key columns, then every `trajectory_metrics` value."""
    root = Path(rollouts_dir)
    rollouts = find_rollouts(root)
    infos = {model: _model_info(root, model) for model in {key.model for key, _ in rollouts}}
    results = pool_map(
        _metrics_job, [(path, params.evaluate) for _, path in rollouts], workers, "metrics"
    )
    rows = []
    for (key, path), metrics in zip(rollouts, results, strict=True):
        seed_info = infos[key.model]["seeds"].get(str(key.seed))
        if seed_info is None:
            raise PimannError(root / key.model / MODELS_FILE, f"no record of seed {key.seed}")
        metrics = {k: v for k, v in metrics.items() if k != "source"}
        rows.append(
            {
                "model": key.model,
                "variant": seed_info["variant"],
                "pi_weight": seed_info["pi_weight"],
                "seed": key.seed,
                "scenario": key.scenario,
                "steering": key.steering,
                "rollout": str(path.relative_to(root)),
                **metrics,
            }
        )
    return sort_rows(pd.DataFrame(rows))


def sort_rows(frame: pd.DataFrame) -> pd.DataFrame:
    """Baseline first, then PI models by weight; seeds, scenarios, unsteered first."""
    order = frame.assign(_b=frame["model"] != BASELINE)
    order = order.sort_values(["_b", "pi_weight", "model", "seed", "scenario", "steering"])
    return order.drop(columns="_b").reset_index(drop=True)


def summarise(frame: pd.DataFrame, metrics: Sequence[str] = SUMMARY_METRICS) -> dict[str, Any]:
    """{scenario: {steering label: {model: {metric: median, q1, q3, iqr, min, max, ...}}}}."""
    summary: dict[str, Any] = {}
    columns = [m for m in metrics if m in frame]
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
    frame: pd.DataFrame, model: str, scenario: str, steering: bool,
    metric: str = "support_rmse_linear_total",
) -> int | None:  # fmt: skip
    """The seed whose `metric` is closest to the seeds' median (ties: the lowest seed)."""
    rows = _select(frame, scenario, steering, model=model).dropna(subset=[metric])
    if rows.empty:
        return None
    distance = (rows[metric] - rows[metric].median()).abs()
    return int(rows.assign(_d=distance).sort_values(["_d", "seed"])["seed"].iloc[0])


def _select(frame: pd.DataFrame, scenario: str, steering: bool, **where: Any) -> pd.DataFrame:
    mask = (frame["scenario"] == scenario) & (frame["steering"] == steering)
    for column, value in where.items():
        mask &= frame[column] == value
    return frame[mask]


def pi_models(frame: pd.DataFrame) -> dict[float, str]:
    """{pi_weight: model name} of the PI models (every model but the baseline)."""
    rows = frame[frame["model"] != BASELINE].drop_duplicates("model")
    return {float(w): str(m) for w, m in sorted(zip(rows["pi_weight"], rows["model"], strict=True))}


def weight_label(weight: float) -> str:
    return f"{weight:g}"


def timeseries_selection(frame: pd.DataFrame, figures: FiguresParams) -> dict[str, RolloutKey]:
    """{csv name: rollout} of the figures' time series: drift (3 conditions), feet per w."""
    scenario = figures.scenario
    models = pi_models(frame)
    chosen: dict[str, RolloutKey] = {}
    seed = representative_seed(frame, BASELINE, scenario, False)
    if seed is not None:
        chosen["base_baseline"] = RolloutKey(BASELINE, seed, scenario, False)
    focus = models.get(float(figures.pi_weight))
    seed = None if focus is None else representative_seed(frame, focus, scenario, False)
    if seed is not None:
        chosen["base_pi"] = RolloutKey(focus, seed, scenario, False)
        if not _select(frame, scenario, True, model=focus, seed=seed).empty:
            chosen["base_pi_steering"] = RolloutKey(focus, seed, scenario, True)
    for weight, model in models.items():
        seed = representative_seed(frame, model, scenario, figures.foot_steering)
        if seed is not None:
            key = RolloutKey(model, seed, scenario, figures.foot_steering)
            chosen[f"feet_w{weight_label(weight)}"] = key
    return chosen


def write_timeseries(
    rollouts_dir: str | Path, out_dir: str | Path, selection: dict[str, RolloutKey], params: Params
) -> None:
    """results/timeseries/<name>.csv for each selected rollout, only the columns figures use."""
    from pimann.metrics import trajectory_time_series
    from pimann.robot import load_robot
    from pimann.trajectory import read_trajectory

    robot = load_robot("retarget")
    with atomic_path(out_dir) as tmp:
        tmp.mkdir()
        for name, key in tqdm(selection.items(), desc="time series"):
            series = trajectory_time_series(
                read_trajectory(rollout_path(rollouts_dir, key)), robot, params.evaluate
            )
            columns = BASE_COLUMNS if name.startswith("base_") else FOOT_COLUMNS
            table = series[columns].copy()
            for column in columns:
                if table[column].dtype == bool:
                    table[column] = table[column].astype(int)
            table.to_csv(tmp / f"{name}.csv", index=False, float_format="%.6g")


# ----------------------------------------------------------------------------- claims

HOLDS, FAILS, NOT_COMPARABLE = "holds", "does not hold", "not comparable"


@dataclasses.dataclass
class Claim:
    id: str
    claim: str  # the paper's statement
    paper: str  # the paper's evidence (figure, numbers)
    figure: str  # our figure (paper_figures/<name>)
    ours: str = ""  # our numbers
    status: str = ""  # HOLDS | FAILS | NOT_COMPARABLE
    reason: str = ""


def _fmt(value: float | None) -> str:
    return "n/a" if value is None or not np.isfinite(value) else f"{value:.3g}"


class _Data:
    """Seed medians of one scenario, by model, for the claims."""

    def __init__(self, frame: pd.DataFrame, scenario: str):
        self.frame = frame[frame["scenario"] == scenario]
        self.scenario = scenario
        self.models = pi_models(frame)

    def values(self, model: str | None, steering: bool, metric: str) -> np.ndarray:
        if model is None or metric not in self.frame:
            return np.array([])
        rows = _select(self.frame, self.scenario, steering, model=model)
        return rows[metric].astype(float).dropna().to_numpy()

    def median(self, model: str | None, steering: bool, metric: str) -> float | None:
        values = self.values(model, steering, metric)
        return float(np.median(values)) if len(values) else None

    def model(self, weight: float) -> str | None:
        return self.models.get(float(weight))


def _missing(claim: Claim, what: str) -> Claim:
    return dataclasses.replace(
        claim, ours="n/a", status=NOT_COMPARABLE, reason=f"no rollouts for {what}"
    )


def evaluate_claims(frame: pd.DataFrame, figures: FiguresParams) -> list[Claim]:
    """Each claim of the paper's Sec. IV (SPEC 8) against our metrics (seed medians)."""
    if frame.empty or not (frame["scenario"] == figures.scenario).any():
        return [
            Claim("C0", "any", "-", "-", "n/a", NOT_COMPARABLE, f"no {figures.scenario} rollouts")
        ]
    data = _Data(frame, figures.scenario)
    return [
        _baseline_magnitude(data),
        *(_lower_than_baseline(data, figures, kind) for kind in ("linear", "angular")),
        _especially_angular(data, figures),
        _decreasing_up_to(data, figures),
        _compared_walk(data, figures),
        *(_large_weight_walks(data, figures, steering) for steering in (False, True)),
        _foot_pitch_grows(data, figures),
        *(_steering_removes(data, figures, axis) for axis in ("y", "yaw")),
        _pi_drifts_more(data, figures),
        _steered_beats_baseline(data, figures),
        _pi_reduces_foot_motion(data, figures),
    ]


RMSE_FIGURE = "pi_weight_comparison"


def _rmse(kind: str) -> str:
    return f"support_rmse_{kind}_total"


def _baseline_magnitude(data: _Data) -> Claim:
    claim = Claim(
        "C1", "Baseline support-foot sliding: total RMSE 22.88 (linear), 17.74 (angular)",
        "Sec. IV-A: 22.88 m/s, 17.74 rad/s", RMSE_FIGURE, "", NOT_COMPARABLE,
        "absolute sums depend on the sole-velocity representation (ours LOCAL_WORLD_ALIGNED, "
        "the authors' code inertial-fixed), the data set and the model; only relative claims "
        "compare",
    )  # fmt: skip
    linear = data.median(BASELINE, False, _rmse("linear"))
    angular = data.median(BASELINE, False, _rmse("angular"))
    if linear is None:
        return _missing(claim, "the baseline")
    return dataclasses.replace(claim, ours=f"{_fmt(linear)} (linear), {_fmt(angular)} (angular)")


def _weights_medians(data: _Data, weights: Iterable[float], steering: bool, metric: str):
    return {w: data.median(data.model(w), steering, metric) for w in weights}


def _list(medians: dict[float, float | None]) -> str:
    return ", ".join(f"w={weight_label(w)}: {_fmt(v)}" for w, v in medians.items())


def _lower_than_baseline(data: _Data, figures: FiguresParams, kind: str) -> Claim:
    weights = figures.box_weights
    claim = Claim(
        "C2" if kind == "linear" else "C3",
        f"PI models slide less than the baseline ({kind} total RMSE) for all w in "
        f"{{{', '.join(weight_label(w) for w in weights)}}}",
        f"Fig. pi_weight_comparison_plot ({kind})", RMSE_FIGURE,
    )  # fmt: skip
    baseline = data.median(BASELINE, False, _rmse(kind))
    medians = _weights_medians(data, weights, False, _rmse(kind))
    if baseline is None or any(v is None for v in medians.values()):
        return _missing(claim, "the baseline or a weight")
    higher = [weight_label(w) for w, v in medians.items() if v >= baseline]
    return dataclasses.replace(
        claim,
        ours=f"baseline {_fmt(baseline)}; {_list(medians)} (seed medians)",
        status=FAILS if higher else HOLDS,
        reason=f"w={', '.join(higher)} at or above the baseline"
        if higher
        else "every median below",
    )


def _reduction(data: _Data, weights: Sequence[float], kind: str) -> float | None:
    baseline = data.median(BASELINE, False, _rmse(kind))
    medians = list(_weights_medians(data, weights, False, _rmse(kind)).values())
    if baseline is None or not baseline or any(v is None for v in medians):
        return None
    return float(np.mean([1.0 - v / baseline for v in medians]))


def _especially_angular(data: _Data, figures: FiguresParams) -> Claim:
    claim = Claim(
        "C4", "The reduction is largest for the angular velocities",
        "Sec. IV-A, Fig. pi_weight_comparison_plot", RMSE_FIGURE,
    )  # fmt: skip
    linear = _reduction(data, figures.box_weights, "linear")
    angular = _reduction(data, figures.box_weights, "angular")
    if linear is None or angular is None:
        return _missing(claim, "the baseline or a weight")
    holds = angular > linear
    return dataclasses.replace(
        claim,
        ours=f"mean relative reduction vs baseline: linear {linear:.0%}, angular {angular:.0%}",
        status=HOLDS if holds else FAILS,
        reason="angular reduced more" if holds else "linear reduced at least as much",
    )


def _decreasing_up_to(data: _Data, figures: FiguresParams) -> Claim:
    weights = sorted(w for w in figures.box_weights if w <= figures.pi_weight)
    claim = Claim(
        "C5", f"Sliding decreases as w grows up to w={weight_label(figures.pi_weight)}",
        "Sec. IV-C2, Fig. pi_weight_comparison_plot", RMSE_FIGURE,
    )  # fmt: skip
    parts, failing = [], []
    for kind in ("linear", "angular"):
        medians = _weights_medians(data, weights, False, _rmse(kind))
        if any(v is None for v in medians.values()) or len(medians) < 2:
            return _missing(claim, f"w in {weights}")
        values = list(medians.values())
        parts.append(f"{kind}: {_list(medians)}")
        if not all(b < a for a, b in zip(values, values[1:], strict=False)):
            failing.append(kind)
    return dataclasses.replace(
        claim,
        ours="; ".join(parts),
        status=FAILS if failing else HOLDS,
        reason=f"{' and '.join(failing)} medians not strictly decreasing"
        if failing
        else "both medians strictly decrease",
    )


def _walk_fraction(data: _Data, weight: float, steering: bool) -> float | None:
    values = data.values(data.model(weight), steering, "walks")
    return float(np.mean(values)) if len(values) else None


def _compared_walk(data: _Data, figures: FiguresParams) -> Claim:
    weights = figures.box_weights
    claim = Claim(
        "C6", "Models with w in the comparison walk without steering (implied)",
        "Sec. IV-C2 (only w=100 is said not to walk)", "base_displacement",
    )  # fmt: skip
    fractions = {w: _walk_fraction(data, w, False) for w in weights}
    if any(v is None for v in fractions.values()):
        return _missing(claim, "a weight")
    short = [weight_label(w) for w, v in fractions.items() if v < 1.0]
    return dataclasses.replace(
        claim,
        ours="walking seeds: "
        + ", ".join(f"w={weight_label(w)}: {v:.0%}" for w, v in fractions.items()),
        status=FAILS if short else HOLDS,
        reason=f"some seeds of w={', '.join(short)} travel less than the walk distance"
        if short
        else "every seed walks",
    )


def _large_weight_walks(data: _Data, figures: FiguresParams, steering: bool) -> Claim:
    w = weight_label(figures.large_weight)
    claim = Claim(
        "C8" if steering else "C7",
        f"w={w} models {'walk with' if steering else 'cannot walk without'} steering",
        "Sec. IV-C2", "base_displacement",
    )  # fmt: skip
    fraction = _walk_fraction(data, figures.large_weight, steering)
    if fraction is None:
        return _missing(claim, f"w={w}")
    holds = fraction == 1.0 if steering else fraction == 0.0
    return dataclasses.replace(
        claim,
        ours=f"{fraction:.0%} of seeds walk (forward travel >= walk_distance)",
        status=HOLDS if holds else FAILS,
        reason="as claimed"
        if holds
        else ("not every seed walks" if steering else "some seeds walk"),
    )


def _foot_pitch_grows(data: _Data, figures: FiguresParams) -> Claim:
    claim = Claim(
        "C9", "Foot pitch in contact grows with w (heel-only stance at large w)",
        "Sec. IV-C2, Fig. foot_rotations", "foot_rotations",
    )  # fmt: skip
    weights = sorted(data.models)
    medians = _weights_medians(data, weights, figures.foot_steering, "contact_sole_pitch_max_abs")
    medians = {w: v for w, v in medians.items() if v is not None}
    if len(medians) < 3:
        return _missing(claim, "three weights or more")
    from scipy.stats import spearmanr

    values = list(medians.values())
    rho = float(spearmanr(list(medians), values).statistic)
    holds = rho >= 0.8 and values[-1] > values[0]
    return dataclasses.replace(
        claim,
        ours=f"median max |contact sole pitch| (rad): {_list(medians)}; Spearman rho {rho:.2f}",
        status=HOLDS if holds else FAILS,
        reason="grows with w (rho >= 0.8, largest w above w=0)"
        if holds
        else "no monotone growth (needs rho >= 0.8 and the largest w above the smallest)",
    )


def _steering_removes(data: _Data, figures: FiguresParams, axis: str) -> Claim:
    metric = f"drift_{axis}_max_abs"
    model = data.model(figures.pi_weight)
    claim = Claim(
        "C10" if axis == "y" else "C11",
        f"Steering removes the {'lateral (y)' if axis == 'y' else 'yaw'} drift of the PI model",
        "Sec. IV-A, IV-C1, Figs. base_displacement_pid_ablation, ground_projection",
        "base_displacement",
    )  # fmt: skip
    free, steered = data.median(model, False, metric), data.median(model, True, metric)
    if free is None or steered is None:
        return _missing(claim, f"w={weight_label(figures.pi_weight)} with and without steering")
    holds = steered <= figures.drift_reduction * free
    unit = "m" if axis == "y" else "rad"
    return dataclasses.replace(
        claim,
        ours=f"w={weight_label(figures.pi_weight)} median max |{axis}| ({unit}): "
        f"{_fmt(free)} without, {_fmt(steered)} with steering",
        status=HOLDS if holds else FAILS,
        reason=f"steered median {'at most' if holds else 'above'} "
        f"{figures.drift_reduction:g} x the unsteered one",
    )


def _versus_baseline(data: _Data, figures: FiguresParams, steering: bool):
    model = data.model(figures.pi_weight)
    out = {}
    for axis in ("y", "yaw"):
        metric = f"drift_{axis}_max_abs"
        out[axis] = (data.median(BASELINE, False, metric), data.median(model, steering, metric))
    return out


def _drift_text(pairs: dict, label: str) -> str:
    return "; ".join(
        f"max |{a}|: baseline {_fmt(b)}, {label} {_fmt(p)}" for a, (b, p) in pairs.items()
    )


def _pi_drifts_more(data: _Data, figures: FiguresParams) -> Claim:
    claim = Claim(
        "C12", "Without steering the PI model drifts more than the baseline",
        "Sec. IV-A, Fig. base_displacement_pid_ablation (a) vs (b)", "base_displacement",
    )  # fmt: skip
    pairs = _versus_baseline(data, figures, False)
    if any(None in pair for pair in pairs.values()):
        return _missing(claim, "the baseline or the PI model")
    less = [a for a, (b, p) in pairs.items() if p <= b]
    return dataclasses.replace(
        claim,
        ours=_drift_text(pairs, f"w={weight_label(figures.pi_weight)}"),
        status=FAILS if less else HOLDS,
        reason=f"{', '.join(less)} drift not larger" if less else "y and yaw drift larger",
    )


def _steered_beats_baseline(data: _Data, figures: FiguresParams) -> Claim:
    claim = Claim(
        "C13", "With steering the PI model deviates less from the walking direction than the "
        "baseline", "Sec. IV-A, Fig. base_displacement_pid_ablation (a) vs (c)",
        "base_displacement",
    )  # fmt: skip
    pairs = _versus_baseline(data, figures, True)
    if any(None in pair for pair in pairs.values()):
        return _missing(claim, "the baseline or the steered PI model")
    more = [a for a, (b, p) in pairs.items() if p >= b]
    return dataclasses.replace(
        claim,
        ours=_drift_text(pairs, f"w={weight_label(figures.pi_weight)} steered"),
        status=FAILS if more else HOLDS,
        reason=f"{', '.join(more)} deviation not smaller" if more else "y and yaw smaller",
    )


def _pi_reduces_foot_motion(data: _Data, figures: FiguresParams) -> Claim:
    low, high = sorted(figures.foot_height_weights)[:1] + sorted(figures.foot_height_weights)[-1:]
    claim = Claim(
        "C14", f"The PI loss (w={weight_label(high)}) reduces support-foot motion against "
        f"w={weight_label(low)}",
        "Sec. IV-C2, Fig. pi_ablation_foot_z_plot", "foot_heights",
    )  # fmt: skip
    steering = figures.foot_steering
    speed = [data.median(data.model(w), steering, "contact_foot_speed_mean") for w in (low, high)]
    skate = [data.median(data.model(w), steering, "skating_ratio") for w in (low, high)]
    if None in speed:
        return _missing(claim, f"w={weight_label(low)} and w={weight_label(high)}")
    holds = speed[1] < speed[0]
    return dataclasses.replace(
        claim,
        ours=f"median contact-foot speed (m/s): {_fmt(speed[0])} vs {_fmt(speed[1])}; "
        f"skating ratio {_fmt(skate[0])} vs {_fmt(skate[1])}",
        status=HOLDS if holds else FAILS,
        reason="contact feet move slower" if holds else "contact feet do not move slower",
    )


def claims_markdown(claims: Sequence[Claim], provenance: dict[str, Any]) -> str:
    """claims.md: a provenance header, then one table row per claim."""
    head = [
        "<!-- generated by `dvc repro evaluate` (pimann.evaluate); do not edit -->",
        f"<!-- provenance: {json.dumps(_header_provenance(provenance), sort_keys=True)} -->",
        "",
        "# The paper's claims on our data",
        "",
        f"Profile **{provenance.get('profile')}**, {provenance.get('epochs')} epochs, "
        f"{provenance.get('clips')} clips, seeds {provenance.get('seeds')}, "
        f"scenario `{provenance.get('scenario')}`. Numbers are medians over the seeds.",
        "Our support-foot RMSE uses LOCAL_WORLD_ALIGNED sole velocities; the authors' code used "
        "an inertial-fixed representation, so absolute values are not comparable, the relative "
        "claims are.",
        "",
        "| id | claim (paper) | paper | ours | our figure | status | why |",
        "|---|---|---|---|---|---|---|",
    ]
    rows = [
        f"| {c.id} | {c.claim} | {c.paper} | {c.ours} | "
        f"{'paper_figures/' + c.figure + '.pdf' if c.figure != '-' else '-'} | **{c.status}** | "
        f"{c.reason} |"
        for c in claims
    ]
    return "\n".join(head + [r.replace("\n", " ") for r in rows]) + "\n"


def _header_provenance(provenance: dict[str, Any]) -> dict[str, Any]:
    return {k: provenance.get(k) for k in ("profile", "epochs", "clips", "max_takes", "seeds")}


# ----------------------------------------------------------------------------- provenance, all


def provenance(params: Params, rollouts_dir: str | Path | None = None) -> dict[str, Any]:
    """Profile and params of the results, with what the trained models recorded."""
    models: dict[str, Any] = {}
    if rollouts_dir is not None:
        for path in sorted(Path(rollouts_dir).glob(f"*/{MODELS_FILE}")):
            models[path.parent.name] = json.loads(path.read_text())["seeds"]
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
        "scenario": params.figures.scenario,
        "params": {
            name: as_dict(getattr(params, name)) for name in ("rollout", "evaluate", "figures")
        },
        "models": models,
    }


def write_results(
    frame: pd.DataFrame,
    results_dir: str | Path,
    params: Params,
    info: dict[str, Any],
    timeseries: dict[str, RolloutKey] | None = None,
) -> list[Claim]:
    """metrics.csv, metrics_summary.json and claims.md under `results_dir` (atomic each)."""
    results_dir = Path(results_dir)
    tidy = frame.assign(profile=info.get("profile"), epochs=info.get("epochs"))
    with atomic_path(results_dir / "metrics.csv") as tmp:
        tidy.to_csv(tmp, index=False, float_format="%.6g")
    summary = {
        "provenance": info,
        "timeseries": {name: dataclasses.asdict(key) for name, key in (timeseries or {}).items()},
        "summary": summarise(frame),
    }
    write_text_atomic(
        results_dir / "metrics_summary.json", json.dumps(summary, indent=2, allow_nan=False) + "\n"
    )
    claims = evaluate_claims(frame, params.figures)
    write_text_atomic(results_dir / "claims.md", claims_markdown(claims, info))
    return claims


def read_metrics(path: str | Path) -> pd.DataFrame:
    """metrics.csv back into a frame."""
    path = Path(path)
    if not path.is_file():
        raise PimannError(path, "file not found (run `dvc repro evaluate`)")
    frame = pd.read_csv(path)
    missing = [c for c in KEY_COLUMNS if c not in frame]
    if missing:
        raise PimannError(path, f"lacks column {missing[0]!r}")
    frame["steering"] = frame["steering"].astype(str).str.lower() == "true"
    return frame


def evaluate_all(
    rollouts_dir: str | Path, results_dir: str | Path, params: Params, workers: int = 2
) -> list[Claim]:
    """The whole evaluate stage: metrics, summary, time series, claims."""
    frame = collect_metrics(rollouts_dir, params, workers)
    selection = timeseries_selection(frame, params.figures)
    write_timeseries(rollouts_dir, Path(results_dir) / "timeseries", selection, params)
    return write_results(frame, results_dir, params, provenance(params, rollouts_dir), selection)
