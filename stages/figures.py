"""DVC stage `figures`: results/ -> paper_figures/*.pdf|png (pimann.figures), nothing else read."""

from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path

from pimann.errors import PimannError
from pimann.figures import make_figures
from pimann.params import load_params
from pimann.paths import REPO_ROOT

log = logging.getLogger("figures")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--results", type=Path, default=Path("results"))
    parser.add_argument("--out", type=Path, default=Path("paper_figures"))
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(message)s")
    try:
        started = time.perf_counter()
        written = make_figures(
            REPO_ROOT / args.results, REPO_ROOT / args.out, load_params().figures
        )
        log.info("%d figures in %.1f s", len(written), time.perf_counter() - started)
    except PimannError as error:
        print(error, file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
