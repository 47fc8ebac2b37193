"""DVC stage `rollout` (one training output) and `rollout_baseline`.

    python stages/rollout.py --models models/w10 --out results/rollouts/w10 [--workers 2]

rolls out every seed of the training output in every scenario of `rollout.scenario_names`
and (`rollout.benchmark_clips`) every test clip's command-following script (clip_<clip name>)
and (`rollout.benchmark_train_clips`) a few training clips' (train_<clip name>), with and
without steering, into <out>/<seed>/<scenario>-<steering|nosteering>.h5, beside them the
contact-consistent variants <scenario>+post and <scenario>+loop of rollout.consistent
(docs/consistent.md), and records the models' meta in <out>/models.json (layout:
pimann.core.rollout_files).
"""

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
from pimann.generate.rollouts import run_rollouts

log = logging.getLogger("rollout")


@stage_entry(reads=("robot",))
def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--models", type=Path, required=True, help="a training output folder")
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--workers", type=int, default=2)
    args = parse_stage_args(parser, argv, log)
    params = load_params()
    started = time.perf_counter()
    written = run_rollouts(
        REPO_ROOT / args.models, REPO_ROOT / args.out, params, cpu_workers(args.workers)
    )
    log.info(
        "profile %s: %d rollouts -> %s in %.0f s",
        params.profile,
        len(written),
        args.out,
        time.perf_counter() - started,
    )


if __name__ == "__main__":
    sys.exit(main())
