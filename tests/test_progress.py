"""Progress and log volume off a terminal (a DVC stage's log file): a few lines with the time
left, per-epoch and per-item lines only at DEBUG, spawned workers logging like their parent."""

from __future__ import annotations

import dataclasses
import logging
import re

import pytest
from builders import SMALL_MODEL, synthetic_collection

from pimann.core.parallel import pool_map
from pimann.core.params import load_params
from pimann.core.progress import MAX_SECONDS, Progress, track
from pimann.learn.dataset import write_dataset
from pimann.learn.features import build_dataset
from pimann.learn.train import train_models

LOGGER = "pimann.test_progress"


class Clock:
    """Seconds that advance by `step` at each reading: a loop of known duration, instantly."""

    def __init__(self, step: float):
        self.now, self.step = 0.0, step

    def __call__(self) -> float:
        self.now += self.step
        return self.now


def _run(steps: int, seconds_per_step: float, caplog) -> list[str]:
    caplog.clear()
    with caplog.at_level(logging.INFO, logger=LOGGER):
        progress = Progress(
            steps, "work", "steps", logger=logging.getLogger(LOGGER), clock=Clock(seconds_per_step)
        )
        for k in range(steps):
            progress.update(postfix=f"loss {1.0 / (k + 1):.3f}")
        progress.close()
    return [r.getMessage() for r in caplog.records if r.name == LOGGER]


def test_a_long_loop_logs_a_few_lines_with_the_time_left(caplog, capsys):
    lines = _run(1000, 1.0, caplog)  # 1000 steps, ~17 minutes
    assert 5 <= len(lines) <= 12, lines
    *progress, final = lines
    for line in progress:
        assert re.match(r"work: \d+/1000 steps, [\d:]+ elapsed, ~[\d:]+ left, loss ", line), line
    assert final.startswith("work: 1000/1000 steps in ") and "left" not in final
    # the time left shrinks, and matches the rate: at 100 s per 100 steps, 1 s per step
    left = [re.search(r"~([\d:]+) left", line).group(1) for line in progress]
    seconds = [int(m) * 60 + int(s) for m, s in (t.split(":") for t in left)]
    assert seconds == sorted(seconds, reverse=True)
    done = int(re.match(r"work: (\d+)/", progress[0]).group(1))
    assert seconds[0] == pytest.approx(1000 - done, abs=3)
    assert capsys.readouterr().err == ""  # no bar off a terminal


def test_a_short_loop_leaves_it_to_the_stage_summary(caplog):
    assert _run(1000, 0.01, caplog) == []  # 10 s: nothing


def test_a_slow_loop_still_reports_every_few_minutes(caplog):
    lines = _run(20, MAX_SECONDS / 2, caplog)  # 10 % = 2 steps = MAX_SECONDS
    assert len(lines) == 10  # every 2 steps, then the final line
    lines = _run(100, 150.0, caplog)  # 10 % = 25 minutes: a line every MAX_SECONDS instead
    assert len(lines) == 100 * 150 // MAX_SECONDS


def test_track_counts_every_item_even_when_the_loop_breaks(caplog):
    caplog.set_level(logging.INFO, logger=LOGGER)
    items = track(range(10), "items", "items", logger=logging.getLogger(LOGGER))
    for k in items:
        if k == 4:
            break
    items.close()
    assert caplog.records == []  # short: no line, and no error closing early


def test_spawned_workers_log_like_their_parent(caplog, capfd):
    caplog.set_level(logging.INFO)
    worker_log = logging.getLogger("pimann.worker").info  # picklable: a logger by its name
    assert pool_map(worker_log, ["job a", "job b"], 2, None) == [None, None]
    err = capfd.readouterr().err
    assert "pimann.worker job a" in err and "pimann.worker job b" in err


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """A tiny dataset and params for 4 epochs of 2 seeds in this process (caplog sees it)."""
    base = load_params()
    train = dataclasses.replace(base.train, epochs=4, batch_size=64, device="cpu", workers=1)
    params = dataclasses.replace(base, model=SMALL_MODEL, train=train)
    dataset = build_dataset(synthetic_collection(n_sources=4, frames=160), params.features, "full")
    path = tmp_path_factory.mktemp("features") / "full.h5"
    write_dataset(path, dataset)
    return params, path


@pytest.mark.parametrize("level", [logging.INFO, logging.DEBUG])
def test_training_logs_epochs_only_at_debug(tmp_path, tiny, caplog, level):
    params, path = tiny
    caplog.set_level(level, logger="pimann")
    train_models(path, tmp_path / "baseline", 0.0, [0, 1], params, "cpu")
    lines = [r.getMessage() for r in caplog.records if r.name == "pimann.learn.train"]
    epochs = [line for line in lines if " epoch " in line]
    if level == logging.INFO:
        assert len(lines) <= 2 and not epochs, lines
        assert lines[0].startswith("baseline (w=0, full data")  # named after its output
    else:
        assert [re.search(r"epoch (\d+)/4", line).group(1) for line in epochs] == list("1234")
