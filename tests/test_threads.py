"""Training threads from the free cores, PIMANN_THREADS over train.threads, bad values named."""

from __future__ import annotations

import os

import pytest
import yaml

from pimann.core.errors import PimannError
from pimann.core.parallel import (
    THREADS_ENV,
    busy_cores,
    cpu_workers,
    free_cores,
    training_threads,
    usable_cores,
)
from pimann.core.params import load_params


def test_free_cores_leave_the_busy_ones_and_keep_one():
    assert free_cores(8, 3) == 5
    assert free_cores(2, 1) == 1
    assert free_cores(2, 5) == 1  # an overloaded machine still trains


def test_busy_cores_read_the_kernel_runnable_count(tmp_path):
    loadavg = tmp_path / "loadavg"
    loadavg.write_text("1.50 1.20 0.90 3/612 4242\n")
    assert busy_cores(loadavg) == 2  # three running, this one among them
    loadavg.write_text("garbage\n")
    assert busy_cores(loadavg) == 0
    assert busy_cores(tmp_path / "absent") == 0


def test_threads_from_the_environment_the_setting_or_the_free_cores(monkeypatch):
    monkeypatch.delenv(THREADS_ENV, raising=False)
    assert training_threads(3) == 3
    assert 1 <= training_threads("auto") <= usable_cores()
    if hasattr(os, "sched_getaffinity"):
        assert usable_cores() == len(os.sched_getaffinity(0))
    assert cpu_workers(10_000) == usable_cores()
    monkeypatch.setenv(THREADS_ENV, "1")
    assert training_threads("auto") == 1 and training_threads(4) == 1
    for bad in ("0", "two", "-1"):
        monkeypatch.setenv(THREADS_ENV, bad)
        with pytest.raises(PimannError, match=THREADS_ENV):
            training_threads("auto")


def test_params_name_a_bad_precision_or_thread_count(tmp_path):
    raw = yaml.safe_load(load_params.__globals__["DEFAULT_PARAMS"].read_text())
    for key, value, problem in (
        ("precision", "half", "train.precision must be one of"),
        ("threads", 0, "train.threads"),
    ):
        changed = {**raw, "train": {**raw["train"], key: value}}
        path = tmp_path / "params.yaml"
        path.write_text(yaml.safe_dump(changed))
        with pytest.raises(PimannError, match=problem) as error:
            load_params(path)
        assert str(path) in str(error.value)
