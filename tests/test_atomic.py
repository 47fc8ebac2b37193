"""Atomic outputs (pimann.core.atomic): the target appears whole or not at all."""

from __future__ import annotations

import pytest

from pimann.core.atomic import atomic_path, write_text_atomic


def _leftovers(folder):
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


def test_a_file_appears_only_when_the_body_succeeds(tmp_path):
    target = tmp_path / "deep" / "out.txt"  # missing parents are made
    with atomic_path(target) as tmp:
        assert tmp.name == "out.txt" and tmp.parent != target.parent
        tmp.write_text("partial")
        assert not target.exists()  # nothing at the target while the body runs
    assert target.read_text() == "partial"
    assert _leftovers(target.parent) == []


def test_a_failing_body_leaves_the_old_file_and_no_temporary(tmp_path):
    target = tmp_path / "out.txt"
    target.write_text("old")
    with pytest.raises(RuntimeError, match="boom"), atomic_path(target) as tmp:
        tmp.write_text("half-written")
        raise RuntimeError("boom")
    assert target.read_text() == "old"
    assert _leftovers(tmp_path) == []


def test_a_folder_replaces_the_old_folder_whole(tmp_path):
    target = tmp_path / "models"
    (target / "stale").mkdir(parents=True)
    (target / "stale" / "x").write_text("1")
    with atomic_path(target) as tmp:
        (tmp / "0").mkdir(parents=True)
        (tmp / "0" / "model.pt").write_bytes(b"\x00\x01")
    assert sorted(p.relative_to(target).as_posix() for p in target.rglob("*")) == [
        "0",
        "0/model.pt",
    ]
    assert _leftovers(tmp_path) == []


def test_a_failing_folder_body_keeps_the_old_folder(tmp_path):
    target = tmp_path / "models"
    target.mkdir()
    (target / "keep").write_text("kept")
    with pytest.raises(ValueError), atomic_path(target) as tmp:
        tmp.mkdir()
        (tmp / "new").write_text("n")
        raise ValueError
    assert [p.name for p in target.iterdir()] == ["keep"]
    assert _leftovers(tmp_path) == []


def test_write_text_atomic_overwrites(tmp_path):
    target = tmp_path / "a.md"
    write_text_atomic(target, "one\n")
    write_text_atomic(target, "two\n")
    assert target.read_text() == "two\n" and [p.name for p in tmp_path.iterdir()] == ["a.md"]
