"""What every DVC stage script shares: progress logging, the one-line error contract, the
check of the shared data it reads, and the record of its wall time."""

from __future__ import annotations

import functools
import logging
import os
import sys
import time
from collections.abc import Callable, Iterable
from pathlib import Path

from pimann.core.errors import PimannError

LOG_FORMAT = "%(asctime)s %(name)s %(message)s"
MAX_PROBLEM_LINES = 10  # a missing folder of 2,000 files is not 2,000 lines

Body = Callable[[list[str] | None], None]
Main = Callable[[list[str] | None], int]
log = logging.getLogger("stage")


def stage_entry(
    body: Body | None = None, *, reads: Iterable[str] = (), times_dir: Path | None = None
) -> Main | Callable[[Body], Main]:
    """Wrap a stage's body (`@stage_entry` or `@stage_entry(reads=(...))`): log at INFO,
    check the shared files of the data-manifest groups `reads` (pimann.core.data_check) before
    any work, turn bad input into one stderr line and exit 1, and record the wall time of a
    stage `dvc repro` runs in `times_dir` (default results/stage_times; pimann.core.stage_times).

    A stage writes its outputs atomically, so an error leaves nothing half-written.
    """
    reads = tuple(reads)

    def wrap(body: Body) -> Main:
        @functools.wraps(body)
        def main(argv: list[str] | None = None) -> int:
            logging.basicConfig(level=logging.INFO, format=LOG_FORMAT)
            started, clock = time.time(), time.perf_counter()
            try:
                from pimann.core.params import load_params

                params = load_params()  # the data check's sources and the record's profile
                problems = _data_problems(reads, params)
                if problems:
                    for line in problems[:MAX_PROBLEM_LINES]:
                        print(line, file=sys.stderr)
                    if len(problems) > MAX_PROBLEM_LINES:
                        more = len(problems) - MAX_PROBLEM_LINES
                        print(f"... and {more} more: pimann check-data lists them", file=sys.stderr)
                    return 1
                body(argv)
                _record_time(started, time.perf_counter() - clock, times_dir, params.profile)
            except PimannError as error:
                print(error, file=sys.stderr)
                return 1
            return 0

        return main

    return wrap if body is None else wrap(body)


def _data_problems(reads: tuple[str, ...], params) -> list[str]:
    if not reads:
        return []
    from pimann.core.data_check import stage_problems

    return stage_problems(reads, params)


def _record_time(started: float, wall_s: float, times_dir: Path | None, profile: str) -> None:
    """The stage's record, when DVC runs it (a run by hand is no run of the pipeline)."""
    from pimann.core.stage_times import (
        GATHERING_STAGE,
        STAGE_ENV,
        TIMES_DIR,
        stage_record,
        write_record,
    )

    stage = os.environ.get(STAGE_ENV)
    if not stage or stage == GATHERING_STAGE:
        log.info("done in %.1f s", wall_s)
        return
    from pimann.core.paths import REPO_ROOT

    record = stage_record(stage, started, wall_s, profile)
    path = write_record(times_dir or REPO_ROOT / TIMES_DIR, record)
    log.info("%s done in %.1f s (%s)", stage, wall_s, path)
