"""DVC stage `features_adherent`: data/retargeted/walking.h5 -> data/features/adherent.h5.

The ADHERENT baseline's samples (pimann.learn.adherent: ground-projected base positions,
facing directions and base velocities over the window, joints and joint velocities; outputs
their future samples, the next joints and velocities and the SE(2) twist), with the split (by
source clip), the time-reversed training clips and the statistics of the `features` stage.
"""

from __future__ import annotations

import logging
import sys
from pathlib import Path

from pimann.core.params import load_params
from pimann.core.paths import REPO_ROOT
from pimann.core.robot import load_robot
from pimann.core.stage import stage_entry
from pimann.core.trajectory import iter_collection
from pimann.learn.adherent import build_adherent_dataset
from pimann.learn.dataset import write_dataset

log = logging.getLogger("features_adherent")

OUTPUT = "adherent.h5"  # in features.output_dir


@stage_entry(reads=("robot",))
def main(argv: list[str] | None = None) -> None:
    params = load_params().features
    source = REPO_ROOT / params.input
    clips = list(iter_collection(source))
    log.info("%d clips from %s, window %s", len(clips), source, params.window)
    dataset = build_adherent_dataset(clips, params, load_robot("retarget"))
    path = REPO_ROOT / Path(params.output_dir) / OUTPUT
    write_dataset(path, dataset)  # type: ignore[arg-type]
    log.info(
        "adherent: %d train samples (%d clips), %d test samples (%d clips) -> %s",
        len(dataset.x_train),
        len(dataset.train_clips),
        len(dataset.x_test),
        len(dataset.test_clips),
        path,
    )


if __name__ == "__main__":
    sys.exit(main())
