"""The sweep across machines on DVC's own mechanism, with real git, DVC and training.

Two worker clones each train one stage of the matrix (a tiny profile: seconds) and push its
outputs and run-cache to the repository's default remote (a folder beside the clones); a
third clone pulls the run-cache, and its `dvc repro` of both stages restores them instead of
training: DVC says so, the stage-time records are the workers' (the run that made the
models), and `dvc status` has them up to date. The workers' recipe and the coordinator's are
those of docs/sweep.md.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from pimann.core.params import load_params
from pimann.core.paths import shared_dir
from pimann.learn.dataset import write_dataset
from pimann.learn.features import build_dataset

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).parent))  # test_features' synthetic clips
from builders import synthetic_collection  # noqa: E402

# what a clone of the pipeline needs to run the training stages (no results, no lock file)
PROJECT = ["dvc.yaml", "params.yaml", ".dvc/config", ".dvcignore", ".gitignore"]
PACKAGES = ["pimann", "stages"]
WEIGHTS = [0, 10]  # two stages of the matrix: one per worker
# training in seconds: one epoch of a small network on a few hundred samples (the quick
# profile's seeds, which other settings name)
TINY = {
    "train.epochs": 1,
    "train.batch_size": 64,
    "train.max_train_samples": 200,
    "train.workers": 1,
    "model.prediction_hidden": 32,
    "model.gating_hidden": 8,
}


def _run(command: list[str], cwd: Path) -> str:
    """`command` in `cwd` with the clone's own pimann; its output (stdout and stderr).

    `dvc` is this interpreter's module, and this interpreter's folder leads PATH, so the
    stages' `python` (dvc.yaml) is the one running the tests: a venv's python works without the
    venv activated (nothing of it on PATH)."""
    if command[0] == "dvc":
        command = [sys.executable, "-m", "dvc", *command[1:]]
    env = {
        **os.environ,
        "PATH": os.pathsep.join([str(Path(sys.executable).parent), os.environ.get("PATH", "")]),
        "PYTHONPATH": str(cwd),
        "OMP_NUM_THREADS": "1",
        "PIMANN_THREADS": "1",
        "DVC_NO_ANALYTICS": "1",
        "PIMANN_SHARED": "",
    }
    env.pop("PIMANN_SHARED")  # the default, ../shared beside the clone, as dvc.yaml tracks it
    done = subprocess.run(command, cwd=cwd, env=env, capture_output=True, text=True, timeout=300)
    output = done.stdout + done.stderr
    assert done.returncode == 0, f"{' '.join(command)} in {cwd.name} failed:\n{output}"
    return output


def _tiny_origin(origin: Path) -> None:
    """A git repository of the project whose quick profile trains in seconds."""
    for name in PROJECT:
        (origin / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(REPO / name, origin / name)
    for package in PACKAGES:
        shutil.copytree(
            REPO / package, origin / package, ignore=shutil.ignore_patterns("__pycache__")
        )
    params = yaml.safe_load((REPO / "params.yaml").read_text())
    params["profiles"]["quick"] = {**(params["profiles"]["quick"] or {}), **TINY}
    params["profile"] = "quick"
    (origin / "params.yaml").write_text(yaml.safe_dump(params, sort_keys=False))
    git = ["git", "-c", "user.name=test", "-c", "user.email=test@example.org"]
    _run(["git", "init", "-q"], origin)
    _run(["git", "add", "-A"], origin)
    _run([*git, "commit", "-qm", "tiny sweep"], origin)


@pytest.mark.skipif(shutil.which("git") is None, reason="no git")
def test_workers_push_trainings_that_a_coordinator_restores_without_training(tmp_path):
    (tmp_path / "shared").symlink_to(shared_dir().resolve())  # ../shared of every clone
    origin = tmp_path / "origin"
    origin.mkdir()
    _tiny_origin(origin)
    # the features every machine pulls (here: the same bytes copied into each clone)
    params = load_params(origin / "params.yaml")
    features = tmp_path / "full.h5"
    write_dataset(features, build_dataset(synthetic_collection(4, 160), params.features, "full"))
    clones = {}
    for name in ("worker0", "worker1", "coordinator"):
        clones[name] = tmp_path / name
        _run(["git", "clone", "-q", str(origin), name], tmp_path)
        target = clones[name] / params.features.output_dir / "full.h5"
        target.parent.mkdir(parents=True)
        shutil.copy2(features, target)

    for k, weight in enumerate(WEIGHTS):  # each worker: one stage of the matrix
        worker = clones[f"worker{k}"]
        trained = _run(["dvc", "repro", "-s", f"train@{weight}"], worker)
        assert f"Running stage 'train@{weight}'" in trained
        _run(["dvc", "push"], worker)
        _run(["dvc", "push", "--run-cache"], worker)
    remote = tmp_path / "pimann-dvc-remote"  # .dvc/config's default: beside the checkout
    assert (remote / "files" / "md5").is_dir() and (remote / "runs").is_dir()

    coordinator = clones["coordinator"]
    stages = [f"train@{weight}" for weight in WEIGHTS]
    # fetch, not pull: a pull also checks out the stages' outputs, which no dvc.lock of this
    # clone records yet (it fails on them); repro --pull takes the outputs the runs name
    _run(["dvc", "fetch", "--run-cache"], coordinator)
    restored = _run(["dvc", "repro", "--pull", "-s", *stages], coordinator)
    assert "Running stage" not in restored, restored
    for k, stage in enumerate(stages):
        assert f"Stage '{stage}' is cached - skipping run, checking out outputs" in restored
        worker = clones[f"worker{k}"]
        for path in (
            f"models/w{WEIGHTS[k]}/0/model.pt",
            f"results/stage_times/{stage}.json",
            f"results/training/w{WEIGHTS[k]}/seed0.csv",
        ):
            assert (coordinator / path).read_bytes() == (worker / path).read_bytes(), path
        record = yaml.safe_load((coordinator / f"results/stage_times/{stage}.json").read_text())
        assert record["stage"] == stage and record["wall_s"] > 0  # the worker's run, not one here
        assert record["train_precision"] == "float32"
    status = _run(["dvc", "status", *stages], coordinator)
    assert "Data and pipelines are up to date." in status, status


WORKER_RECIPE = ["dvc pull features", "dvc repro -s", "dvc push", "dvc push --run-cache"]


def test_job_files_cover_the_training_matrix_with_the_worker_recipe():
    """The Slurm array has one task per training stage of params.yaml's matrix, and both job
    files run the worker recipe in its order."""
    import re

    params = load_params(REPO / "params.yaml")
    slurm = (REPO / "jobs/slurm_train.sh").read_text()
    (last,) = re.findall(r"^#SBATCH --array=0-(\d+)$", slurm, re.MULTILINE)
    assert int(last) + 1 == len(params.train.pi_weights) + 1  # train@<w> each, train_baseline
    skypilot = yaml.safe_load((REPO / "jobs/skypilot_train.yaml").read_text())
    for name, script in (("slurm", slurm), ("skypilot", skypilot["run"])):
        at = [script.find(step) for step in WORKER_RECIPE]
        assert -1 not in at and at == sorted(at), name
    assert skypilot["envs"]["STAGE"].startswith("train")


def test_every_output_of_a_training_is_cached():
    """The run-cache covers a stage only when DVC caches all its outputs and plots."""
    stages = yaml.safe_load((REPO / "dvc.yaml").read_text())["stages"]
    for name in ("train", "train_baseline"):
        entries = stages[name]["outs"] + stages[name].get("plots", [])
        assert len(entries) >= 3, name  # models, stage-time record, loss curves
        for entry in entries:
            options = next(iter(entry.values())) if isinstance(entry, dict) else {}
            assert options.get("cache", True), f"{name}: {entry}"
