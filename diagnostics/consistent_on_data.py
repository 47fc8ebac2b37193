"""The contact-consistent post-process on the data the models learn from: every retargeted clip
held as a rollout is (docs/consistent.md, section "What it costs"), raw against held.

    python -m diagnostics.consistent_on_data [--every 4] [--drift 0.05 --drift-s 4]
        [--collection data/retargeted/walking.h5]

For every `--every`-th clip of the collection (params `features.input`, in name order): the clip
made contact-consistent by pimann.generate.contact_consistent.make_consistent (params
`rollout.consistent` and `contacts`), and both measured by the evaluate stage's own functions,
the data as the evaluate stage measures it:

- the data's level (pimann.evaluate.data_reference.clip_reference, the figure of
  results/claims.md row D and metrics_summary.json's `data_reference`): contact-masked RMS
  by the evaluate rule (never the file's flags) over the clip's forward-walking frames, per 500
  frames; its medians over the clips with at least `MIN_FORWARD_FRAMES` forward frames, as the
  data reference's;
- every frame of the clip (pimann.evaluate.metrics.trajectory_metrics, the rule's contacts),
  per 500 frames: every clip counts;
- position-level sliding (`support_rmse_linear_position_total`), the authors' metric
  (`support_rmse_paper_linear_total`) and touchdowns (the rule's, on each variant's own soles);
- the joints' distance to the raw ones, RMS and largest over every frame and joint
  (pimann.evaluate.consistency_measures' `joint_distance_rms_rad`, `joint_distance_max_rad`)
  and the largest held-sole residual (`consistent_residual_max_m`).

The retargeted clips carry no joint velocities: the raw clip is measured on its joints'
differences, as the data reference measures it, and so is the held one (make_consistent keeps a
missing velocity missing). `--drift V --drift-s S` measures each clip with a sideways drift of V
m/s (to the left of its first frame's heading) added to the base over its first S seconds, then
kept: every foot on the floor glides at V meanwhile. Outside the pipeline: nothing imports this
module.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from pimann.core.params import Params, load_params
from pimann.core.paths import REPO_ROOT
from pimann.core.robot import Robot, load_robot
from pimann.core.rotations import quaternion_xyzw_matrices, yaw_of
from pimann.core.trajectory import Trajectory, iter_collection
from pimann.evaluate.consistency_measures import joint_distance
from pimann.evaluate.data_reference import FRAMES, MIN_FORWARD_FRAMES, clip_reference
from pimann.evaluate.metrics import trajectory_metrics
from pimann.generate.contact_consistent import LegSolver, make_consistent

POSITION = "support_rmse_linear_position_total"  # position level, linear
AUTHORS = "support_rmse_paper_linear_total"  # the authors' metric, linear
ABOVE = 1.1  # a clip whose held level exceeds this many times its raw one is counted
SUMMARY = REPO_ROOT / "results/metrics_summary.json"  # the evaluate stage's data reference


def drifted(trajectory: Trajectory, speed: float, seconds: float) -> Trajectory:
    """The clip with its base moved sideways (left of its first frame's heading) at `speed`
    m/s over its first `seconds`, then kept there: every foot on the floor glides meanwhile."""
    time = np.asarray(trajectory.time, float)
    yaw = float(yaw_of(quaternion_xyzw_matrices(trajectory.base_quaternion_xyzw[:1]))[0])
    left = np.array([-np.sin(yaw), np.cos(yaw), 0.0])
    travel = speed * np.clip(time - time[0], 0.0, seconds)
    base = np.asarray(trajectory.base_position, float) + travel[:, None] * left
    return dataclasses.replace(trajectory, base_position=base)


def measures(trajectory: Trajectory, robot: Robot, params: Params) -> dict[str, Any]:
    """The sliding of one clip: the data reference's (forward frames, per `FRAMES`; None
    without forward frames) and over every frame (per `FRAMES`), and the rule's touchdowns."""
    reference = clip_reference(trajectory, params.evaluate, params.contacts)
    metrics = trajectory_metrics(
        trajectory, robot, params.evaluate, params.contacts, file_contacts=False
    )
    frames = metrics["frames"]
    return {
        "forward_frames": reference["forward_frames"],
        "position": reference[POSITION],
        "authors": reference[AUTHORS],
        "position_clip": FRAMES * metrics[POSITION] / frames,
        "authors_clip": FRAMES * metrics[AUTHORS] / (frames - 1),  # frame 0 has no step
        "touchdowns": metrics["touchdowns"],
    }


def clip_row(
    name: str,
    trajectory: Trajectory,
    robot: Robot,
    params: Params,
    solver: LegSolver | None = None,
    drift: float = 0.0,
    drift_s: float = 0.0,
) -> dict[str, Any]:
    """One clip (drifting where `drift`), raw and held: {"clip", "raw", "held", "joints_rms",
    "joints_max", "residual"}."""
    if drift:
        trajectory = drifted(trajectory, drift, drift_s)
    consistent = params.rollout.consistent
    held = make_consistent(trajectory, robot, consistent, params.contacts, solver).trajectory
    rms, largest = joint_distance(trajectory.joint_positions, held.joint_positions)
    return {
        "clip": name,
        "raw": measures(trajectory, robot, params),
        "held": measures(held, robot, params),
        "joints_rms": rms,
        "joints_max": largest,
        "residual": float(held.attrs["consistent_residual_max_m"]),
    }


def _level(rows: list[dict[str, Any]], key: str) -> dict[str, Any]:
    """Medians of raw and held `key` over the rows that have it, and the clips whose held
    level is above `ABOVE` x the raw one (with the largest ratio)."""
    pairs = [(r["raw"][key], r["held"][key]) for r in rows if r["raw"][key] is not None]
    if not pairs:
        return {"clips": 0, "raw": None, "held": None, "above": 0, "largest_ratio": None}
    raw, held = np.array(pairs).T
    ratio = held / np.maximum(raw, 1e-12)
    return {
        "clips": len(pairs),
        "raw": float(np.median(raw)),
        "held": float(np.median(held)),
        "above": int((ratio > ABOVE).sum()),
        "largest_ratio": float(ratio.max()),
    }


def summary(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Medians over the clips: the data reference's (clips with at least
    `MIN_FORWARD_FRAMES` forward frames) and every frame of every clip."""
    used = [r for r in rows if r["raw"]["forward_frames"] >= MIN_FORWARD_FRAMES]
    touchdowns = np.array([(r["raw"]["touchdowns"], r["held"]["touchdowns"]) for r in rows])
    return {
        "clips": len(rows),
        "position": _level(used, "position"),
        "authors": _level(used, "authors"),
        "position_clip": _level(rows, "position_clip"),
        "authors_clip": _level(rows, "authors_clip"),
        "touchdowns": [int(t) for t in touchdowns.sum(axis=0)],
        "touchdowns_changed": int((touchdowns[:, 0] != touchdowns[:, 1]).sum()),
        "joints_rms": float(np.median([r["joints_rms"] for r in rows])),
        "joints_max": float(np.median([r["joints_max"] for r in rows])),
        "joints_max_largest": float(max(r["joints_max"] for r in rows)),
        "residual": float(np.median([r["residual"] for r in rows])),
        "residual_largest": float(max(r["residual"] for r in rows)),
    }


def _pair(raw: float | None, held: float | None, digits: int = 1) -> str:
    if raw is None or held is None:
        return "-"
    return f"{raw:.{digits}f} / {held:.{digits}f}"


COLUMNS = (  # the per-clip table's: header, width
    ("clip", -40),
    ("fwd", 4),
    ("position (data ref.)", 20),
    ("position (clip)", 15),
    ("authors (clip)", 15),
    ("touchdowns", 10),
    ("joints RMS/max", 14),
    ("resid. (m)", 10),
)


def table(rows: Iterable[dict[str, Any]]) -> str:
    """The per-clip table, raw / held ("fwd": the clip's forward-walking frames)."""

    def line(cells: Iterable[str]) -> str:
        return " ".join(
            f"{c[:-w]:<{-w}}" if w < 0 else f"{c:>{w}}"
            for c, (_, w) in zip(cells, COLUMNS, strict=True)
        )

    lines = [line(name for name, _ in COLUMNS)]
    for r in rows:
        raw, held = r["raw"], r["held"]
        lines.append(
            line(
                (
                    r["clip"],
                    str(raw["forward_frames"]),
                    _pair(raw["position"], held["position"]),
                    _pair(raw["position_clip"], held["position_clip"]),
                    _pair(raw["authors_clip"], held["authors_clip"]),
                    f"{raw['touchdowns']} / {held['touchdowns']}",
                    f"{r['joints_rms']:.3f} / {r['joints_max']:.2f}",
                    f"{r['residual']:.3f}",
                )
            )
        )
    return "\n".join(lines)


def medians_text(s: dict[str, Any], reference: float | None = None) -> str:
    """The medians, raw / held, and the clips above `ABOVE` x their raw level."""

    def level(name: str, key: str) -> str:
        m = s[key]
        if not m["clips"]:
            return f"{name}: no clip"
        return (
            f"{name} ({m['clips']} clips): {_pair(m['raw'], m['held'])}, "
            f"{m['above']} above {ABOVE}x raw (at most {m['largest_ratio']:.2f}x)"
        )

    lines = [
        f"medians over {s['clips']} clips, raw / held (per {FRAMES} frames):",
        "  " + level("position level, the data reference's (forward frames)", "position"),
        "  " + level("authors' metric, the data reference's (forward frames)", "authors"),
        "  " + level("position level, every frame", "position_clip"),
        "  " + level("authors' metric, every frame", "authors_clip"),
        f"  touchdowns (sum): {s['touchdowns'][0]} / {s['touchdowns'][1]}, "
        f"{s['touchdowns_changed']} clips changed",
        f"  joints from raw: RMS {s['joints_rms']:.3f} rad, largest {s['joints_max']:.2f} rad "
        f"(median over clips; at most {s['joints_max_largest']:.2f})",
        f"  held-sole residual: {s['residual'] * 1e3:.1f} mm (median; at most "
        f"{s['residual_largest'] * 1e3:.1f} mm)",
    ]
    if reference is not None:
        lines.append(
            f"  (the evaluate stage's data level, every clip, position level: {reference:.1f})"
        )
    return "\n".join(lines)


def data_level(path: Path = SUMMARY) -> float | None:
    """The evaluate stage's data reference, position level, all clips (None: not there)."""
    if not path.is_file():
        return None
    reference = json.loads(path.read_text()).get("data_reference") or {}
    stats = reference.get("all", {}).get("metrics", {}).get(POSITION) or {}
    return stats.get("median")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--every", type=int, default=4, help="every n-th clip (name order)")
    parser.add_argument("--drift", type=float, default=0.0, help="m/s sideways, 0: none")
    parser.add_argument("--drift-s", type=float, default=4.0, help="s of drift from the start")
    parser.add_argument("--collection", type=Path, default=None, help="default features.input")
    args = parser.parse_args(argv)
    params = load_params()
    collection = args.collection or REPO_ROOT / params.features.input
    robot = load_robot("retarget")
    solver = LegSolver(robot, params.rollout.consistent)
    rows = []
    with threadpool_limits(1):
        for k, (name, trajectory) in enumerate(iter_collection(collection)):
            if k % args.every == 0:
                rows.append(
                    clip_row(name, trajectory, robot, params, solver, args.drift, args.drift_s)
                )
    what = f"drift {args.drift} m/s over {args.drift_s} s" if args.drift else "as retargeted"
    print(f"{collection.name}, every {args.every}th clip, {what}; raw / held")
    print(table(rows))
    print(medians_text(summary(rows), data_level()))


if __name__ == "__main__":
    main()
