"""What a stage's log shows (pimann.core.logs): our lines, quiet libraries, -v for detail."""

from __future__ import annotations

import argparse
import logging

import pytest

from pimann.core.logs import (
    OURS,
    QUIET_LOGGERS,
    logging_levels,
    parse_stage_args,
    quiet_third_party,
    worker_logging,
)


@pytest.fixture
def restore_levels():
    names = (OURS, "stage_under_test", "", *QUIET_LOGGERS)
    saved = {name: logging.getLogger(name).level for name in names}
    yield
    for name, level in saved.items():
        logging.getLogger(name).setLevel(level)


def test_quiet_third_party_raises_only_the_libraries(restore_levels):
    logging.getLogger(OURS).setLevel(logging.INFO)
    quiet_third_party()
    assert all(logging.getLogger(n).level == logging.WARNING for n in QUIET_LOGGERS)
    assert not logging.getLogger("fontTools.subset").isEnabledFor(logging.INFO)
    assert logging.getLogger(f"{OURS}.train").isEnabledFor(logging.INFO)


@pytest.mark.parametrize("verbose", [False, True])
def test_verbose_turns_on_debug_for_ours_and_the_stage_only(restore_levels, verbose):
    stage_log = logging.getLogger("stage_under_test")
    stage_log.setLevel(logging.INFO)
    logging.getLogger(OURS).setLevel(logging.INFO)
    parser = argparse.ArgumentParser()
    parser.add_argument("--out")
    args = parse_stage_args(parser, ["--out", "x", *(["-v"] if verbose else [])], stage_log)
    assert args.out == "x" and args.verbose is verbose
    assert logging.getLogger(f"{OURS}.metrics").isEnabledFor(logging.DEBUG) is verbose
    assert stage_log.isEnabledFor(logging.DEBUG) is verbose
    assert not logging.getLogger("matplotlib.font_manager").isEnabledFor(logging.INFO)


def test_a_worker_logs_at_its_parents_levels(restore_levels):
    logging.getLogger(OURS).setLevel(logging.DEBUG)
    levels = logging_levels()
    assert levels[1] == logging.DEBUG
    logging.getLogger(OURS).setLevel(logging.WARNING)  # as a fresh process might have it
    worker_logging(levels)
    assert logging.getLogger(OURS).getEffectiveLevel() == logging.DEBUG
    assert logging.getLogger("PIL").level == logging.WARNING
