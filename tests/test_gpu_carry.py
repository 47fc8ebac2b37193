"""jobs/gpu_carry.py's round trip on the CPU: pack, carry, unpack, train, pack back, unpack."""

from __future__ import annotations

import importlib.util
import json

import pytest
from builders import synthetic_collection

from pimann.core.params import load_params
from pimann.core.paths import REPO_ROOT
from pimann.learn.dataset import write_dataset
from pimann.learn.features import build_dataset


@pytest.fixture(scope="module")
def carry():
    spec = importlib.util.spec_from_file_location("gpu_carry", REPO_ROOT / "jobs" / "gpu_carry.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_stage_commands_are_dvc_yamls(carry):
    """What the device runs: every train@<w> of train.pi_weights and train_baseline."""
    commands = dict(carry.stage_commands(REPO_ROOT))
    weights = load_params().train.pi_weights
    assert list(commands) == [f"train@{w:g}" for w in weights] + ["train_baseline"]
    assert commands["train@10"] == (
        "python stages/train.py --pi-weight 10 --variant full --out models/w10"
        " --plots results/training/w10"
    )


def test_the_dry_run_trains_on_the_copy_and_brings_every_model_back(carry, tmp_path):
    features = tmp_path / "features"
    collection = synthetic_collection(n_sources=4, frames=160)
    for variant in ("full", "ground_projected"):
        dataset = build_dataset(collection, load_params().features, variant)
        write_dataset(features / f"{variant}.h5", dataset)
    result = carry.smoke(REPO_ROOT, tmp_path / "work", features)
    inputs = result["inputs"]
    assert len(inputs["pieces"]) > 1 and result["calls"] > 1  # joined from pieces both ways
    assert any(
        name.endswith("robots/ergoCubGazeboV1_xsens/ergoCubGazeboV1_xsens.urdf")
        for name in inputs["files"]
    )
    calls = carry.device_calls(inputs)
    assert all(len(c["carry"]) == 2 and c["carry"][0].endswith(carry.MANIFEST) for c in calls)
    assert "train" in calls[-1]["command"] and "train" not in calls[0]["command"]
    returned = set(result["returned"])
    for stage, command in carry.stage_commands(REPO_ROOT):
        out = command.split()[command.split().index("--out") + 1]
        assert f"{out}/0/model.pt" in returned and f"{out}/0/meta.json" in returned
        assert f"results/stage_times/{stage}.json" in returned
    meta = json.loads(
        (tmp_path / "work" / "back" / "models" / "w10" / "0" / "meta.json").read_text()
    )
    assert meta["pi_weight"] == 10 and meta["epochs"] == 1
