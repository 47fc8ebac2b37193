"""Every benchmark's smoke mode runs in-process on the real parts and prints its table.

The benchmarks are found by listing benchmarks/*.py, so a new one is covered without an
edit here; each must offer `main(argv) -> int` and a `--smoke` flag (tiny sizes, seconds).
"""

from __future__ import annotations

import importlib
from pathlib import Path

import pytest
import torch

from pimann.core.params import load_params
from pimann.core.paths import shared_glob

REPO = Path(__file__).resolve().parents[1]
BENCHMARKS = sorted(
    p.stem for p in (REPO / "benchmarks").glob("*.py") if not p.stem.startswith("_")
)


def _mocap_absent() -> str | None:
    """Why the retargeting benchmark cannot run here (no motion capture files), or None."""
    sources = load_params().data.sources
    missing = [key for key, source in sources.items() if not shared_glob(source.path)]
    return f"no motion capture files for data.sources {missing}" if missing else None


# what a benchmark needs beyond the repository and the robot model: why it is absent, or None
NEEDS = {"retarget_speed": _mocap_absent}


def test_every_benchmark_is_found():
    assert {"generate_speed", "metrics_speed", "sim_speed", "train_step"} <= set(BENCHMARKS)


@pytest.mark.parametrize("name", BENCHMARKS)
def test_smoke_mode_runs(name, capsys, monkeypatch):
    absent = NEEDS[name]() if name in NEEDS else None
    if absent:
        pytest.skip(absent)
    monkeypatch.syspath_prepend(str(REPO))  # `benchmarks` also when run as plain `pytest`
    threads = torch.get_num_threads()  # a benchmark sets its own; the other tests keep theirs
    try:
        module = importlib.import_module(f"benchmarks.{name}")
        assert module.main(["--smoke"]) == 0
    finally:
        torch.set_num_threads(threads)
    out = capsys.readouterr().out
    lines = [line for line in out.splitlines() if line.strip()]
    assert len(lines) >= 2, out
    assert any(any(c.isdigit() for c in line) for line in lines), out
