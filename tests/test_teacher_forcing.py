"""Teacher-forced response per motion class (pimann.teacher_forcing) on a tiny real pipeline."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from pimann.features import build_dataset, write_dataset
from pimann.mann import MANN
from pimann.model_files import save_model
from pimann.params import ModelParams, load_params
from pimann.teacher_forcing import _slope, class_response
from pimann.trajectory import write_collection
from tests.test_features import synthetic_collection


def test_slope_of_a_scaled_copy_and_of_a_constant():
    truth = np.linspace(-1, 1, 50)
    assert _slope(truth, truth) == pytest.approx(1.0)
    assert _slope(truth, 0.5 * truth + 3) == pytest.approx(0.5)
    assert _slope(truth, np.full(50, 0.2)) == pytest.approx(0.0, abs=1e-12)


def test_class_response_reports_the_data_velocity_per_class(tmp_path):
    params = load_params()
    clips = synthetic_collection(n_sources=6, frames=200)  # straight walks at 0.2-0.7 m/s
    collection = tmp_path / "walking.h5"
    write_collection(collection, clips)
    dataset = build_dataset(clips, params.features, "full")
    dataset_path = tmp_path / "full.h5"
    write_dataset(dataset_path, dataset)
    small = ModelParams(2, 8, 2, 16, 2, 0.0, "elu")
    torch.manual_seed(0)
    model = MANN(dataset.layout.input_dim, dataset.layout.output_dim, small, seeds=[0])
    meta = {"pi_weight": 0.0, "seed": 0, "variant": "full", "dataset": str(dataset_path),
            "params": {"model": dataclasses.asdict(small)}}  # fmt: skip
    save_model(tmp_path / "w0" / "0", model, dataset.layout, dataset.stats, meta)
    table = class_response(tmp_path / "w0", collection, samples=500)
    assert set(table["split"]) == {"train", "test"}
    assert set(table["class"]) <= {"forward", "turning", "diagonal"}
    # the truth is the clips' own forward speed in the base frame (0.2 .. 0.7 m/s, pitched base)
    assert ((table["vx_true"] > 0.1) & (table["vx_true"] < 0.8)).all()
    assert table["samples"].min() >= 50 and np.isfinite(table["vx_slope"]).all()


def test_models_folder_or_one_training_output_and_a_named_error(tmp_path, capsys):
    from pimann.teacher_forcing import main, model_folders

    (tmp_path / "w10" / "0").mkdir(parents=True)
    (tmp_path / "w10" / "0" / "meta.json").write_text("{}")
    (tmp_path / "notes").mkdir()
    assert model_folders(tmp_path) == [tmp_path / "w10"]
    assert model_folders(tmp_path / "w10") == [tmp_path / "w10"]
    assert main(["--models", str(tmp_path / "notes")]) == 2
    error = capsys.readouterr().err
    assert "notes" in error and "no trained models" in error and error.count("\n") == 1
