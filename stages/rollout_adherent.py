"""DVC stage `rollout_adherent`: the ADHERENT baseline's rollouts, as its own generator.

    python stages/rollout_adherent.py --models models/adherent --out results/rollouts/adherent

rolls out every seed in every script of pimann.generate.rollouts.rollout_scripts (the named
scenarios and the benchmark clips) and each protocol of `rollout.protocols`, without steering
(ADHERENT has none), the past base velocities `rollout.adherent_past_velocity` (`twist`: its
predicted twist fed back, as its python generator does; `zeros`: BLF's MANNAutoregressive), into
<out>/<seed>/<scenario>-nosteering.h5, and records the models' meta in <out>/models.json
(pimann.generate.adherent_rollout).
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
from pimann.generate.adherent_rollout import run_adherent_rollouts

log = logging.getLogger("rollout_adherent")


@stage_entry(reads=("robot",))
def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--models", type=Path, required=True, help="a training output folder")
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--workers", type=int, default=2)
    args = parse_stage_args(parser, argv, log)
    params = load_params()
    started = time.perf_counter()
    written = run_adherent_rollouts(
        REPO_ROOT / args.models, REPO_ROOT / args.out, params, cpu_workers(args.workers)
    )
    log.info(
        "profile %s, past velocities %s: %d rollouts -> %s in %.0f s",
        params.profile,
        params.rollout.adherent_past_velocity,
        len(written),
        args.out,
        time.perf_counter() - started,
    )


if __name__ == "__main__":
    sys.exit(main())
