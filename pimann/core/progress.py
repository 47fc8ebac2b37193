"""Progress of a long loop, with the time left: a tqdm bar on a terminal, log lines in a file.

A DVC stage's log goes to a file, where a bar redrawn with carriage returns is unreadable and
tqdm's `disable=None` shows nothing. Off a terminal `Progress` logs a line when at least
`EVERY_FRACTION` of the work and `MIN_SECONDS` have passed since the last one (whichever comes
later), and at least every `MAX_SECONDS`; then a final line, unless the work was too short to
report on (its stage's summary line says it). Rate and time left are tqdm's own arithmetic.
"""

from __future__ import annotations

import logging
import sys
import time
from collections.abc import Callable, Iterable, Iterator
from typing import TypeVar

from tqdm import tqdm

EVERY_FRACTION = 0.1
MIN_SECONDS = 60.0
MAX_SECONDS = 300.0
LINE = "{desc}: {n_fmt}/{total_fmt} {unit}, {elapsed} elapsed, ~{remaining} left{postfix}"
FINAL = "{desc}: {n_fmt}/{total_fmt} {unit} in {elapsed}{postfix}"

log = logging.getLogger(__name__)
T = TypeVar("T")


class Progress:
    """`total` steps of work named `desc`, counted in `unit` (plural: "epochs", "runs").

    `enabled=False`: silent (e.g. all but one of several processes sharing a stage);
    `clock`: seconds, for tests.
    """

    def __init__(
        self,
        total: int,
        desc: str,
        unit: str = "steps",
        *,
        initial: int = 0,
        logger: logging.Logger | None = None,
        enabled: bool = True,
        clock: Callable[[], float] = time.monotonic,
    ):
        self.total, self.desc, self.unit, self.initial = total, desc, unit, initial
        self.n = initial
        self.postfix = ""
        self.logger = logger or log
        self.enabled = enabled
        self.clock = clock
        self.started = self.last_time = clock()
        self.last_n = initial
        self.reported = False
        self.bar = None
        if enabled and sys.stderr.isatty():
            self.bar = tqdm(total=total, initial=initial, desc=desc, unit=unit, file=sys.stderr)

    def update(self, steps: int = 1, postfix: str | None = None) -> None:
        """`steps` more done; `postfix`: the latest figures (a loss), shown after the count."""
        self.n += steps
        if postfix is not None:
            self.postfix = postfix
        if self.bar is not None:
            if postfix is not None:
                self.bar.set_postfix_str(postfix, refresh=False)
            self.bar.update(steps)
            return
        now = self.clock()
        since = now - self.last_time
        enough = self.n - self.last_n >= EVERY_FRACTION * self.total and since >= MIN_SECONDS
        if self.enabled and self.n < self.total and (enough or since >= MAX_SECONDS):
            self._log(LINE, now)
            self.last_time, self.last_n = now, self.n

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None
            return
        now = self.clock()
        if self.enabled and (self.reported or now - self.started >= MIN_SECONDS):
            self._log(FINAL, now)
        self.enabled = False  # closed: no second final line

    def _log(self, line: str, now: float) -> None:
        self.logger.info(
            tqdm.format_meter(
                self.n,
                self.total,
                now - self.started,
                prefix=self.desc,
                unit=self.unit,
                bar_format=line,
                postfix=self.postfix,
                initial=self.initial,
            )
        )
        self.reported = True

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def track(
    items: Iterable[T],
    desc: str,
    unit: str = "steps",
    *,
    total: int | None = None,
    logger: logging.Logger | None = None,
) -> Iterator[T]:
    """`items` one by one, with a `Progress` over them (`total`: default len(items))."""
    if total is None:
        total = len(items)  # type: ignore[arg-type]
    with Progress(total, desc, unit, logger=logger) as progress:
        for item in items:
            yield item
            progress.update()
