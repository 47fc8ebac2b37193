"""The rollouts of the study (stage `rollout`): their file layout and the runner.

One file per run, simple to list and to rerun:

    results/rollouts/<model>/<seed>/<scenario>-<steering|nosteering>.h5
    results/rollouts/<model>/models.json      the trained models' meta (pi_weight, variant, ...)

`<model>` is the training output's folder name (`w10`, `baseline`); `baseline` is the
ADHERENT-style model (ground-projected features, no physics term). `<scenario>` is a named
scenario of `rollout.scenario_names` or, with `rollout.benchmark_clips`, `clip_<clip name>`: the
command-following benchmark's script of one test clip of the features stage's split
(`benchmark_scripts`, pimann.command_following.clip_commands). Every rollout records the script
it ran in its attrs["script"] (JSON, `script_json`; `read_script` reads it back).

The helpers at the end name the models of a table keyed like the layout (model, pi_weight,
seed, scenario, steering), as the evaluation's metrics.csv is.

This module sits beside the generator: the simulation, the CLI and the evaluation import the
layout from here; it imports nothing of the evaluation.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import re
import shutil
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pimann.atomic import atomic_path
from pimann.errors import PimannError
from pimann.parallel import pool_map
from pimann.params import MotionSegment, Params, StandSegment
from pimann.paths import REPO_ROOT

if TYPE_CHECKING:
    import pandas as pd

    from pimann.trajectory import Trajectory

log = logging.getLogger(__name__)

BASELINE = "baseline"
MODELS_FILE = "models.json"
STEERING_LABEL = {True: "steering", False: "nosteering"}
CLIP_PREFIX = "clip_"  # the benchmark scripts' scenario names: clip_<clip name>
SCRIPT_ATTR = "script"  # a rollout's attrs: the script it ran, as JSON

Segment = MotionSegment | StandSegment


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


# ----------------------------------------------------------------------------- scripts


def script_json(script: Sequence[Segment]) -> str:
    """A command script as JSON: [{duration, vx, vy, yaw_rate} | {duration, stand: true}]."""
    return json.dumps([dataclasses.asdict(segment) for segment in script])


def script_of_json(text: str, source: Any = None) -> list[Segment]:
    """The inverse of `script_json`."""
    try:
        items = json.loads(text)
        script: list[Segment] = [
            StandSegment(float(d["duration"]), True)
            if d.get("stand")
            else MotionSegment(
                float(d["duration"]), float(d["vx"]), float(d["vy"]), float(d["yaw_rate"])
            )
            for d in items
        ]
    except (ValueError, TypeError, KeyError, AttributeError) as error:
        raise PimannError(source, f"not a command script ({error!r})") from None
    if not script:
        raise PimannError(source, "the command script has no segments")
    return script


def read_script(trajectory: Trajectory, params: Params | None = None) -> list[Segment]:
    """The script a rollout ran (its attrs); for a file written before the attribute, the
    named scenario's of `params` (a PimannError where there is none)."""
    text = trajectory.attrs.get(SCRIPT_ATTR)
    if text is not None:
        return script_of_json(str(text), trajectory.source)
    scenario = trajectory.attrs.get("scenario")
    if params is not None and scenario in params.rollout.scenarios:
        return list(params.rollout.scenarios[scenario])
    raise PimannError(trajectory.source, "records no command script (attrs['script'])")


def is_clip(scenario: str) -> bool:
    """A benchmark script of a test clip, not a named scenario."""
    return scenario.startswith(CLIP_PREFIX)


def clip_scenario(clip: str) -> str:
    """The scenario name (a file stem) of a clip's benchmark script: clip_<clip name>."""
    return CLIP_PREFIX + re.sub(r"[^A-Za-z0-9_.-]", "_", clip)


def held_out_clips(collection: str | Path, params: Params) -> list[tuple[str, Trajectory]]:
    """(name, trajectory) of the clips of a retargeted collection on the test side of the
    features stage's split (by source clip, mirrors included), in name order."""
    from pimann.features import split_sources
    from pimann.trajectory import iter_collection

    sources = [t.source for _, t in iter_collection(collection)]  # a pass for the names only
    if len(set(sources)) < 2:
        raise PimannError(collection, "needs at least 2 source clips for the test split")
    test = split_sources(sources, params.features.test_fraction, params.features.split_seed)
    return [(name, t) for name, t in iter_collection(collection) if t.source in test]


def benchmark_scripts(params: Params) -> dict[str, list[Segment]]:
    """{clip_<clip name>: script} of the command-following benchmark: each test clip of the
    features stage's split (collection `features.input`) as the commands of its own base
    motion (pimann.command_following.clip_commands)."""
    from pimann.command_following import clip_commands

    scripts: dict[str, list[Segment]] = {}
    for name, trajectory in held_out_clips(REPO_ROOT / params.features.input, params):
        scenario = clip_scenario(name)
        if scenario in scripts:
            raise PimannError(params.features.input, f"two test clips are named {scenario!r}")
        scripts[scenario] = clip_commands(trajectory)
    return scripts


# ----------------------------------------------------------------------------- running


def model_seeds(models_dir: str | Path) -> dict[int, Path]:
    """{seed: folder} of the trained models in a training output (`<seed>/meta.json`)."""
    models_dir = Path(models_dir)
    seeds = {int(p.parent.name): p.parent for p in models_dir.glob("*/meta.json")}
    if not seeds:
        raise PimannError(models_dir, "holds no trained model (<seed>/meta.json)")
    return dict(sorted(seeds.items()))


def rollout_columns(
    root: str | Path, rollouts: Sequence[tuple[RolloutKey, Path]]
) -> list[dict[str, Any]]:
    """The key columns of each rollout (model, variant, pi_weight, seed, scenario, steering,
    rollout), with the seed's record from the rollout stage's models.json."""
    root = Path(root)
    seeds: dict[str, dict[str, Any]] = {}
    columns = []
    for key, path in rollouts:
        record_path = root / key.model / MODELS_FILE
        if key.model not in seeds:
            try:
                seeds[key.model] = json.loads(record_path.read_text())["seeds"]
            except FileNotFoundError:
                raise PimannError(
                    record_path, "missing: the rollout stage records the models here"
                ) from None
        seed = seeds[key.model].get(str(key.seed))
        if seed is None:
            raise PimannError(record_path, f"no record of seed {key.seed}")
        columns.append({
            "model": key.model, "variant": seed["variant"], "pi_weight": seed["pi_weight"],
            "seed": key.seed, "scenario": key.scenario, "steering": key.steering,
            "rollout": str(Path(path).relative_to(root)),
        })  # fmt: skip
    return columns


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


def _generate_seed(
    job: tuple[Path, list[tuple[str, list[Segment], bool, Path]], Params],
) -> str | None:
    """One seed's rollouts, generated together in batches (pimann.generate.generate_files);
    the error that stopped them (naming the file), or None."""
    import torch

    from pimann.generate import FileJob, generate_files

    torch.set_num_threads(1)  # one process per core
    model_dir, files, params = job
    jobs = [FileJob(*file) for file in files]
    try:
        generate_files(model_dir, jobs, params)
    except PimannError as error:
        return str(error)
    return None


def rollout_scripts(params: Params) -> dict[str, list[Segment]]:
    """{scenario: script} the rollout stage runs: the named scenarios of
    `rollout.scenario_names`, then (`rollout.benchmark_clips`) the test clips' scripts."""
    names = scenario_names(params.rollout)
    unknown = [name for name in names if name not in params.rollout.scenarios]
    if unknown:
        raise PimannError("params.yaml", f"rollout.scenario_names: unknown scenario {unknown[0]!r}")
    scripts = {name: list(params.rollout.scenarios[name]) for name in names}
    if params.rollout.benchmark_clips:
        clips = benchmark_scripts(params)
        clash = sorted(set(clips) & set(scripts))
        if clash:
            raise PimannError("params.yaml", f"scenario {clash[0]!r} is also a clip's script name")
        scripts.update(clips)
    return scripts


def run_rollouts(
    models_dir: str | Path, out_dir: str | Path, params: Params, workers: int = 2
) -> list[Path]:
    """Every seed of one training output x every script of `rollout_scripts` (the named
    scenarios and the benchmark clips), with and without steering.

    One job per seed (`workers` processes): its scripts x steering advance together as one
    batch (pimann.batch_generate). Written into `out_dir` (= results/rollouts/<model>) as a
    whole, atomically.
    """
    models_dir, out_dir = Path(models_dir), Path(out_dir)
    seeds = model_seeds(models_dir)
    scripts = rollout_scripts(params)
    record = {
        "profile": params.profile,
        "models_dir": models_dir.name,
        "seeds": models_record(models_dir),
    }
    with atomic_path(out_dir) as tmp:
        jobs = [
            (folder, [(sc, script, st, rollout_path(tmp.parent, RolloutKey(tmp.name, seed, sc, st)))
                      for sc, script in scripts.items() for st in (False, True)], params)
            for seed, folder in seeds.items()
        ]  # fmt: skip
        tmp.mkdir()
        for seed in seeds:
            (tmp / str(seed)).mkdir()
        failures = pool_map(_generate_seed, jobs, workers, f"rollouts {out_dir.name}", "seeds")
        record["failed"] = {
            str(seed): error for seed, error in zip(seeds, failures, strict=True) if error
        }
        for seed, error in record["failed"].items():  # recorded; the other seeds go on
            log.warning("rollouts of %s seed %s failed: %s", models_dir.name, seed, error)
            shutil.rmtree(tmp / seed)  # no half set of a seed's rollouts
        if len(record["failed"]) == len(seeds):
            raise PimannError(models_dir, f"every seed failed; first: {failures[0]}")
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
