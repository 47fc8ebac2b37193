"""What a stage's or the CLI's log shows: the study's own lines, third-party loggers kept quiet,
detail (per epoch, per item) at DEBUG behind -v, and spawned workers logging like their parent.

Not in pimann.core.stage: that module is a dependency of the retarget stage, and editing it would
rerun the whole pipeline.
"""

from __future__ import annotations

import argparse
import logging

from pimann.core.stage import LOG_FORMAT

# libraries that log their internals at INFO: fontTools prints ~900 lines subsetting the fonts
# of the figures' PDFs, matplotlib's font manager a line per font lookup or cache rebuild
QUIET_LOGGERS = ("fontTools", "matplotlib", "PIL")
OURS = "pimann"  # the library's loggers


def quiet_third_party(level: int = logging.WARNING) -> None:
    """Raise the third-party loggers of `QUIET_LOGGERS` to `level`; ours stay at INFO."""
    for name in QUIET_LOGGERS:
        logging.getLogger(name).setLevel(level)


def parse_stage_args(
    parser: argparse.ArgumentParser, argv: list[str] | None, stage_log: logging.Logger
) -> argparse.Namespace:
    """A stage's arguments, with its -v (per-epoch and per-item lines, DEBUG) added, and its
    log set up: third-party loggers quiet; under -v, DEBUG for pimann's loggers and the
    stage's own, not the libraries'."""
    parser.add_argument(
        "-v", "--verbose", action="store_true", help="log per-epoch and per-item detail too"
    )
    args = parser.parse_args(argv)
    quiet_third_party()
    if args.verbose:
        for logger in (logging.getLogger(OURS), stage_log):
            logger.setLevel(logging.DEBUG)
    return args


def logging_levels() -> tuple[int, int]:
    """(root level, pimann's effective level) of this process, for `worker_logging`."""
    return logging.getLogger().level, logging.getLogger(OURS).getEffectiveLevel()


def worker_logging(levels: tuple[int, int]) -> None:
    """A spawned worker's logging, as its parent's (`logging_levels`): a spawned process starts
    unconfigured and would drop every INFO line."""
    root, ours = levels
    logging.basicConfig(level=root, format=LOG_FORMAT)
    logging.getLogger(OURS).setLevel(ours)
    quiet_third_party()
