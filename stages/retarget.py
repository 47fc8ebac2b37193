"""DVC stage `retarget`: the selected walking clips (and their mirrors) onto ergoCub.

Writes data/retargeted/walking.h5 (one group per clip, `<clip>` and `<clip>_mirror`) and
results/retarget_quality.json (SPEC 3.1 quality figures, the profile and params used).
"""

from __future__ import annotations

import functools
import json
import logging
import sys
import time
from multiprocessing import Pool

from tqdm import tqdm

from pimann.atomic import write_text_atomic
from pimann.mocap.clips import select_clips
from pimann.mocap.mirror import mirror_trajectory
from pimann.params import as_dict, load_params
from pimann.paths import REPO_ROOT
from pimann.retarget import retarget_clip
from pimann.retarget.quality import quality_report, summarize
from pimann.stage import stage_entry
from pimann.trajectory import write_collection

OUTPUT = REPO_ROOT / "data/retargeted/walking.h5"
QUALITY = REPO_ROOT / "results/retarget_quality.json"
log = logging.getLogger("retarget")


@stage_entry
def main(argv: list[str] | None = None) -> None:
    params = load_params()
    clips = select_clips(params.data)
    log.info("profile %s: %d clips, mirror %s", params.profile, len(clips), params.data.mirror)
    started = time.perf_counter()
    work = functools.partial(retarget_clip, params=params)
    with Pool(params.retarget.workers) as pool:
        results = list(
            tqdm(
                pool.imap(work, [c.path for c in clips]),
                total=len(clips),
                desc="retarget",
            )
        )
    wall = time.perf_counter() - started
    trajectories = []
    for name, trajectory, _, _ in results:
        trajectories.append((name, trajectory))
        if params.data.mirror:
            # mirror the robot trajectory in joint space, not the person: exact for
            # ergoCub (SPEC 2) and half the cost of retargeting the mirrored motion
            trajectories.append((f"{name}_mirror", mirror_trajectory(trajectory)))
    write_collection(OUTPUT, trajectories)
    quality = summarize([m for _, _, m, _ in results], sum(s for *_, s in results))
    quality["wall_seconds"] = wall
    quality["trajectories"] = len(trajectories)
    quality["duration_s"] = float(sum(t.time[-1] for _, t in trajectories))
    report = {
        "profile": params.profile,
        "params": {"data": as_dict(params.data), "retarget": as_dict(params.retarget)},
        "quality": quality,
    }
    write_text_atomic(QUALITY, json.dumps(report, indent=2) + "\n")
    log.info("wrote %s (%d trajectories) in %.0f s", OUTPUT, len(trajectories), wall)
    print(quality_report(quality))


if __name__ == "__main__":
    sys.exit(main())
