"""DVC stage `evaluate`: results/rollouts -> results/metrics.csv, metrics_summary.json,
timeseries/*.csv and claims.md (pimann.evaluate.evaluation, pimann.evaluate.claims), with the
retargeted data's own
sliding level (pimann.evaluate.data_reference) beside, and command_following.csv, .md and .png
(pimann.evaluate.command_following_benchmark)."""

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
from pimann.evaluate.evaluation import evaluate_all

log = logging.getLogger("evaluate")


@stage_entry(reads=("robot",))
def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rollouts", type=Path, default=Path("results/rollouts"))
    parser.add_argument("--results", type=Path, default=Path("results"))
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--data", type=Path, help="retargeted collection (default: features.input)")
    args = parse_stage_args(parser, argv, log)
    params = load_params()
    started = time.perf_counter()
    claims = evaluate_all(
        REPO_ROOT / args.rollouts,
        REPO_ROOT / args.results,
        params,
        cpu_workers(args.workers),
        args.data,
    )
    by_status: dict[str, list[str]] = {}
    for claim in claims:  # one line each with -v; the statements are in claims.md
        log.debug("%s %s: %s", claim.id, claim.status, claim.claim)
        by_status.setdefault(claim.status, []).append(claim.id)
    statuses = "; ".join(f"{status} {' '.join(ids)}" for status, ids in by_status.items())
    log.info("claims (%s): %s", args.results / "claims.md", statuses)
    log.info("profile %s: evaluated in %.0f s", params.profile, time.perf_counter() - started)


if __name__ == "__main__":
    sys.exit(main())
