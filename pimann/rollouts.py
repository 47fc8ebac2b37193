"""The rollouts of the study (stage `rollout`): their file layout and the runner.

One file per run, simple to list and to rerun:

    results/rollouts/<model>/<seed>/<scenario>-<steering|nosteering>.h5
    results/rollouts/<model>/models.json      the trained models' meta (pi_weight, variant, ...)

`<model>` is the training output's folder name (`w10`, `baseline`); `baseline` is the
ADHERENT-style model (ground-projected features, no physics term). The helpers at the end name
the models of a table keyed like the layout (model, pi_weight, seed, scenario, steering), as
the evaluation's metrics.csv is.

This module sits beside the generator: the simulation, the CLI and the evaluation import the
layout from here; it imports nothing of the evaluation.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pimann.atomic import atomic_path
from pimann.errors import PimannError
from pimann.parallel import pool_map
from pimann.params import Params

if TYPE_CHECKING:
    import pandas as pd

BASELINE = "baseline"
MODELS_FILE = "models.json"
STEERING_LABEL = {True: "steering", False: "nosteering"}


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


# ----------------------------------------------------------------------------- a table's models


def select_rows(frame: pd.DataFrame, scenario: str, steering: bool, **where: Any) -> pd.DataFrame:
    """The rows of one scenario and steering condition (and `column=value` of `where`)."""
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
