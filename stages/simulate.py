"""DVC stage `simulate`: chosen rollouts walked by ergoCub in MuJoCo (both controllers).

    python stages/simulate.py [--rollouts results/rollouts] [--out results/sim]
                              [--summary results/sim_summary.json]

runs every rollout of `simulate.runs` (params.yaml) through footsteps -> DCM plan (offline)
or the centroidal MPC replanned as it walks (online) -> whole-body IK + ZMP-CoM feedback ->
MuJoCo and writes results/sim/<run>.h5, a video of the runs marked `video`, the push-recovery
study of `simulate.pushes`, and the per-run summary (layout: pimann.sim.run_list).
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path

import pimann.sim  # noqa: F401 -- picks MuJoCo's headless GL backend before mujoco loads
from pimann.core.logs import parse_stage_args
from pimann.core.params import load_params
from pimann.core.paths import REPO_ROOT
from pimann.core.stage import stage_entry
from pimann.sim.run_list import simulate_runs

log = logging.getLogger("simulate")


@stage_entry(reads=("robot", "simulation"))
def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rollouts", type=Path, default=Path("results/rollouts"))
    parser.add_argument("--out", type=Path, default=Path("results/sim"))
    parser.add_argument("--summary", type=Path, default=Path("results/sim_summary.json"))
    args = parse_stage_args(parser, argv, log)
    params = load_params()
    started = time.perf_counter()
    record = simulate_runs(
        REPO_ROOT / args.rollouts, REPO_ROOT / args.out, REPO_ROOT / args.summary, params
    )
    log.info(
        "profile %s: %d runs -> %s in %.0f s",
        params.profile,
        len(record["runs"]),
        args.out,
        time.perf_counter() - started,
    )


if __name__ == "__main__":
    sys.exit(main())
