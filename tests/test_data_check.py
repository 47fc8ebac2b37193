"""Checked data (pimann.core.data_check): the real shared folder matches the committed manifest, and
on a copy of a few of its files a changed, a missing or an unlisted file is named, by the
check, by `pimann check-data` and by a stage before it runs."""

from __future__ import annotations

import ast
import dataclasses
import re
import shutil
from pathlib import Path

import pytest

from pimann.cli import main as cli
from pimann.core.data_check import (
    MANIFEST,
    MOCAP,
    Group,
    check_groups,
    format_manifest,
    read_manifest,
    stage_problems,
)
from pimann.core.errors import PimannError
from pimann.core.params import load_params
from pimann.core.paths import REPO_ROOT, shared_dir
from pimann.core.robot import MESH_DIRS, MODEL_FILES
from pimann.core.stage import stage_entry

BANDAI = "mocap:bandai_namco"


def test_the_shared_folder_matches_the_manifest():
    groups = read_manifest()
    assert check_groups(groups.values()) == []
    assert stage_problems((MOCAP, "robot", "simulation"), load_params()) == []
    sources = load_params().data.sources
    assert {f"mocap:{key}" for key in sources} | {"robot", "simulation"} == set(groups)
    paths = {entry.path for group in groups.values() for entry in group.files}
    assert {f"robots/{file}" for file in MODEL_FILES.values()} <= paths
    meshes = [p for p in paths if p.startswith(f"robots/{MESH_DIRS['simulation']}/")]
    assert len(meshes) > 50 and all(p.endswith(".stl") for p in meshes)
    bvh = {p for p in groups[BANDAI].files if p.path.endswith(".bvh")}
    labels = {p for p in groups[BANDAI].files if p.path.endswith(".json")}
    assert len(bvh) == len(labels) > 700  # every take's JSON labels beside it
    assert not [p for p in paths if p.startswith(("paper/", "SPEC", "ARCHITECTURE", "hooks/"))]


def test_write_manifest_reproduces_the_committed_one(tmp_path, capsys):
    out = tmp_path / "manifest.txt"
    assert cli(["check-data", "--write-manifest", "--manifest", str(out)]) == 0
    assert out.read_text() == MANIFEST.read_text()
    groups = read_manifest()
    count = sum(len(group.files) for group in groups.values())
    assert capsys.readouterr().out == f"{out}: {count} files in {len(groups)} groups\n"


def _copy(tmp_path: Path, names: tuple[str, ...] = ("robot", "mocap:avatargovr")) -> Path:
    """A data folder holding the files of a few groups (Bandai Namco: two takes and their
    labels), and beside it the manifest of just those files; the folder."""
    groups = read_manifest()
    subset = []
    for name in names:
        group = groups[name]
        if name == BANDAI:
            takes = [e.path for e in group.files if e.path.endswith(".bvh")][:2]
            keep = {t for t in takes} | {re.sub(r"\.bvh$", ".json", t) for t in takes}
            files = tuple(e for e in group.files if e.path in keep or "/cfg/" in e.path)
            group = dataclasses.replace(group, files=files)
        subset.append(group)
    folder = tmp_path / "shared"
    for group in subset:
        for entry in group.files:
            target = folder / entry.path
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(shared_dir() / entry.path, target)  # writable, unlike the source
    (tmp_path / "manifest.txt").write_text(format_manifest(subset))
    return folder


def _change_one_byte(path: Path) -> None:
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 1
    path.write_bytes(bytes(data))


def test_a_changed_file_is_named(tmp_path):
    folder = _copy(tmp_path, ("robot", "mocap:avatargovr", BANDAI))
    groups = read_manifest(tmp_path / "manifest.txt")
    assert check_groups(groups.values(), folder) == []
    changed = folder / "data/mocap/avatargovr/locomotion_vr_mid.bvh"
    _change_one_byte(changed)
    (problem,) = check_groups(groups.values(), folder)
    assert problem.startswith(f"{changed.resolve()}: differs from the manifest (sha256 ")


def test_missing_and_unlisted_files_are_named(tmp_path):
    folder = _copy(tmp_path, ("robot", BANDAI))
    groups = read_manifest(tmp_path / "manifest.txt")
    label = next(e.path for e in groups[BANDAI].files if e.path.endswith(".json"))
    (folder / label).unlink()
    stray = folder / Path(label).with_name("dataset-1_walk_extra_001.bvh")
    stray.write_text("HIERARCHY\n")
    problems = check_groups(groups.values(), folder)
    assert problems == [
        f"{(folder / label).resolve()}: missing",
        f"{stray.resolve()}: not in the manifest, matched by {groups[BANDAI].glob} "
        "(pimann check-data --write-manifest records it)",
    ]
    assert check_groups(groups.values(), tmp_path / "nowhere") == [
        f"{(tmp_path / 'nowhere').resolve()}: shared data folder not found (set PIMANN_SHARED "
        "or --shared)"
    ]


def test_cli_exit_code_and_one_line(tmp_path, capsys):
    folder = _copy(tmp_path)
    argv = ["check-data", "--shared", str(folder), "--manifest", str(tmp_path / "manifest.txt")]
    assert cli(argv) == 0
    assert capsys.readouterr().out.startswith("2 files in 2 groups match ")
    changed = folder / "robots" / MODEL_FILES["retarget"]
    _change_one_byte(changed)
    assert cli(argv) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    (line,) = captured.err.splitlines()
    assert line.startswith(f"pimann check-data: {changed.resolve()}: differs from the manifest")
    changed.unlink()
    assert cli(argv) == 2
    assert capsys.readouterr().err == f"pimann check-data: {changed.resolve()}: missing\n"


def test_a_stage_stops_before_its_body_on_changed_data(tmp_path, monkeypatch, capsys):
    folder = _copy(tmp_path)
    ran = []
    main = stage_entry(ran.append, reads=("robot",))
    monkeypatch.setenv("PIMANN_SHARED", str(folder))
    assert main([]) == 0 and ran == [[]]  # the copy's URDF is the committed one
    changed = folder / "robots" / MODEL_FILES["retarget"]
    _change_one_byte(changed)
    capsys.readouterr()
    assert main([]) == 1 and ran == [[]]  # the body did not run again
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith(f"{changed.resolve()}: differs from the manifest (sha256 ")


def test_a_source_the_manifest_lacks_is_refused():
    """The retarget stage reads `mocap`: every source of data.sources, as recorded."""
    params = load_params()
    avatar = params.data.sources["avatargovr"]
    sources = {
        **params.data.sources,
        "mine": avatar,
        "avatargovr": dataclasses.replace(avatar, path="data/mocap/avatargovr/*.bvh"),
    }
    own = dataclasses.replace(params, data=dataclasses.replace(params.data, sources=sources))
    problems = stage_problems((MOCAP,), own)
    assert [p.split(": ", 1)[1] for p in problems] == [
        "data.sources.avatargovr (data/mocap/avatargovr/*.bvh) is not in the manifest "
        "(pimann check-data --write-manifest records it)",
        "data.sources.mine (data/mocap/avatargovr/locomotion_vr_mid.bvh) is not in the "
        "manifest (pimann check-data --write-manifest records it)",
    ]


def test_every_stage_reads_known_groups():
    known = {MOCAP, *read_manifest()}
    declared = {}
    for script in sorted((REPO_ROOT / "stages").glob("*.py")):
        for node in ast.walk(ast.parse(script.read_text())):
            if isinstance(node, ast.Call) and getattr(node.func, "id", "") == "stage_entry":
                (keyword,) = [k for k in node.keywords if k.arg == "reads"]
                declared[script.stem] = set(ast.literal_eval(keyword.value))
    assert declared["retarget"] == {MOCAP, "robot"}
    assert "simulation" in declared["simulate"]
    assert {"train", "rollout", "evaluate", "data_report"} <= set(declared)
    assert all(reads <= known for reads in declared.values()), declared


def test_a_malformed_manifest_names_its_line(tmp_path):
    path = tmp_path / "manifest.txt"
    path.write_text(format_manifest([Group("robot", "x", ())]) + "not a line\n")
    with pytest.raises(PimannError, match=r"manifest.txt: line \d+: not"):
        read_manifest(path)
