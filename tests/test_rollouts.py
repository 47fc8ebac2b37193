"""The rollouts' layout (pimann.rollouts): paths, the table's model names, and that the module
sits beside the generator, apart from the evaluation."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from pimann.errors import PimannError
from pimann.paths import REPO_ROOT
from pimann.rollouts import (
    BASELINE,
    RolloutKey,
    find_rollouts,
    parse_rollout_path,
    pi_models,
    rollout_path,
    select_rows,
    weight_label,
)

EVALUATION = ("pimann.evaluate", "pimann.claims", "pimann.claim_rules", "pimann.data_reference")


def test_rollout_paths_round_trip(tmp_path):
    key = RolloutKey("w10", 3, "turn-left", True)
    path = rollout_path(tmp_path, key)
    assert path == tmp_path / "w10" / "3" / "turn-left-steering.h5"
    assert parse_rollout_path(tmp_path, path) == key
    with pytest.raises(PimannError, match="not <model>"):
        parse_rollout_path(tmp_path, tmp_path / "w10" / "3" / "forward-maybe.h5")
    with pytest.raises(PimannError, match="holds no rollout"):
        find_rollouts(tmp_path)
    path.parent.mkdir(parents=True)
    path.touch()
    assert find_rollouts(tmp_path) == [(key, path)]


def test_table_models_and_rows():
    frame = pd.DataFrame(
        {"model": [BASELINE, "w10", "w1", "w10"], "pi_weight": [0.0, 10.0, 1.0, 10.0],
         "scenario": ["forward"] * 4, "steering": [False, False, False, True], "seed": [0] * 4}
    )  # fmt: skip
    assert pi_models(frame) == {1.0: "w1", 10.0: "w10"}
    assert weight_label(10.0) == "10" and weight_label(0.5) == "0.5"
    assert list(select_rows(frame, "forward", False, model="w10").index) == [1]


def test_rollouts_import_nothing_of_the_evaluation():
    code = "import sys, pimann.rollouts; print(sorted(m for m in sys.modules if m in %r))"
    out = subprocess.run(
        [sys.executable, "-c", code % (EVALUATION,)], capture_output=True, text=True, check=True
    )
    assert out.stdout.strip() == "[]"


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text())
    return {
        node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom) and node.module
    } | {a.name for node in ast.walk(tree) if isinstance(node, ast.Import) for a in node.names}


def test_rollout_users_import_the_layout_from_rollouts():
    users = [
        *sorted((REPO_ROOT / "pimann" / "sim").glob("*.py")),
        REPO_ROOT / "pimann" / "cli.py",
        REPO_ROOT / "stages" / "rollout.py",
        REPO_ROOT / "stages" / "simulate.py",
    ]
    for path in users:
        assert not _imports(path) & set(EVALUATION), path
    assert "pimann.rollouts" in _imports(REPO_ROOT / "pimann" / "sim" / "runs.py")
    assert "pimann.rollouts" in _imports(REPO_ROOT / "stages" / "rollout.py")
