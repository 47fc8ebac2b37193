"""DVC stage `data_report`: the retargeted collection -> results/data_report.json, .md, .png
(pimann.evaluate.data_report: composition per source and motion class, and the evaluate stage's foot
metrics applied to the data itself)."""

from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path

from pimann.core.logs import parse_stage_args
from pimann.core.parallel import cpu_workers
from pimann.core.params import load_params
from pimann.core.paths import REPO_ROOT
from pimann.core.stage import stage_entry
from pimann.evaluate.data_report import data_report
from pimann.evaluate.data_report_output import write_report

log = logging.getLogger("data_report")


@stage_entry(reads=("robot",))
def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--collection", type=Path, default=None, help="default: features.input")
    parser.add_argument("--out", type=Path, default=Path("results/data_report"))
    parser.add_argument("--workers", type=int, default=2)
    args = parse_stage_args(parser, argv, log)
    params = load_params()
    collection = REPO_ROOT / (args.collection or Path(params.features.input))
    started = time.perf_counter()
    report = data_report(collection, params, cpu_workers(args.workers))
    if collection.is_relative_to(REPO_ROOT):  # recorded as the repository's own path
        report["collection"] = str(collection.relative_to(REPO_ROOT))
    out = REPO_ROOT / args.out
    paths = [out.with_suffix(suffix) for suffix in (".json", ".md", ".png")]
    write_report(report, *paths, params.figures)
    # the table is the .md file (and the report page's section): not repeated in the log
    log.info(
        "profile %s: %s.{json,md,png} in %.0f s",
        params.profile,
        args.out,
        time.perf_counter() - started,
    )


if __name__ == "__main__":
    sys.exit(main())
