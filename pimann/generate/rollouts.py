"""The rollout stage's runner: every seed of a training output x every command script, with
and without steering, generated in batches and written in the layout of
pimann.core.rollout_files.

Beside the scripts, each of the authors' test protocols (`rollout.protocols`) under its own
name, with and without steering, each way with the rollout keys it sets.

Beside the raw rollouts of the scenarios of `rollout.consistent.scenarios`, their
contact-consistent variants (docs/consistent.md): `<scenario>+loop` generated with the hold
inside the loop, `<scenario>+post` each raw one post-processed (ADHERENT's too, through
`write_seed_rollouts`).

The scripts are the named scenarios of `rollout.scenario_names` and, with
`rollout.benchmark_clips`, the command-following benchmark's script of each test clip of the
features stage's split (pimann.generate.benchmark_clips), with `rollout.benchmark_train_clips` also
of a few training clips per motion class.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

from pimann.core.atomic import atomic_path
from pimann.core.errors import PimannError
from pimann.core.parallel import pool_map
from pimann.core.params import Params
from pimann.core.rollout_files import (
    MODELS_FILE,
    RAW,
    RolloutKey,
    Segment,
    parse_rollout_path,
    rollout_path,
    scenario_names,
    split_variant,
    variant_scenario,
)
from pimann.generate.benchmark_clips import benchmark_scripts
from pimann.learn.model_files import model_seeds

log = logging.getLogger(__name__)


def models_record(models_dir: str | Path) -> dict[str, Any]:
    """What the rollouts' provenance keeps of each seed's meta.json."""
    record: dict[str, Any] = {}
    for seed, folder in model_seeds(models_dir).items():
        meta_path = folder / "meta.json"
        try:
            meta = json.loads(meta_path.read_text())
            record[str(seed)] = {
                "pi_weight": float(meta["pi_weight"]),
                "variant": meta["variant"],
                "best_epoch": meta.get("best_epoch"),
                "best_test_loss": meta.get("best_test_loss"),
                "epochs": meta.get("epochs"),
                "train_samples": meta.get("train_samples"),
                "clips": len(meta.get("train_clips", [])) + len(meta.get("test_clips", [])),
            }
        except KeyError as error:
            raise PimannError(meta_path, f"a model's metadata lacks {error}") from None
        except (AttributeError, TypeError, ValueError) as error:  # not JSON, not an object
            raise PimannError(meta_path, f"not a model's metadata ({error})") from None
    return record


def _generate_seed(
    job: tuple[Path, list[tuple[str, list[Segment], bool, Path, str | None, bool]], Params],
) -> str | None:
    """One seed's rollouts, generated together in batches
    (pimann.generate.rollout_batch.generate_files);
    the error that stopped them (naming the file), or None."""
    import torch

    from pimann.generate.rollout_batch import FileJob, generate_files

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
    `rollout.scenario_names`, then the benchmark's clips' scripts (`rollout.benchmark_clips`:
    the test clips', `rollout.benchmark_train_clips`: training clips')."""
    names = scenario_names(params.rollout)
    unknown = [name for name in names if name not in params.rollout.scenarios]
    if unknown:
        raise PimannError("params.yaml", f"rollout.scenario_names: unknown scenario {unknown[0]!r}")
    scripts = {name: list(params.rollout.scenarios[name]) for name in names}
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
    scenarios and the benchmark clips), with and without steering; and, with "loop" in
    `rollout.consistent.variants`, the contact-consistent rollouts of its scenarios held inside
    the loop (`<scenario>+loop`; the "post" ones: `write_seed_rollouts`).

    One job per seed (`workers` processes): its scripts x steering advance together as one
    batch (pimann.generate.batch_generator). Written into `out_dir` (= results/rollouts/<model>) as
    a whole, atomically.
    """
    scripts = rollout_scripts(params)
    runs = [(sc, script, None) for sc, script in scripts.items()] + [
        (name, protocol.script, name) for name, protocol in params.rollout.protocols.items()
    ]  # a protocol runs under its own name, with the rollout keys it sets
    consistent = params.rollout.consistent
    variants = [(RAW, False)] + [("loop", True)] * ("loop" in consistent.variants)

    def seed_job(tmp: Path, seed: int, folder: Path) -> tuple:
        files = []
        for variant, loop in variants:
            for sc, script, protocol in runs:
                if loop and sc not in consistent.scenarios:
                    continue
                name = variant_scenario(sc, variant)
                files += [
                    (
                        name,
                        script,
                        st,
                        rollout_path(tmp.parent, RolloutKey(tmp.name, seed, name, st)),
                        protocol,
                        loop,
                    )
                    for st in (False, True)
                ]
        return folder, files, params

    return write_seed_rollouts(models_dir, out_dir, params, seed_job, _generate_seed, workers)


def write_seed_rollouts(
    models_dir: str | Path,
    out_dir: str | Path,
    params: Params,
    seed_job: Callable[[Path, int, Path], Any],
    generate_seed: Callable[[Any], str | None],
    workers: int,
) -> list[Path]:
    """Each seed's rollouts by `generate_seed(seed_job(tmp, seed, model folder))` (an error
    naming the file, or None), `workers` processes, into `out_dir` as a whole, atomically, with
    `MODELS_FILE`: the models' meta and the seeds that failed (recorded; the others go on).
    With "post" in `rollout.consistent.variants`, each raw rollout of its scenarios also
    post-processed into its contact-consistent variant `<scenario>+post` (`_post_seed`)."""
    models_dir, out_dir = Path(models_dir), Path(out_dir)
    seeds = model_seeds(models_dir)
    record = {
        "profile": params.profile,
        "models_dir": models_dir.name,
        "seeds": models_record(models_dir),
    }
    with atomic_path(out_dir) as tmp:
        jobs = [seed_job(tmp, seed, folder) for seed, folder in seeds.items()]
        tmp.mkdir()
        for seed in seeds:
            (tmp / str(seed)).mkdir()
        failures = pool_map(generate_seed, jobs, workers, f"rollouts {out_dir.name}", "seeds")
        record["failed"] = {
            str(seed): error for seed, error in zip(seeds, failures, strict=True) if error
        }
        for seed, error in record["failed"].items():  # recorded; the other seeds go on
            log.warning("rollouts of %s seed %s failed: %s", models_dir.name, seed, error)
            shutil.rmtree(tmp / seed)  # no half set of a seed's rollouts
        if len(record["failed"]) == len(seeds):
            raise PimannError(models_dir, f"every seed failed; first: {failures[0]}")
        if "post" in params.rollout.consistent.variants:
            done = [tmp / str(seed) for seed in seeds if str(seed) not in record["failed"]]
            jobs = [(folder, params) for folder in done]
            pool_map(_post_seed, jobs, workers, f"consistent {out_dir.name}", "seeds")
        (tmp / MODELS_FILE).write_text(json.dumps(record, indent=2) + "\n")
    return sorted(out_dir.glob("*/*.h5"))


def _post_seed(job: tuple[Path, Params]) -> None:
    """The contact-consistent variant `<scenario>+post` of each raw rollout of one seed's
    folder whose scenario is in `rollout.consistent.scenarios`
    (pimann.generate.contact_consistent), beside it."""
    from pimann.core.robot import load_robot
    from pimann.core.trajectory import read_trajectory, write_trajectory
    from pimann.generate.contact_consistent import LegSolver, make_consistent

    folder, params = job
    consistent, robot = params.rollout.consistent, load_robot()
    solver = LegSolver(robot, consistent)
    root = folder.parent.parent
    for path in sorted(folder.glob("*.h5")):
        key = parse_rollout_path(root, path)
        scenario, variant = split_variant(key.scenario)
        if variant != RAW or scenario not in consistent.scenarios:
            continue
        out = make_consistent(read_trajectory(path), robot, consistent, params.contacts, solver)
        post = dataclasses.replace(key, scenario=variant_scenario(scenario, "post"))
        write_trajectory(rollout_path(root, post), out.trajectory)
