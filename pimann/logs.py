"""Third-party loggers kept quiet, so that a stage's or the CLI's log is the study's own.

Not in pimann.stage: that module is a dependency of the retarget stage, and editing it would
rerun the whole pipeline.
"""

from __future__ import annotations

import logging

# libraries that log their internals at INFO: fontTools prints ~900 lines subsetting the fonts
# of the figures' PDFs, matplotlib's font manager a line per font lookup or cache rebuild
QUIET_LOGGERS = ("fontTools", "matplotlib", "PIL")


def quiet_third_party(level: int = logging.WARNING) -> None:
    """Raise the third-party loggers of `QUIET_LOGGERS` to `level`; ours stay at INFO."""
    for name in QUIET_LOGGERS:
        logging.getLogger(name).setLevel(level)
