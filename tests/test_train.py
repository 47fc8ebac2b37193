"""Training: deterministic, exact resume, loss goes down, the PI term reaches the gradient."""

from __future__ import annotations

import csv
import dataclasses
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
from builders import (
    BROKEN_MODELS,
    SMALL_MODEL,
    _weights,
    break_features,
    break_model,
    save_small_model,
)

from pimann.core.errors import PimannError
from pimann.learn.epochs import epoch_order, epoch_seed, schedule_factor
from pimann.learn.mann import MANN
from pimann.learn.model_files import load_model
from pimann.learn.train import train_models
from pimann.learn.training_loss import TrainingLoss


def test_schedule_and_order():
    factors = [schedule_factor(e, 10, 2) for e in range(31)]
    assert factors[0] == 1.0 and factors[10] == 1.0 and factors[30] == 1.0  # restarts
    assert factors[5] == pytest.approx(0.5) and factors[20] == pytest.approx(0.5)
    assert all(a > b for a, b in zip(factors[:9], factors[1:10], strict=True))
    assert np.array_equal(epoch_order(3, 2, 50), epoch_order(3, 2, 50))
    assert not np.array_equal(epoch_order(3, 2, 50), epoch_order(4, 2, 50))
    assert sorted(epoch_order(3, 2, 50)) == list(range(50))
    # one seed per (member, epoch)
    seeds = {epoch_seed(s, e, "dropout") for s in (0, 1) for e in (0, 1)}
    assert len(seeds) == 4 and epoch_seed(1, 1, "dropout") == epoch_seed(1, 1, "dropout")


def test_training_is_deterministic_resumes_exactly_and_learns(tmp_path, params, dataset_path):
    seeds = [0, 1]
    straight = train_models(
        dataset_path, tmp_path / "a", 1.0, seeds, params, "cpu", plots_dir=tmp_path / "plots_a"
    )
    again = train_models(dataset_path, tmp_path / "b", 1.0, seeds, params, "cpu")
    # interrupted after 2 epochs, then resumed to 4
    assert train_models(dataset_path, tmp_path / "c", 1.0, seeds, params, "cpu", stop_after=2) == {}
    assert not (tmp_path / "c").exists() and (tmp_path / ".checkpoints" / "c").is_dir()
    resumed = train_models(dataset_path, tmp_path / "c", 1.0, seeds, params, "cpu")
    assert not (tmp_path / ".checkpoints" / "c").exists()  # removed once the models are out
    for seed in seeds:
        a, b, c = (_weights(tmp_path / name / str(seed)) for name in "abc")
        for name in a:
            assert torch.equal(a[name], b[name]), name
            torch.testing.assert_close(a[name], c[name], rtol=1e-6, atol=1e-7)
        assert (
            straight[seed]["best_epoch"] == again[seed]["best_epoch"] == resumed[seed]["best_epoch"]
        )
    # members differ (own init and data order), and the loss went down
    assert not torch.equal(*(_weights(tmp_path / "a" / str(s))["expert_weight_0"] for s in seeds))
    with (tmp_path / "plots_a" / "seed0.csv").open() as file:
        rows = list(csv.DictReader(file))
    assert [int(r["epoch"]) for r in rows] == [1, 2, 3, 4]
    assert float(rows[-1]["train_loss"]) < float(rows[0]["train_loss"])
    assert float(rows[-1]["train_pi"]) > 0.0
    best = min(rows, key=lambda r: float(r["test_loss"]))
    assert straight[0]["best_epoch"] == int(best["epoch"])
    # the saved model reloads and predicts like the best member
    model, layout, stats, meta = load_model(tmp_path / "a" / "0")
    assert meta == json.loads((tmp_path / "a" / "0" / "meta.json").read_text())
    assert layout.input_dim == 130 and not model.training and meta["pi_weight"] == 1.0
    x = torch.zeros(3, 130)
    assert model(x).shape == (3, 100) and stats.y_std.shape == (100,)


def test_members_train_alike_in_any_group(tmp_path, params, dataset_path):
    """Seeds split over 2 processes, or all in one, or alone: the same models."""
    one = dataclasses.replace(params, train=dataclasses.replace(params.train, workers=1))
    two = dataclasses.replace(params, train=dataclasses.replace(params.train, workers=2))
    train_models(dataset_path, tmp_path / "one", 1.0, [0, 1, 2], one, "cpu")
    train_models(dataset_path, tmp_path / "two", 1.0, [0, 1, 2], two, "cpu")
    train_models(dataset_path, tmp_path / "alone", 1.0, [2], one, "cpu")
    reference = _weights(tmp_path / "one" / "2")
    for other in (_weights(tmp_path / "two" / "2"), _weights(tmp_path / "alone" / "2")):
        for name in reference:
            torch.testing.assert_close(other[name], reference[name], rtol=1e-5, atol=1e-6)


def test_pi_term_enters_the_gradient(params, dataset_path):
    from pimann.learn.dataset import read_dataset

    data = read_dataset(dataset_path)
    cpu = torch.device("cpu")
    loss = TrainingLoss(
        data.layout, data.stats, cpu, pi_configuration="predicted", pi_gradient="both"
    )
    model = MANN.from_seeds(130, 100, SMALL_MODEL, [0]).eval()
    x = torch.as_tensor(data.x_train[None, :32])
    y = torch.as_tensor(data.y_train[None, :32])

    def gradient(weight: float) -> torch.Tensor:
        model.zero_grad()
        terms = loss(model(x), y)
        total = terms.total(weight)
        assert torch.equal(total, terms.data + weight * terms.physics)  # L = L_D + w L_B
        total.sum().backward()
        return model.expert_weight_2.grad.clone()

    g0, g10 = gradient(0.0), gradient(10.0)
    assert not torch.allclose(g0, g10)
    # the ground-truth configuration variant changes the PI gradient, not the value's sign
    truth = TrainingLoss(
        data.layout, data.stats, cpu, pi_configuration="ground_truth", pi_gradient="both"
    )
    with torch.no_grad():
        pred = model(x)
        assert truth(pred, y)[1] > 0 and loss(pred, y)[1] > 0
        assert not torch.allclose(truth(pred, y)[1], loss(pred, y)[1])


@pytest.fixture(scope="module")
def small_model(tmp_path_factory) -> Path:
    return save_small_model(tmp_path_factory.mktemp("models") / "3")


@pytest.mark.parametrize("kind", BROKEN_MODELS)
def test_load_model_names_the_file_and_what_is_wrong(tmp_path, small_model, kind):
    folder = shutil.copytree(small_model, tmp_path / "3")
    model, layout, stats, meta = load_model(folder)  # the folder reads before it is broken
    assert model.input_dim == layout.input_dim == len(stats.x_mean) and meta["seed"] == 3
    named, message = break_model(folder, kind)
    with pytest.raises(PimannError, match=message) as raised:
        load_model(folder)
    assert raised.value.path == str(named) and "\n" not in str(raised.value)


@pytest.mark.parametrize("kind", ["truncated", "trajectory", "layout_other_window", "nan"])
def test_training_on_a_broken_dataset_names_it_and_writes_nothing(
    tmp_path, params, dataset_path, kind
):
    broken = tmp_path / "full.h5"
    shutil.copy(dataset_path, broken)
    message = break_features(broken, kind)
    with pytest.raises(PimannError, match=message) as raised:
        train_models(broken, tmp_path / "w1", 1.0, [0], params, "cpu", plots_dir=tmp_path / "p")
    assert raised.value.path == str(broken)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["full.h5"]


@pytest.mark.parametrize("side", ["both", "joints", "base", "joint_velocities"])
def test_pi_gradient_moves_only_the_chosen_side(dataset_path, side):
    """`train.pi_gradient`: L_B's gradient reaches the base velocity outputs only with `both`
    or `base`, the joint velocity outputs unless `base`, the configuration (base pose, joints)
    unless `base` or `joint_velocities`; the loss's value is the same."""
    from pimann.learn.dataset import read_dataset

    data = read_dataset(dataset_path)
    cpu = torch.device("cpu")
    loss = TrainingLoss(
        data.layout, data.stats, cpu, pi_configuration="predicted", pi_gradient=side
    )
    both = TrainingLoss(
        data.layout, data.stats, cpu, pi_configuration="predicted", pi_gradient="both"
    )
    model = MANN.from_seeds(130, 100, SMALL_MODEL, [0]).eval()
    x = torch.as_tensor(data.x_train[None, :16])
    prediction = model(x).detach().requires_grad_(True)
    pi = loss(prediction, prediction.detach())[1]
    assert torch.allclose(pi, both(prediction, prediction.detach())[1])
    (grad,) = torch.autograd.grad(pi.sum(), prediction)
    s, now = data.layout.y_slices, data.layout.current_output
    base = grad[..., s["base_linear_future"]].unflatten(-1, (-1, 3))[..., now, :]
    joint_velocities = grad[..., s["joint_velocities"]]
    pose = ("base_position", "base_rpy", "joints")
    configuration = torch.cat([grad[..., s[name]] for name in pose], -1)
    assert (base.abs().max() > 0) == (side in ("both", "base"))
    assert (joint_velocities.abs().max() > 0) == (side != "base")
    assert (configuration.abs().max() > 0) == (side in ("both", "joints"))


def test_pi_dropout_false_takes_l_b_without_dropout(tmp_path, params, dataset_path):
    """pi_dropout false: L_B is the dropout-free prediction's (the eval-mode network's), L_D
    keeps its dropout; the training then differs from the paper's and stays deterministic."""
    from pimann.learn.dataset import read_dataset

    data = read_dataset(dataset_path)
    loss = TrainingLoss.from_params(params.train, data.layout, data.stats, torch.device("cpu"))
    model = MANN.from_seeds(130, 100, SMALL_MODEL, [0])
    x = torch.as_tensor(data.x_train[None, :32])
    y = torch.as_tensor(data.y_train[None, :32])
    model.seed_dropout([1])
    noisy = model.train()(x)
    clean = model.eval()(x)
    mse, pi = loss(noisy, y, pi_prediction=clean)
    assert torch.equal(mse, loss(noisy, y)[0])
    assert torch.equal(pi, loss(clean, y)[1])
    assert not torch.allclose(pi, loss(noisy, y)[1])

    off = dataclasses.replace(
        params, train=dataclasses.replace(params.train, pi_dropout=False, epochs=1)
    )
    on = dataclasses.replace(
        params, train=dataclasses.replace(params.train, pi_dropout=True, epochs=1)
    )
    for name, run in (("off", off), ("off_again", off), ("on", on)):
        train_models(dataset_path, tmp_path / name, 10.0, [0], run, "cpu")
    a, b = _weights(tmp_path / "off" / "0"), _weights(tmp_path / "off_again" / "0")
    c = _weights(tmp_path / "on" / "0")
    assert torch.equal(a["expert_weight_2"], b["expert_weight_2"])
    assert not torch.equal(a["expert_weight_2"], c["expert_weight_2"])


def test_bf16_training_is_deterministic_and_recorded(tmp_path, params, dataset_path):
    """Two bf16 trainings of one seed give identical weights, not float32's, and say bf16."""
    runs = {}
    for name, precision in (("bf16", "bfloat16"), ("bf16_again", "bfloat16"), ("f32", "float32")):
        train = dataclasses.replace(params.train, precision=precision, epochs=2)
        runs[name] = train_models(
            dataset_path, tmp_path / name, 1.0, [0], dataclasses.replace(params, train=train), "cpu"
        )
    a, b, f32 = (_weights(tmp_path / name / "0") for name in ("bf16", "bf16_again", "f32"))
    for name in a:
        assert a[name].dtype == torch.float32, name  # the weights stay float32
        assert torch.equal(a[name], b[name]), name
    assert not torch.equal(a["expert_weight_0"], f32["expert_weight_0"])
    assert runs["bf16"][0]["precision"] == "bfloat16" and runs["f32"][0]["precision"] == "float32"
    meta = json.loads((tmp_path / "bf16" / "0" / "meta.json").read_text())
    assert meta["precision"] == "bfloat16"


# bf16 keeps 8 bits of mantissa (a product's relative error ~2^-8 = 0.4% per element); the
# losses average thousands of squared errors. Measured on this batch: at most 0.3% apart
BF16_LOSS_RTOL = 0.01


def test_bf16_and_float32_losses_of_a_batch_agree(params, dataset_path):
    from pimann.learn.dataset import read_dataset
    from pimann.learn.train import autocast

    data = read_dataset(dataset_path)
    cpu = torch.device("cpu")
    loss = TrainingLoss.from_params(params.train, data.layout, data.stats, cpu)
    model = MANN.from_seeds(130, 100, SMALL_MODEL, [0, 1]).train()
    x = torch.as_tensor(data.x_train[None, :64]).expand(2, -1, -1)
    y = torch.as_tensor(data.y_train[None, :64]).expand(2, -1, -1)
    contacts = torch.as_tensor(data.train_contacts[None, :64]).expand(2, -1, -1)
    losses = {}
    for precision in ("float32", "bfloat16"):
        model.seed_dropout([5, 6])  # the same masks in both
        with autocast(cpu, precision):
            prediction = model(x)
        assert prediction.dtype == (torch.bfloat16 if precision == "bfloat16" else torch.float32)
        mse = loss(prediction.float(), y, False).data
        # L_B with the data's feet as support: the lower sole can swap on a near tie
        terms = loss.pi_terms(prediction.float())
        pi = loss.physics(**terms, support=contacts).mean(-1)
        losses[precision] = torch.stack([mse, pi])
    f32, bf16 = losses["float32"], losses["bfloat16"]
    assert (f32 > 0).all() and not torch.equal(f32, bf16)
    torch.testing.assert_close(bf16, f32, rtol=BF16_LOSS_RTOL, atol=0.0)


def test_precision_auto_follows_the_cpu_flags(tmp_path):
    from pimann.learn.train import cpu_has_bf16, pick_precision

    with_bf16, without = tmp_path / "with", tmp_path / "without"
    with_bf16.write_text("processor : 0\nflags : fpu sse2 avx512f avx512_bf16 amx_tile\n")
    without.write_text("processor : 0\nflags : fpu sse2 avx2\n")
    assert cpu_has_bf16(with_bf16) and not cpu_has_bf16(without)
    assert not cpu_has_bf16(tmp_path / "absent")
    cpu = torch.device("cpu")
    assert pick_precision("auto", cpu) == ("bfloat16" if cpu_has_bf16() else "float32")
    assert pick_precision("float32", cpu) == "float32"
    assert pick_precision("bfloat16", cpu) == "bfloat16"


def test_meta_records_the_dataset_relative_to_the_repository(tmp_path, params, dataset_path):
    """A model's meta names its dataset relative to REPO_ROOT, so two checkouts of the same
    code and data write the same meta.json (the same DVC hash of models/); read back
    against REPO_ROOT it is the file trained on."""
    import tempfile

    from pimann.core.paths import REPO_ROOT, repo_path

    params = dataclasses.replace(params, train=dataclasses.replace(params.train, epochs=1))
    with tempfile.TemporaryDirectory(dir=REPO_ROOT) as inside:
        inside = Path(inside)
        shutil.copy(dataset_path, inside / "full.h5")
        (inside / "linked").symlink_to(dataset_path.parent)  # as a checkout's linked data/
        for name, path in (("copied", inside / "full.h5"), ("linked", inside / "linked/full.h5")):
            metas = train_models(path, tmp_path / name, 0.0, [0], params, "cpu")
            recorded = metas[0]["dataset"]
            assert recorded == str(path.relative_to(REPO_ROOT)), recorded
            assert not Path(recorded).is_absolute()
            assert repo_path(recorded).samefile(path)
            meta = json.loads((tmp_path / name / "0" / "meta.json").read_text())
            assert meta["dataset"] == recorded
    # outside the repository it stays absolute (nothing to be relative to)
    outside = train_models(dataset_path, tmp_path / "out", 0.0, [0], params, "cpu")
    assert outside[0]["dataset"] == str(dataset_path.resolve())
    assert repo_path(outside[0]["dataset"]) == dataset_path.resolve()
