"""The sweep trainer: every (w, seed) one member, each equal to its own weight's training."""

from __future__ import annotations

import csv
import dataclasses
import json
import os
import subprocess
import sys

import pytest
import torch

from pimann.core.errors import PimannError
from pimann.learn.model_files import load_model
from pimann.learn.sweep import SWEEP_DIR, SweepMember, train_from_sweep, train_sweep
from pimann.learn.train import cublas_problem, train_models

WEIGHTS, SEEDS = [0.0, 10.0], [0, 1]
CUDA = pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")


BATCH = 100  # the 384 training samples in 3 batches and a tail of 84: two graphs on CUDA


@pytest.fixture(scope="module")
def sweep_params(params):
    """The small training in float32 (bfloat16 products would blur the comparison), at a batch
    that leaves a tail (its own step, and on CUDA its own graph and memory pool)."""
    train = dataclasses.replace(
        params.train, precision="float32", workers=1, seeds=SEEDS, batch_size=BATCH
    )
    return dataclasses.replace(params, train=train)


def test_the_training_set_leaves_a_tail_batch(dataset_path):
    from pimann.learn.dataset import read_dataset

    n = len(read_dataset(dataset_path).x_train)
    assert n > BATCH and n % BATCH != 0


@pytest.fixture(scope="module")
def solo(tmp_path_factory, sweep_params, dataset_path):
    """Each weight's own training (pimann.learn.train), its models by (w, seed)."""
    root = tmp_path_factory.mktemp("solo")
    metas = {}
    for w in WEIGHTS:
        plots = root / "plots" / f"w{w:g}"
        for seed, meta in train_models(
            dataset_path, root / f"w{w:g}", w, SEEDS, sweep_params, "cpu", plots_dir=plots
        ).items():
            metas[SweepMember(w, seed)] = (meta, root / f"w{w:g}" / str(seed))
    return metas


def _assert_member_is_solo(member: dict, meta: dict, folder, atol: float) -> None:
    model, *_ = load_model(folder)
    for name, value in model.state_dict().items():
        torch.testing.assert_close(member["state_dict"][name], value.cpu(), rtol=0, atol=atol)
    assert member["best_epoch"] == meta["best_epoch"]
    assert member["best_loss"] == pytest.approx(meta["best_test_loss"], rel=1e-5)


def test_each_member_ends_as_its_weights_own_training(sweep_params, dataset_path, solo):
    results = train_sweep(dataset_path, WEIGHTS, SEEDS, sweep_params, "cpu", progress=None)
    assert set(results) == set(solo)
    for member, (meta, folder) in solo.items():
        _assert_member_is_solo(results[member], meta, folder, atol=1e-6)
    # the members differ: own seeds, own weights (w=10's L_B moved it off w=0's path)
    a, b, c = (
        results[SweepMember(w, s)]["state_dict"]["expert_weight_0"]
        for w, s in ((0.0, 0), (0.0, 1), (10.0, 0))
    )
    assert (a - b).abs().max() > 1e-3 and (a - c).abs().max() > 1e-5
    rows = results[SweepMember(10.0, 0)]["history"]
    assert [r["epoch"] for r in rows] == [1, 2, 3, 4] and rows[-1]["train_pi"] > 0
    assert rows[-1]["train_loss"] < rows[0]["train_loss"]
    assert rows[0]["train_loss"] == pytest.approx(rows[0]["train_mse"] + 10 * rows[0]["train_pi"])


def test_a_bfloat16_sweep_ends_as_the_bfloat16_trainings(tmp_path, sweep_params, dataset_path):
    """The products under autocast (its cast cache off, as a graph needs) as the CPU's trainer."""
    train = dataclasses.replace(sweep_params.train, precision="bfloat16", epochs=2)
    bf16 = dataclasses.replace(sweep_params, train=train)
    results = train_sweep(dataset_path, [10.0], SEEDS, bf16, "cpu", progress=None)
    metas = train_models(dataset_path, tmp_path / "w10", 10.0, SEEDS, bf16, "cpu")
    for seed, meta in metas.items():
        assert meta["precision"] == "bfloat16"
        _assert_member_is_solo(
            results[SweepMember(10.0, seed)], meta, tmp_path / "w10" / str(seed), atol=1e-5
        )


def test_an_interrupted_sweep_resumes_exactly(tmp_path, sweep_params, dataset_path):
    checkpoint = tmp_path / "sweep.pt"
    straight = train_sweep(dataset_path, WEIGHTS, SEEDS, sweep_params, "cpu", progress=None)
    stopped = train_sweep(
        dataset_path,
        WEIGHTS,
        SEEDS,
        sweep_params,
        "cpu",
        checkpoint=checkpoint,
        stop_after=2,
        progress=None,
    )
    assert stopped is None and checkpoint.is_file()
    resumed = train_sweep(
        dataset_path, WEIGHTS, SEEDS, sweep_params, "cpu", checkpoint=checkpoint, progress=None
    )
    for member, result in straight.items():
        for name, value in result["state_dict"].items():
            assert torch.equal(resumed[member]["state_dict"][name], value), (member, name)
        assert resumed[member]["history"] == result["history"]


def test_the_stages_write_each_weight_out_of_one_sweep(tmp_path, sweep_params, dataset_path, solo):
    models = tmp_path / "models"
    metas = train_from_sweep(
        dataset_path,
        models / "w0",
        0,
        WEIGHTS,
        sweep_params,
        "cpu",
        plots_dir=tmp_path / "plots" / "w0",
    )
    assert (models / SWEEP_DIR).is_dir()  # kept for w=10's stage
    train_from_sweep(
        dataset_path,
        models / "w10",
        10,
        WEIGHTS,
        sweep_params,
        "cpu",
        plots_dir=tmp_path / "plots" / "w10",
    )
    assert not (models / SWEEP_DIR).exists()  # every weight is out
    for member, (meta, folder) in solo.items():
        written = models / f"w{member.pi_weight:g}" / str(member.seed)
        mine = json.loads((written / "meta.json").read_text())
        assert list(mine) == list(meta)  # the same record as the CPU's trainer writes
        assert mine["pi_weight"] == member.pi_weight and mine["seed"] == member.seed
        model, *_ = load_model(written)
        reference, *_ = load_model(folder)
        for name, value in model.state_dict().items():
            torch.testing.assert_close(value, reference.state_dict()[name], rtol=0, atol=1e-6)
    assert metas[0]["best_epoch"] == solo[SweepMember(0.0, 0)][0]["best_epoch"]
    # the loss CSVs: the same columns and, to float tolerance, the same values (w = 0's
    # train_pi included: L_B after each epoch on a sample, as the CPU's trainer logs it)
    for member, (_, folder) in solo.items():
        name = f"w{member.pi_weight:g}/seed{member.seed}.csv"
        mine = _read_csv(tmp_path / "plots" / name)
        theirs = _read_csv(folder.parent.parent / "plots" / name)
        assert list(mine[0]) == list(theirs[0]) and len(mine) == len(theirs) == 4
        for row, reference in zip(mine, theirs, strict=True):
            for column, value in reference.items():
                assert float(row[column]) == pytest.approx(float(value), rel=1e-5, abs=1e-9), (
                    name,
                    column,
                )
        assert min(float(row["train_pi"]) for row in mine) > 0


def _read_csv(path) -> list[dict[str, str]]:
    with path.open(newline="") as file:
        return list(csv.DictReader(file))


def test_what_the_sweep_cannot_do_is_refused(tmp_path, sweep_params, dataset_path):
    with pytest.raises(PimannError, match="distinct"):
        train_sweep(dataset_path, [1.0, 1.0], SEEDS, sweep_params, "cpu")
    with pytest.raises(PimannError, match="not in the sweep"):
        train_from_sweep(dataset_path, tmp_path / "w5", 5, WEIGHTS, sweep_params, "cpu")
    if not torch.cuda.is_available():
        with pytest.raises(PimannError, match="CUDA"):
            train_sweep(dataset_path, WEIGHTS, SEEDS, sweep_params, "cpu", graph=True)


def test_cublas_is_set_at_import_and_checked():
    """Deterministic cuBLAS: the setting is in the environment once the trainers are
    imported, and a CUDA training refuses a wrong or late one (a CPU one needs none)."""
    env = {k: v for k, v in os.environ.items() if k != "CUBLAS_WORKSPACE_CONFIG"}
    code = "import os, pimann.learn.sweep; print(os.environ['CUBLAS_WORKSPACE_CONFIG'])"
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    )
    assert out.stdout.strip() == ":4096:8"
    cuda, cpu = torch.device("cuda"), torch.device("cpu")
    assert cublas_problem(cuda, ":4096:8", late=False) is None
    assert cublas_problem(cuda, ":16:8", late=False) is None
    assert "is not one of" in cublas_problem(cuda, None, late=False)
    assert "is not one of" in cublas_problem(cuda, ":0:0", late=False)
    assert "after CUDA started" in cublas_problem(cuda, ":4096:8", late=True)
    assert cublas_problem(cpu, None, late=True) is None


@CUDA
def test_the_cuda_graph_trains_as_the_eager_step_and_the_solo_training(
    tmp_path, sweep_params, dataset_path
):
    graphed = train_sweep(
        dataset_path, WEIGHTS, SEEDS, sweep_params, "cuda", graph=True, progress=None
    )
    eager = train_sweep(
        dataset_path, WEIGHTS, SEEDS, sweep_params, "cuda", graph=False, progress=None
    )
    for member, result in eager.items():
        for name, value in result["state_dict"].items():
            torch.testing.assert_close(
                graphed[member]["state_dict"][name], value, rtol=0, atol=1e-5
            )
        assert graphed[member]["best_epoch"] == result["best_epoch"]
    for w in WEIGHTS:
        metas = train_models(dataset_path, tmp_path / f"w{w:g}", w, SEEDS, sweep_params, "cuda")
        for seed, meta in metas.items():
            _assert_member_is_solo(
                graphed[SweepMember(w, seed)], meta, tmp_path / f"w{w:g}" / str(seed), atol=1e-5
            )
