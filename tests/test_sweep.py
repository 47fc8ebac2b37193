"""The sweep trainer: every (w, seed) one member, each equal to its own weight's training."""

from __future__ import annotations

import dataclasses
import json

import pytest
import torch

from pimann.core.errors import PimannError
from pimann.learn.model_files import load_model
from pimann.learn.sweep import SWEEP_DIR, SweepMember, train_from_sweep, train_sweep
from pimann.learn.train import train_models

WEIGHTS, SEEDS = [0.0, 10.0], [0, 1]
CUDA = pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")


@pytest.fixture(scope="module")
def sweep_params(params):
    """The small training in float32 (bfloat16 products would blur the comparison)."""
    train = dataclasses.replace(params.train, precision="float32", workers=1, seeds=SEEDS)
    return dataclasses.replace(params, train=train)


@pytest.fixture(scope="module")
def solo(tmp_path_factory, sweep_params, dataset_path):
    """Each weight's own training (pimann.learn.train), its models by (w, seed)."""
    root = tmp_path_factory.mktemp("solo")
    metas = {}
    for w in WEIGHTS:
        for seed, meta in train_models(
            dataset_path, root / f"w{w:g}", w, SEEDS, sweep_params, "cpu"
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
    train_from_sweep(dataset_path, models / "w10", 10, WEIGHTS, sweep_params, "cpu")
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
    assert (tmp_path / "plots" / "w0" / "seed1.csv").is_file()


def test_what_the_sweep_cannot_do_is_refused(tmp_path, sweep_params, dataset_path):
    with pytest.raises(PimannError, match="distinct"):
        train_sweep(dataset_path, [1.0, 1.0], SEEDS, sweep_params, "cpu")
    with pytest.raises(PimannError, match="not in the sweep"):
        train_from_sweep(dataset_path, tmp_path / "w5", 5, WEIGHTS, sweep_params, "cpu")
    if not torch.cuda.is_available():
        with pytest.raises(PimannError, match="CUDA"):
            train_sweep(dataset_path, WEIGHTS, SEEDS, sweep_params, "cpu", graph=True)


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
