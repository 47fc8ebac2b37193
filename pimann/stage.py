"""What every DVC stage script shares: progress logging, the one-line error contract and the
check of the shared data it reads."""

from __future__ import annotations

import functools
import logging
import sys
from collections.abc import Callable, Iterable

from pimann.errors import PimannError

LOG_FORMAT = "%(asctime)s %(name)s %(message)s"
MAX_PROBLEM_LINES = 10  # a missing folder of 2,000 files is not 2,000 lines

Body = Callable[[list[str] | None], None]
Main = Callable[[list[str] | None], int]


def stage_entry(
    body: Body | None = None, *, reads: Iterable[str] = ()
) -> Main | Callable[[Body], Main]:
    """Wrap a stage's body (`@stage_entry` or `@stage_entry(reads=(...))`): log at INFO,
    check the shared files of the data-manifest groups `reads` (pimann.data_check) before
    any work, turn bad input into one stderr line and exit 1.

    A stage writes its outputs atomically, so an error leaves nothing half-written.
    """
    reads = tuple(reads)

    def wrap(body: Body) -> Main:
        @functools.wraps(body)
        def main(argv: list[str] | None = None) -> int:
            logging.basicConfig(level=logging.INFO, format=LOG_FORMAT)
            try:
                problems = _data_problems(reads)
                if problems:
                    for line in problems[:MAX_PROBLEM_LINES]:
                        print(line, file=sys.stderr)
                    if len(problems) > MAX_PROBLEM_LINES:
                        more = len(problems) - MAX_PROBLEM_LINES
                        print(f"... and {more} more: pimann check-data lists them", file=sys.stderr)
                    return 1
                body(argv)
            except PimannError as error:
                print(error, file=sys.stderr)
                return 1
            return 0

        return main

    return wrap if body is None else wrap(body)


def _data_problems(reads: tuple[str, ...]) -> list[str]:
    if not reads:
        return []
    from pimann.data_check import stage_problems

    return stage_problems(reads)
