"""DVC stage `retarget`: every source's takes, cut into clips, (and their mirrors) onto ergoCub.

Writes data/retargeted/walking.h5 (one group per clip, `<clip>` and `<clip>_mirror`) and
results/retarget_quality.json (quality figures, per-source counts, the profile and
params used).
"""

from __future__ import annotations

import functools
import json
import logging
import sys
import time
from multiprocessing import Pool

from pimann.core.atomic import write_text_atomic
from pimann.core.params import as_dict, load_params
from pimann.core.paths import REPO_ROOT
from pimann.core.progress import track
from pimann.core.stage import stage_entry
from pimann.core.trajectory import write_collection
from pimann.mocap.clips import select_takes
from pimann.mocap.mirror import mirror_trajectory
from pimann.retarget import retarget_clip
from pimann.retarget.quality import quality_report, summarize

OUTPUT = REPO_ROOT / "data/retargeted/walking.h5"
QUALITY = REPO_ROOT / "results/retarget_quality.json"
log = logging.getLogger("retarget")


def _indexed(item, work):
    """(index, result): results come back as workers finish, and are put back in order."""
    index, take = item
    return index, work(take)


@stage_entry(reads=("mocap", "robot"))
def main(argv: list[str] | None = None) -> None:
    params = load_params()
    takes = select_takes(params.data)
    log.info("profile %s: %d takes, mirror %s", params.profile, len(takes), params.data.mirror)
    started = time.perf_counter()
    work = functools.partial(_indexed, work=functools.partial(retarget_clip, params=params))
    # the longest files first, so a long take does not finish alone at the end
    order = sorted(enumerate(takes), key=lambda item: -item[1].path.stat().st_size)
    results: list[list] = [[] for _ in takes]
    with Pool(params.retarget.workers) as pool:
        done = pool.imap_unordered(work, order)
        for index, take_results in track(done, "retarget", "takes", total=len(takes), logger=log):
            results[index] = take_results
    wall = time.perf_counter() - started
    clips = [clip for take_clips in results for clip in take_clips]
    trajectories = []
    for name, trajectory, _, _ in clips:
        trajectories.append((name, trajectory))
        if params.data.mirror:
            # mirror the robot trajectory in joint space, not the person: exact for
            # ergoCub and half the cost of retargeting the mirrored motion
            trajectories.append((f"{name}_mirror", mirror_trajectory(trajectory)))
    write_collection(OUTPUT, trajectories)
    quality = summarize([m for _, _, m, _ in clips], sum(s for *_, s in clips))
    quality["wall_seconds"] = wall
    quality["trajectories"] = len(trajectories)
    quality["duration_s"] = float(sum(t.time[-1] for _, t in trajectories))
    quality["sources"] = source_counts(takes, results)
    report = {
        "profile": params.profile,
        "params": {"data": as_dict(params.data), "retarget": as_dict(params.retarget)},
        "quality": quality,
    }
    write_text_atomic(QUALITY, json.dumps(report, indent=2) + "\n")
    log.info("wrote %s (%d trajectories) in %.0f s", OUTPUT, len(trajectories), wall)
    print(quality_report(quality))
    for source, counts in quality["sources"].items():
        print("{}: {takes} takes, {clips} clips, {minutes:.1f} min".format(source, **counts))


def source_counts(takes, results) -> dict[str, dict]:
    """Takes, clips and minutes (before mirroring) of every source."""
    counts: dict[str, dict] = {}
    for take, clips in zip(takes, results, strict=True):
        entry = counts.setdefault(take.source, {"takes": 0, "clips": 0, "minutes": 0.0})
        entry["takes"] += 1
        entry["clips"] += len(clips)
        entry["minutes"] += sum(float(t.time[-1]) for _, t, _, _ in clips) / 60.0
    return counts


if __name__ == "__main__":
    sys.exit(main())
