"""DVC stage `report`: results/ and paper_figures/ -> results/metrics.json (the study's key
numbers, the pipeline's DVC metrics; pimann.report.key_metrics) and results/report.html (the study
on one self-contained page; pimann.report.page); README.md's results block from metrics.json
(pimann.report.readme_results)."""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from pathlib import Path

from pimann.core.logs import parse_stage_args
from pimann.core.params import load_params
from pimann.core.paths import REPO_ROOT
from pimann.core.stage import stage_entry
from pimann.report.page import write_report
from pimann.report.readme_results import write_readme_results

log = logging.getLogger("report")


@stage_entry
def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--results", type=Path, default=Path("results"))
    parser.add_argument("--figures", type=Path, default=Path("paper_figures"))
    args = parse_stage_args(parser, argv, log)
    started = time.perf_counter()
    metrics, report = write_report(
        REPO_ROOT / args.results, REPO_ROOT / args.figures, load_params()
    )
    # README.md's results block (tracked by git, so a side effect, not a DVC out); a copy of
    # the pipeline without the README (a worker's clone of the stages) has none to rewrite
    readme = REPO_ROOT / "README.md"
    if readme.exists():
        write_readme_results(readme, json.loads(metrics.read_text()))
    else:
        log.warning("no %s: its results block is not rewritten", readme)
    log.info(
        "%s, %s (%.1f MB) in %.1f s",
        metrics,
        report,
        report.stat().st_size / 1e6,
        time.perf_counter() - started,
    )


if __name__ == "__main__":
    sys.exit(main())
