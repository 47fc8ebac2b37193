"""Training: deterministic, exact resume, loss goes down, the PI term reaches the gradient."""

from __future__ import annotations

import csv
import dataclasses
import json

import numpy as np
import pytest
import torch
from test_features import synthetic_collection

from pimann.errors import PimannError
from pimann.features import build_dataset, write_dataset
from pimann.mann import MANN
from pimann.params import ModelParams, load_params
from pimann.train import (
    TrainingLoss,
    epoch_order,
    load_model,
    schedule_factor,
    train_models,
)

SMALL_MODEL = ModelParams(
    n_experts=2, gating_hidden=8, gating_layers=3, prediction_hidden=32, prediction_layers=3,
    dropout=0.3, activation="elu",
)  # fmt: skip


@pytest.fixture(scope="module")
def params():
    base = load_params()
    train = dataclasses.replace(base.train, epochs=4, batch_size=64, device="cpu")
    return dataclasses.replace(base, model=SMALL_MODEL, train=train)


@pytest.fixture(scope="module")
def dataset_path(tmp_path_factory, params):
    """A tiny dataset: 4 synthetic sources and their 'mirrors', ~50 samples each."""
    dataset = build_dataset(synthetic_collection(n_sources=4, frames=160), params.features, "full")
    path = tmp_path_factory.mktemp("features") / "full.h5"
    write_dataset(path, dataset)
    return path


def _weights(directory) -> dict[str, torch.Tensor]:
    return torch.load(directory / "model.pt", weights_only=True)["state_dict"]


def test_schedule_and_order():
    factors = [schedule_factor(e, 10, 2) for e in range(31)]
    assert factors[0] == 1.0 and factors[10] == 1.0 and factors[30] == 1.0  # restarts
    assert factors[5] == pytest.approx(0.5) and factors[20] == pytest.approx(0.5)
    assert all(a > b for a, b in zip(factors[:9], factors[1:10], strict=True))
    assert np.array_equal(epoch_order(3, 2, 50), epoch_order(3, 2, 50))
    assert not np.array_equal(epoch_order(3, 2, 50), epoch_order(4, 2, 50))
    assert sorted(epoch_order(3, 2, 50)) == list(range(50))


def test_training_is_deterministic_resumes_exactly_and_learns(tmp_path, params, dataset_path):
    seeds = [0, 1]
    straight = train_models(dataset_path, tmp_path / "a", 1.0, seeds, params, "cpu",
                            plots_dir=tmp_path / "plots_a")  # fmt: skip
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
        assert straight[seed]["best_epoch"] == again[seed]["best_epoch"] == resumed[seed][
            "best_epoch"]  # fmt: skip
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


def test_pi_support_from_data_contacts(tmp_path, params, dataset_path):
    """data_contacts trains on the data's flags, differs from lower_sole, and needs them."""
    from pimann.features import read_dataset

    contacts = dataclasses.replace(
        params, train=dataclasses.replace(params.train, pi_support="data_contacts", epochs=1)
    )
    lower = dataclasses.replace(
        params, train=dataclasses.replace(params.train, pi_support="lower_sole", epochs=1)
    )
    train_models(dataset_path, tmp_path / "contacts", 1.0, [0], contacts, "cpu")
    train_models(dataset_path, tmp_path / "lower", 1.0, [0], lower, "cpu")
    a, b = _weights(tmp_path / "contacts" / "0"), _weights(tmp_path / "lower" / "0")
    assert not torch.equal(a["expert_weight_2"], b["expert_weight_2"])
    data = read_dataset(dataset_path)
    data.train_contacts = data.test_contacts = None
    bare = tmp_path / "bare.h5"
    write_dataset(bare, data)
    with pytest.raises(PimannError, match="contact flags"):
        train_models(bare, tmp_path / "bare", 1.0, [0], contacts, "cpu")


def test_pi_term_enters_the_gradient(params, dataset_path):
    from pimann.features import read_dataset

    data = read_dataset(dataset_path)
    loss = TrainingLoss(data.layout, data.stats, "predicted", torch.device("cpu"))
    model = MANN.from_seeds(130, 100, SMALL_MODEL, [0]).eval()
    x = torch.as_tensor(data.x_train[None, :32])
    y = torch.as_tensor(data.y_train[None, :32])

    def gradient(weight: float) -> torch.Tensor:
        model.zero_grad()
        mse, pi = loss(model(x), y)
        (mse + weight * pi).sum().backward()
        return model.expert_weight_2.grad.clone()

    g0, g10 = gradient(0.0), gradient(10.0)
    assert not torch.allclose(g0, g10)
    # the ground-truth configuration variant changes the PI gradient, not the value's sign
    truth = TrainingLoss(data.layout, data.stats, "ground_truth", torch.device("cpu"))
    with torch.no_grad():
        pred = model(x)
        assert truth(pred, y)[1] > 0 and loss(pred, y)[1] > 0
        assert not torch.allclose(truth(pred, y)[1], loss(pred, y)[1])
