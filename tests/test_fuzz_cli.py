"""Fuzz the command line with broken inputs: every subcommand, fed for each input it reads (a
mocap file, a trajectory file, a trained model's folder) an empty, truncated, NaN-laden,
wrong-layout or wrong-type file, exits 2 with one line naming the file, no traceback, and
leaves no output behind. No subcommand reads a feature file: the train stage does, and
tests/test_train.py feeds it broken ones (tests/test_features.py: read_dataset itself)."""

from __future__ import annotations

import json
import shutil

import h5py
import numpy as np
import pytest
from builders import BROKEN_MODELS, break_model, save_small_model

from pimann.cli import main
from pimann.core.params import load_params
from pimann.core.paths import shared_dir
from pimann.core.robot import STANDING_JOINTS
from pimann.core.trajectory import Trajectory, write_trajectory

BVH = next(iter(sorted((shared_dir() / "data" / "mocap" / "bandai-namco").rglob("*.bvh"))))


def _trajectory(frames: int = 60) -> Trajectory:
    time = np.arange(frames) / 50.0
    position = np.stack([0.5 * time, np.zeros(frames), np.full(frames, 0.7)], axis=1)
    quaternion = np.tile([0.0, 0.0, 0.0, 1.0], (frames, 1))
    joints = np.tile(STANDING_JOINTS, (frames, 1))
    contacts = np.ones((frames, 2), bool)
    return Trajectory(
        time, position, quaternion, joints, source="fuzz", rate_hz=50.0, contacts=contacts
    )


def _mocap_files(tmp_path):
    text = BVH.read_text()
    motion = text.index("MOTION")
    lines = text.splitlines()
    frames_at = next(k for k, line in enumerate(lines) if line.strip().startswith("Frame Time"))
    nan = lines[: frames_at + 3] + [
        lines[frames_at + 3].replace(lines[frames_at + 3].split()[4], "nan", 1)
    ]
    h5 = tmp_path / "layout.bvh"
    with h5py.File(h5, "w") as file:
        file.create_dataset("x", data=np.zeros(3))
    files = {
        "empty": b"",
        "truncated": text[: motion // 2].encode(),
        "cut_motion": text[: motion + (len(text) - motion) // 3].rsplit("\n", 1)[0].encode(),
        "nan": "\n".join(nan + lines[frames_at + 4 :]).encode(),
        "binary": bytes(range(256)) * 8,
    }
    paths = {}
    for name, data in files.items():
        path = tmp_path / f"{name}.bvh"
        path.write_bytes(data)
        paths[name] = path
    paths["layout"] = h5
    return paths


def _trajectory_files(tmp_path):
    good = tmp_path / "good.h5"
    write_trajectory(good, _trajectory())
    nan_path = tmp_path / "nan.h5"
    write_trajectory(nan_path, _trajectory())
    with h5py.File(nan_path, "r+") as file:  # the writer itself would refuse NaN
        file["joint_positions"][7, 3] = np.nan
    layout = tmp_path / "layout.h5"
    with h5py.File(layout, "w") as file:
        file.create_dataset("time", data=np.arange(10) / 50.0)
        file.create_dataset("base_position", data=np.zeros((10, 2)))
    paths = {"nan": nan_path, "layout": layout}
    for name, data in (
        ("empty", b""),
        ("truncated", good.read_bytes()[:3000]),
        ("text", b"time,x\n0,1\n"),
    ):
        path = tmp_path / f"{name}.h5"
        path.write_bytes(data)
        paths[name] = path
    return paths


def _one_line_naming(capsys, path) -> None:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert str(path) in err and "Traceback" not in err


MOCAP_KINDS = ["empty", "truncated", "cut_motion", "nan", "binary", "layout"]
TRAJECTORY_KINDS = ["empty", "truncated", "nan", "layout", "text"]


@pytest.mark.parametrize("kind", MOCAP_KINDS)
@pytest.mark.parametrize("command", ["mocap-info", "retarget", "render"])
def test_broken_mocap(tmp_path, capsys, command, kind):
    path = _mocap_files(tmp_path)[kind]
    out = tmp_path / ("out.png" if command == "render" else "out.h5")
    argv = {
        "mocap-info": ["mocap-info", str(path)],
        "retarget": ["retarget", str(path), "-o", str(out)],
        "render": ["render", str(tmp_path / "none.h5"), "--mocap", str(path), "-o", str(out)],
    }[command]
    if command == "render":  # the trajectory is fine; the mocap beside it is broken
        write_trajectory(tmp_path / "none.h5", _trajectory())
    assert main(argv) == 2
    _one_line_naming(capsys, path)
    assert not out.exists()


@pytest.mark.parametrize("kind", TRAJECTORY_KINDS)
@pytest.mark.parametrize("command", ["metrics", "render", "simulate"])
def test_broken_trajectory(tmp_path, capsys, command, kind):
    path = _trajectory_files(tmp_path)[kind]
    out = tmp_path / ("out.png" if command == "render" else "out.h5")
    argv = {
        "metrics": ["metrics", str(path)],
        "render": ["render", str(path), "-o", str(out)],
        "simulate": ["simulate", str(path), "-o", str(out)],
    }[command]
    assert main(argv) == 2
    _one_line_naming(capsys, path)
    assert not out.exists()


@pytest.fixture(scope="module")
def small_model(tmp_path_factory):
    return save_small_model(tmp_path_factory.mktemp("models") / "3")


def _bad_standing(folder) -> None:
    """meta.json's standing pose (generate starts from it)."""
    meta = json.loads((folder / "meta.json").read_text())
    meta["standing"] = {"joints": [0.1, 0.2], "roll_pitch": [0.0, 0.0], "origin": "data"}
    (folder / "meta.json").write_text(json.dumps(meta))


@pytest.mark.parametrize("kind", [*BROKEN_MODELS, "standing"])
def test_broken_model(tmp_path, capsys, small_model, kind):
    folder = shutil.copytree(small_model, tmp_path / "3")
    if kind == "standing":
        _bad_standing(folder)
        named = folder / "meta.json"
    else:
        named, _ = break_model(folder, kind)
    out = tmp_path / "out.h5"
    scenario = next(iter(load_params().rollout.scenarios))
    assert main(["generate", str(folder), "--scenario", scenario, "-o", str(out)]) == 2
    _one_line_naming(capsys, named)
    assert not out.exists()


def test_an_error_is_one_line_whatever_the_library_said():
    from pimann.core.errors import PimannError

    error = PimannError("model.pt", "unpickling failed:\n  line 1\n\tline 2", frame=3)
    assert str(error) == "model.pt (frame 3): unpickling failed: line 1 line 2"
