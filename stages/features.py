"""DVC stage `features`: data/retargeted/walking.h5 -> data/features/{full,ground_projected}.h5.

`full` feeds the physics-informed models, `ground_projected` (roll and pitch of the base set
to 0) the ADHERENT-style baseline. Both share the split (by source clip) and the windows.
"""

from __future__ import annotations

import logging
import sys
from pathlib import Path

from pimann.core.params import load_params
from pimann.core.paths import REPO_ROOT
from pimann.core.stage import stage_entry
from pimann.core.trajectory import iter_collection
from pimann.learn.dataset import write_dataset
from pimann.learn.feature_layout import VARIANTS
from pimann.learn.features import build_dataset

log = logging.getLogger("features")


@stage_entry
def main(argv: list[str] | None = None) -> None:
    params = load_params().features
    source = REPO_ROOT / params.input
    clips = list(iter_collection(source))
    log.info("%d clips from %s, window %s", len(clips), source, params.window)
    for variant in VARIANTS:
        dataset = build_dataset(clips, params, variant)
        path = REPO_ROOT / Path(params.output_dir) / f"{variant}.h5"
        write_dataset(path, dataset)
        log.info(
            "%s: %d train samples (%d clips), %d test samples (%d clips) -> %s",
            variant,
            len(dataset.x_train),
            len(dataset.train_clips),
            len(dataset.x_test),
            len(dataset.test_clips),
            path,
        )


if __name__ == "__main__":
    sys.exit(main())
