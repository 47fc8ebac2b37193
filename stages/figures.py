"""DVC stage `figures`: results/ -> paper_figures/*.pdf|png (pimann.report.figures), nothing else
read."""

from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path

from pimann.core.logs import parse_stage_args
from pimann.core.params import load_params
from pimann.core.paths import REPO_ROOT
from pimann.core.stage import stage_entry
from pimann.report.figures import make_figures

log = logging.getLogger("figures")


@stage_entry
def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--results", type=Path, default=Path("results"))
    parser.add_argument("--out", type=Path, default=Path("paper_figures"))
    args = parse_stage_args(parser, argv, log)
    started = time.perf_counter()
    params = load_params()
    written = make_figures(
        REPO_ROOT / args.results, REPO_ROOT / args.out, params.figures, params.evaluate
    )
    log.info("%d figures -> %s in %.1f s", len(written), args.out, time.perf_counter() - started)


if __name__ == "__main__":
    sys.exit(main())
