"""DVC stage `train` (one PI weight, every seed) and `train_baseline`.

    python stages/train.py --pi-weight 10 --variant full --out models/w10 \
        --plots results/training/w10 [-v]

trains the seeds `train.seeds` of one weight as one vectorised ensemble and writes
<out>/<seed>/{model.pt,meta.json} and <plots>/seed<seed>.csv. On a CUDA device the first
weight's stage trains every weight of `train.pi_weights` at once (pimann.learn.sweep) and
each stage writes its own weight's models out of that sweep. An interrupted run resumes from
its per-epoch checkpoint in <out's parent>/.checkpoints/<out's name>/. The log names the run
after <out> (w10, baseline): its progress over the epochs, and with -v every epoch's losses.
"""

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
from pimann.learn.feature_layout import VARIANTS
from pimann.learn.sweep import train_from_sweep, uses_sweep
from pimann.learn.train import pick_device, train_models

log = logging.getLogger("train")


@stage_entry(reads=("robot",))
def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pi-weight", type=float, required=True)
    parser.add_argument("--variant", choices=VARIANTS, default="full")
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--plots", type=Path, required=True)
    args = parse_stage_args(parser, argv, log)
    params = load_params()
    dataset = REPO_ROOT / params.features.output_dir / f"{args.variant}.h5"
    device = pick_device(params.train.device)
    log.info(
        "profile %s: %s, w=%g, seeds %s, %d epochs on %s, data %s",
        params.profile,
        args.out.name,
        args.pi_weight,
        params.train.seeds,
        params.train.epochs,
        device,
        dataset,
    )
    started = time.perf_counter()
    if uses_sweep(device):
        in_sweep = args.variant == "full" and args.pi_weight in params.train.pi_weights
        sweep = params.train.pi_weights if in_sweep else [args.pi_weight]
        metas = train_from_sweep(
            dataset,
            REPO_ROOT / args.out,
            args.pi_weight,
            sweep,
            params,
            device,
            plots_dir=REPO_ROOT / args.plots,
        )
    else:
        metas = train_models(
            dataset,
            REPO_ROOT / args.out,
            args.pi_weight,
            params.train.seeds,
            params,
            device,
            plots_dir=REPO_ROOT / args.plots,
        )
    best = ", ".join(
        f"{seed}: {meta['best_epoch']} ({meta['best_test_loss']:.5f})"
        for seed, meta in metas.items()
    )
    log.info(
        "trained in %.0f s; best epoch (test loss) of seed %s", time.perf_counter() - started, best
    )


if __name__ == "__main__":
    sys.exit(main())
