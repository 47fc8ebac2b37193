"""DVC stage `figures`: results/ -> paper_figures/*.pdf|png (pimann.figures), nothing else read."""

from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path

from pimann.figures import make_figures
from pimann.logs import add_verbose, quiet_third_party, set_verbose
from pimann.params import load_params
from pimann.paths import REPO_ROOT
from pimann.stage import stage_entry

log = logging.getLogger("figures")


@stage_entry
def main(argv: list[str] | None = None) -> None:
    quiet_third_party()
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--results", type=Path, default=Path("results"))
    parser.add_argument("--out", type=Path, default=Path("paper_figures"))
    add_verbose(parser)
    args = parser.parse_args(argv)
    set_verbose(args.verbose, log)
    started = time.perf_counter()
    written = make_figures(REPO_ROOT / args.results, REPO_ROOT / args.out, load_params().figures)
    log.info("%d figures -> %s in %.1f s", len(written), args.out, time.perf_counter() - started)


if __name__ == "__main__":
    sys.exit(main())
