"""DVC stage `train_adherent`: the ADHERENT baseline's seeds on data/features/adherent.h5.

    python stages/train_adherent.py --out models/adherent --plots results/training/adherent [-v]

trains the seeds `train.seeds` as one vectorised ensemble (pimann.learn.adherent_train: no physics
term) and writes <out>/<seed>/{model.pt,meta.json} and <plots>/seed<seed>.csv.
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path

import torch

from pimann.core.logs import parse_stage_args
from pimann.core.parallel import training_threads
from pimann.core.params import load_params
from pimann.core.paths import REPO_ROOT
from pimann.core.stage import stage_entry
from pimann.learn.adherent_train import train_adherent

log = logging.getLogger("train_adherent")

DATASET = "adherent.h5"  # in features.output_dir (stages/features_adherent.py)


@stage_entry
def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--plots", type=Path, required=True)
    args = parse_stage_args(parser, argv, log)
    params = load_params()
    dataset = REPO_ROOT / params.features.output_dir / DATASET
    threads = training_threads(params.train.threads)
    torch.set_num_threads(threads)
    log.info(
        "profile %s: adherent, seeds %s, %d epochs, %d thread(s), data %s",
        params.profile,
        params.train.seeds,
        params.train.epochs,
        threads,
        dataset,
    )
    started = time.perf_counter()
    metas = train_adherent(
        dataset, REPO_ROOT / args.out, params.train.seeds, params, REPO_ROOT / args.plots
    )
    best = ", ".join(
        f"{seed}: {m['best_epoch']} ({m['best_test_loss']:.5f})" for seed, m in metas.items()
    )
    log.info(
        "trained in %.0f s; best epoch (test loss) of seed %s", time.perf_counter() - started, best
    )


if __name__ == "__main__":
    sys.exit(main())
