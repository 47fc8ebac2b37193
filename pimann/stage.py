"""What every DVC stage script shares: progress logging and the one-line error contract."""

from __future__ import annotations

import functools
import logging
import sys
from collections.abc import Callable

from pimann.errors import PimannError

LOG_FORMAT = "%(asctime)s %(name)s %(message)s"


def stage_entry(body: Callable[[list[str] | None], None]) -> Callable[[list[str] | None], int]:
    """Wrap a stage's body: log at INFO, turn bad input into one stderr line and exit 1.

    A stage writes its outputs atomically, so an error leaves nothing half-written.
    """

    @functools.wraps(body)
    def main(argv: list[str] | None = None) -> int:
        logging.basicConfig(level=logging.INFO, format=LOG_FORMAT)
        try:
            body(argv)
        except PimannError as error:
            print(error, file=sys.stderr)
            return 1
        return 0

    return main
