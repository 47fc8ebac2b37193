"""The data's own level of the sliding metrics: the retargeted clips the models learn from,
measured as the rollouts are (the evaluate stage writes it into metrics_summary.json).

For each clip of the collection (`features.input`): the per-frame RMS of every sliding metric
of pimann.evaluate.metrics (`SLIDING`: both levels, both representations), masked by contact with
the evaluate rule (the Schmitt trigger on the lowest sole corner, never the file's own contacts),
averaged over the two feet, summed over the clip's forward-walking frames
(pimann.learn.motion_classes) and scaled to `FRAMES` frames (the paper's 10 s at 50 Hz): the total
RMSE a 10 s forward rollout as good as the clip would score. The level is the median over the
clips with at least `MIN_FORWARD_FRAMES` forward frames, over all clips and over the test clips
(the features stage's split by source clip, a clip and its mirror together).

The data's gait (pimann.evaluate.gait, `gait`): windows of its forward walking, the originals
only (a mirror steps as its clip does), each with its speed, and the level by speed.

Beside them, where in a stance the data slides (pimann.evaluate.sliding: the shares of the
linear sums just after touchdown, mid-stance and before lift-off, over the same forward frames).

The retargeted data carries no joint velocities: the authors' metric takes the joints' first
differences ((s_i - s_{i-1}) / dt, as their features do), our velocity level their central
differences (and the base that holds the lower foot still), the position level the base's and
the joints' differences alike.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from pimann.core.parallel import pool_map
from pimann.core.params import ContactParams, EvaluateParams, Params
from pimann.core.robot import load_robot
from pimann.core.trajectory import Trajectory, iter_collection
from pimann.evaluate.gait import data_gait_windows, gait_reference
from pimann.evaluate.metrics import PAPER_SLIDING, SLIDING, aggregate, analyse
from pimann.evaluate.sliding import PHASES, SHARE_METRICS, phase_share_metrics
from pimann.learn.features import split_sources
from pimann.learn.motion_classes import CLASSES, motion_classes

FRAMES = 500  # the paper's test: 10 s at 50 Hz
MIN_FORWARD_FRAMES = 250  # a clip counts with at least 5 s of forward walking at 50 Hz
LABEL = "data (retargeted, forward walking)"
METRICS = (
    [f"support_rmse_{name}_total" for name in SLIDING]
    + [f"support_rmse_{name}_{phase}_share" for name in SHARE_METRICS for phase in PHASES]
    + [f"contact_{phase}_frames_share" for phase in PHASES]
)


def clip_reference(
    trajectory: Trajectory, params: EvaluateParams, contacts: ContactParams
) -> dict[str, Any]:
    """One clip: its forward frames and every sliding total over them, per `FRAMES` frames."""
    robot = load_robot("retarget")
    a = analyse(trajectory, robot, params, contacts, file_contacts=False)  # one pass, both uses
    sliding = {name: np.where(a.contacts_of(name), a.rms(name), 0.0) for name in SLIDING}
    classes = motion_classes(trajectory)
    forward = np.asarray(CLASSES)[classes] == "forward"
    row: dict[str, Any] = {
        "frames": len(forward),
        "forward_frames": int(forward.sum()),
        "joint_velocities": trajectory.joint_velocities is not None,
    }
    stepped = forward.copy()
    stepped[0] = False  # the authors' metric has no step into frame 0
    for name in SLIDING:
        per_frame = sliding[name].mean(axis=1)  # the frame's share of the left-right mean
        counted = stepped if name in PAPER_SLIDING else forward
        value = FRAMES * float(per_frame[counted].mean()) if counted.any() else None
        row[f"support_rmse_{name}_total"] = value
    rms = {name: sliding[name] for name in SHARE_METRICS}
    row.update(phase_share_metrics(rms, a.contacts, trajectory.rate_hz, forward))
    row["gait_windows"] = []  # a mirror steps as its clip does: counted once
    if not trajectory.attrs.get("mirrored", False):
        row["gait_windows"] = data_gait_windows(
            a.time,
            classes,
            a.feet.heights,
            a.feet.positions,
            a.feet.pitches,
            a.sole_velocities["contact_point"],
            a.displacement[:, :2],
            params,
            contacts,
            contacts=a.contacts,  # the rule's: file_contacts is off
        )
    return row


def _job(job: tuple[Trajectory, EvaluateParams, ContactParams]) -> dict[str, Any]:
    return clip_reference(*job)


def _subset(rows: list[dict[str, Any]]) -> dict[str, Any]:
    used = [r for r in rows if r["forward_frames"] >= MIN_FORWARD_FRAMES]
    return {
        "clips": len(rows),
        "used": len(used),
        "forward_frames": sum(r["forward_frames"] for r in used),
        "metrics": aggregate([{m: r[m] for m in METRICS} for r in used]),
    }


def data_reference(
    collection: str | Path, params: Params, workers: int = 1, name: str | None = None
) -> dict[str, Any]:
    """The data's level over all clips and over the test clips (`name`: the path recorded)."""
    clips = list(iter_collection(collection))
    sources = [t.source for _, t in clips]
    test = set()
    if len(set(sources)) >= 2:
        features = params.features
        test = split_sources([t for _, t in clips], features.test_fraction, features.split_seed)
    jobs = [(t, params.evaluate, params.contacts) for _, t in clips]
    rows = pool_map(_job, jobs, workers, "data reference")
    return {
        "label": LABEL,
        "collection": str(name or collection),
        "frames": FRAMES,
        "min_forward_frames": MIN_FORWARD_FRAMES,
        "contacts": "evaluate rule (Schmitt trigger), not the file's",
        "split": {
            "test_fraction": params.features.test_fraction,
            "split_seed": params.features.split_seed,
        },
        "joint_velocities": "file" if any(r["joint_velocities"] for r in rows) else "differences",
        "all": _subset(rows),
        "test": _subset([r for r, s in zip(rows, sources, strict=True) if s in test]),
        "gait": gait_reference([w for r in rows for w in r["gait_windows"]], params.evaluate),
    }


def reference_value(reference: dict[str, Any] | None, metric: str, subset: str = "all"):
    """The median of `metric` over the used clips of a subset, None where there is none."""
    stats = ((reference or {}).get(subset) or {}).get("metrics", {}).get(metric) or {}
    return stats.get("median")
