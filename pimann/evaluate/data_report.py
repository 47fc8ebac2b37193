"""What the models learn from: composition and foot quality of the retargeted collection.

The study is about still support feet, so every foot metric the evaluate stage applies to
generated trajectories is applied here, with the same functions and contact rule, to the data
(a trajectory collection, pimann.core.trajectory), per source (the clips' `dataset` attribute,
"all" when absent) and in total:

- Motion classes, per frame, and starts and stops (pimann.learn.motion_classes: the base's planar
  velocity in the heading frame and its yaw rate over a centred `WINDOW_S` window; transitions
  between standing and moving whose both states last `MIN_STATE_S`). Minutes are given for
  the original clips and with their mirrors; the authors' composition (docs/metrics.md) is
  pre-mirror and label-based, so the `content` labels' minutes are given beside ours where
  clips have them.
- Support-foot sliding (pimann.evaluate.metrics' velocity level, the joints' differences moving the
  feet with the lower one held: RMS over the 3 linear / 3 angular components of the sole
  velocity in `evaluate.foot_velocity_frame`, summed over frames in contact, left and
  right sums averaged) with the shared contact rule (params.yaml `contacts`, the Schmitt
  trigger of pimann.core.contacts on the lowest sole corner) and with the file's own
  flags. A sum grows with the frames, so it is scaled as the paper's 10 s test: the mean per
  frame times `PAPER_FRAMES` (500 frames, 10 s at 50 Hz). Per motion class it is restricted to
  the frames of that class (frames whose 1 s window is, e.g., forward walking), where the class
  has at least `MIN_CLASS_FRAMES`.
- Double support: the fraction of walking frames (every moving class but turning in place)
  with both feet in contact, for either contact rule.
- Glides: the 95th percentile of the horizontal speed of the sole corners (`SOLE_CORNERS`)
  that are within `GLIDE_HEIGHT` of the floor (z = 0), LOCAL_WORLD_ALIGNED corner velocities
  v + omega x (R c); a clean foot is still once down (target <= `GLIDE_TARGET`).
- The data's own L_B (pimann.learn.physics_loss), computed exactly as training computes it on a
  sample (pimann.learn.training_loss.TrainingLoss on the output y_i of
  pimann.learn.features.clip_features), on
  the ground-truth outputs of every sample of the collection (training and test clips alike,
  built here from the collection, not from the features file), with `lower_sole` and with
  `data_contacts` (the settled flags of pimann.learn.features.settled_contacts).
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pimann.core.contacts import frame_period
from pimann.core.errors import PimannError
from pimann.core.parallel import pool_map
from pimann.core.params import Params, as_dict
from pimann.core.robot import SOLE_CORNERS, corner_offsets, load_robot
from pimann.core.trajectory import Trajectory, iter_collection
from pimann.evaluate.metrics import PAPER_BASELINE_RMSE, analyse
from pimann.learn.feature_layout import window_layout
from pimann.learn.features import clip_features, settled_contacts
from pimann.learn.motion_classes import (
    BACKWARD_DEG,
    CLASSES,
    FORWARD_DEG,
    MIN_STATE_S,
    SIDE_DEG,
    STANDING_SPEED,
    STANDING_YAW_RATE,
    TURN_YAW_RATE,
    WALKING,
    WINDOW_S,
    motion_classes,
    transitions,
)

# ----------------------------------------------------------------------------- thresholds
MIN_CLASS_FRAMES = 500  # per-class foot metrics only over at least 10 s at 50 Hz
PAPER_FRAMES = 500  # the paper's test: 500 frames (10 s at 50 Hz)
GLIDE_HEIGHT = 0.005  # m, a sole corner this close to the floor is down
# m, a sole corner this far under the floor is in it (the retargeting's target): the retargeting's
# quality check's -FLOOR_TOLERANCE, not imported from pimann.retarget.quality because that
# would load the whole retargeting into this stage (tests/test_data_report.py ties the two)
BELOW_FLOOR = 0.005
GLIDE_TARGET = 0.1  # m/s, what the 95th percentile of a down corner's speed should not exceed
GLIDE_PERCENTILE = 95.0

RULES = ("evaluate_rule", "file_contacts")
# the evaluate section's keys the foot metrics read (dvc.yaml lists these for the stage, so
# what the claims and figures feature never reruns the data report)
METRIC_KEYS = (
    "skating_height",
    "skating_speed_per_frame",
    "skating_rate_hz",
    "walk_distance",
    "foot_velocity_frame",
)
ALL = "all"  # the source of clips without a `dataset` attribute
TOTAL = "total"
CORNER_COLUMNS = tuple(f"glide_{f}{c}" for f in "lr" for c in range(len(SOLE_CORNERS)))

# docs/data.md: the authors' training data, label-based minutes before mirroring
AUTHORS_MINUTES = {"forward": 5.3, "backward": 5.4, "side": 5.7, "diagonal": 2.4, "mixed": 13.3}
AUTHORS_SAMPLES = {"originals": 96_065, "with_mirrors": 192_130}
CLASS_COLOURS = {
    "forward": "tab:blue",
    "backward": "tab:orange",
    "side": "tab:green",
    "diagonal": "tab:purple",
    "turning": "tab:red",
    "turning_in_place": "tab:brown",
    "standing": "0.7",
    "mixed": "tab:cyan",
}


# ----------------------------------------------------------------------------- per frame


@functools.cache
def _training_loss(layout):
    """The training stage's loss module, with identity statistics (y in physical units)."""
    import torch

    from pimann.learn.feature_layout import Normalisation
    from pimann.learn.training_loss import TrainingLoss

    stats = Normalisation(
        np.zeros(layout.input_dim),
        np.ones(layout.input_dim),
        np.zeros(layout.output_dim),
        np.ones(layout.output_dim),
    )
    return TrainingLoss(
        layout, stats, torch.device("cpu"), pi_configuration="ground_truth", pi_gradient="both"
    )


def data_pi_loss(trajectory: Trajectory, params: Params) -> dict[str, np.ndarray]:
    """The data's own L_B per training sample of a clip: `steps` (N,) frames, `lower_sole`
    (N,), and `data_contacts` (N,) where the clip has contact flags."""
    import torch

    # the paper's layout: L_B reads no gait phase, and a clip without contacts has none
    layout = window_layout(params.features, float(trajectory.rate_hz), "full")
    layout = dataclasses.replace(layout, gait_phase_step_s=None)
    _, y, steps = clip_features(trajectory, layout)
    out = {"steps": steps, "lower_sole": np.empty(0), "data_contacts": np.empty(0)}
    if len(steps) == 0:
        return out
    loss = _training_loss(layout)
    with torch.no_grad():
        terms = loss.pi_terms(torch.as_tensor(y, dtype=torch.float32))
        out["lower_sole"] = loss.physics(**terms).double().numpy()
        if trajectory.contacts is not None:
            margin = round(params.features.contact_margin_s * layout.rate_hz)
            support = settled_contacts(trajectory.contacts, margin)[steps]
            out["data_contacts"] = (
                loss.physics(**terms, support=torch.as_tensor(support)).double().numpy()
            )
    return out


def _corner_speeds(positions, rotations, velocities) -> tuple[np.ndarray, np.ndarray]:
    """(T, 2, C) heights and horizontal speeds of the sole corners (LOCAL_WORLD_ALIGNED v)."""
    offsets = corner_offsets(rotations)  # (T, 2, C, 3)
    heights = positions[..., None, 2] + offsets[..., 2]
    linear = velocities[..., None, :3] + np.cross(velocities[..., None, 3:], offsets)
    return heights, np.linalg.norm(linear[..., :2], axis=-1)


def _sliding(rms: np.ndarray, contacts: np.ndarray) -> np.ndarray:
    """(T,) the frame's share of the total RMSE: contact-masked RMS, averaged over the feet."""
    return np.where(contacts, rms, 0.0).mean(axis=1)


def clip_frames(name: str, trajectory: Trajectory, params: Params) -> pd.DataFrame:
    """One row per frame of a clip: class, sliding, double support, glides, L_B, events."""
    robot = load_robot("retarget")
    time = np.asarray(trajectory.time, dtype=float)
    dt = frame_period(trajectory)
    analysis = analyse(
        trajectory, robot, params.evaluate, params.contacts, file_contacts=False
    )  # as evaluated
    rms = {kind: analysis.rms(kind) for kind in ("linear", "angular")}
    contacts = {"evaluate_rule": analysis.contacts}
    if trajectory.contacts is not None:
        contacts["file_contacts"] = np.asarray(trajectory.contacts, dtype=bool)
    feet, moved = analysis.feet, analysis.sole_velocities["position"]  # what the soles did

    classes = motion_classes(trajectory)
    n = len(time)
    columns: dict[str, Any] = {
        "clip": name,
        "dataset": str(trajectory.attrs.get("dataset", ALL)),
        "mirrored": bool(trajectory.attrs.get("mirrored", False)),
        "content": str(trajectory.attrs.get("content", "")),
        "seconds": dt,
        "class": np.asarray(CLASSES)[classes],
    }
    starts, stops = transitions(classes != CLASSES.index("standing"), round(MIN_STATE_S / dt))
    columns["start"] = np.isin(np.arange(n), starts)
    columns["stop"] = np.isin(np.arange(n), stops)
    for rule in RULES:
        flags = contacts.get(rule)
        for kind in ("linear", "angular"):
            columns[f"{kind}_{rule}"] = np.nan if flags is None else _sliding(rms[kind], flags)
        columns[f"double_{rule}"] = np.nan if flags is None else flags.all(axis=1).astype(float)
    heights, speeds = _corner_speeds(feet.positions, feet.rotations, moved)
    columns["lowest_corner"] = heights.min(axis=(1, 2))
    file_flags = contacts.get("file_contacts")
    columns["flight"] = np.nan if file_flags is None else (~file_flags.any(axis=1)).astype(float)
    speeds = np.where(heights <= GLIDE_HEIGHT, speeds, np.nan).reshape(n, -1)
    for k, column in enumerate(CORNER_COLUMNS):
        columns[column] = speeds[:, k]
    pi = data_pi_loss(trajectory, params)
    for support in ("lower_sole", "data_contacts"):
        values = np.full(n, np.nan)
        if len(pi[support]):
            values[pi["steps"]] = pi[support]
        columns[f"l_b_{support}"] = values
    return pd.DataFrame(columns)


def _clip_job(job: tuple[str, Trajectory, Params]) -> pd.DataFrame:
    return clip_frames(*job)


def collection_frames(
    trajectories: Iterable[tuple[str, Trajectory]], params: Params, workers: int = 1
) -> pd.DataFrame:
    """`clip_frames` of every clip, one table."""
    jobs = [(name, trajectory, params) for name, trajectory in trajectories]
    if not jobs:
        raise PimannError(None, "the collection holds no trajectory")
    return pd.concat(pool_map(_clip_job, jobs, workers, "data report"), ignore_index=True)


# ----------------------------------------------------------------------------- summaries


def _number(value: float) -> float | None:
    return float(value) if np.isfinite(value) else None


def _minutes(frames: pd.DataFrame, by: str, names: Iterable[str]) -> dict[str, float]:
    seconds = frames.groupby(by)["seconds"].sum()
    return {name: float(seconds.get(name, 0.0)) / 60.0 for name in names}


def sliding(frames: pd.DataFrame, rule: str) -> dict[str, float | None]:
    """The total RMSE scaled to the paper's 500 frames, over the given frames."""
    return {
        kind: _number(PAPER_FRAMES * frames[f"{kind}_{rule}"].mean()) if len(frames) else None
        for kind in ("linear", "angular")
    }


def glides(frames: pd.DataFrame) -> dict[str, float | int | None]:
    speeds = frames[list(CORNER_COLUMNS)].to_numpy().ravel()
    speeds = speeds[np.isfinite(speeds)]
    if len(speeds) == 0:
        return {"p95_m_s": None, "fraction_above_target": None, "samples": 0}
    return {
        "p95_m_s": float(np.percentile(speeds, GLIDE_PERCENTILE)),
        "fraction_above_target": float(np.mean(speeds > GLIDE_TARGET)),
        "samples": len(speeds),
    }


def floor(frames: pd.DataFrame) -> dict[str, float | None]:
    """Where the soles meet the floor: the lowest sole corner (m), the share of frames with a
    corner below it by more than `BELOW_FLOOR`, and of frames with no foot down by the file's
    flags (a person's flight phase leaves the robot base nothing to stand on)."""
    flight = frames["flight"].dropna()
    return {
        "lowest_corner_m": _number(frames["lowest_corner"].min()),
        "below_floor_share": _number((frames["lowest_corner"] < -BELOW_FLOOR).mean()),
        "flight_share": _number(flight.mean()) if len(flight) else None,
    }


def summarise(frames: pd.DataFrame) -> dict[str, Any]:
    """Composition of the original clips, and every foot metric over all clips (mirrors too)."""
    originals = frames[~frames["mirrored"]]
    walking = frames[frames["class"].isin(WALKING)]
    labels = originals["content"].replace("", "unlabelled")
    summary: dict[str, Any] = {
        "clips": int(originals["clip"].nunique()),
        "clips_with_mirrors": int(frames["clip"].nunique()),
        "frames": len(originals),
        "frames_with_mirrors": len(frames),
        "minutes": _minutes(originals, "class", CLASSES),
        "minutes_with_mirrors": _minutes(frames, "class", CLASSES),
        "label_minutes": _minutes(originals.assign(content=labels), "content", sorted(set(labels))),
        "starts": int(originals["start"].sum()),
        "stops": int(originals["stop"].sum()),
        "sliding": {},
        "double_support": {},
        "glides": glides(frames),
        "floor": floor(frames),
        "l_b": {},
    }
    summary["minutes"]["total"] = float(originals["seconds"].sum()) / 60.0
    summary["minutes_with_mirrors"]["total"] = float(frames["seconds"].sum()) / 60.0
    by_class = dict(tuple(frames.groupby("class")))
    for rule in RULES:
        if frames[f"linear_{rule}"].isna().any():
            summary["sliding"][rule] = None
            summary["double_support"][rule] = None
            continue
        summary["sliding"][rule] = sliding(frames, rule)
        summary["sliding"][rule]["per_class"] = {
            name: {**sliding(part, rule), "double_support": _number(part[f"double_{rule}"].mean())}
            for name, part in sorted(by_class.items())
            if len(part) >= MIN_CLASS_FRAMES
        }
        double = walking[f"double_{rule}"]
        summary["double_support"][rule] = _number(double.mean()) if len(double) else None
    for support in ("lower_sole", "data_contacts"):
        values = frames[f"l_b_{support}"].dropna()
        forward = frames.loc[frames["class"] == "forward", f"l_b_{support}"].dropna()
        summary["l_b"][support] = {
            "mean": _number(values.mean()) if len(values) else None,
            "forward": _number(forward.mean()) if len(forward) >= MIN_CLASS_FRAMES else None,
            "samples": len(values),
        }
    return summary


def thresholds() -> dict[str, Any]:
    return {
        "window_s": WINDOW_S,
        "standing_speed_m_s": STANDING_SPEED,
        "standing_yaw_rate_rad_s": STANDING_YAW_RATE,
        "turn_yaw_rate_rad_s": TURN_YAW_RATE,
        "forward_deg": FORWARD_DEG,
        "side_deg": list(SIDE_DEG),
        "backward_deg": BACKWARD_DEG,
        "min_state_s": MIN_STATE_S,
        "min_class_frames": MIN_CLASS_FRAMES,
        "paper_frames": PAPER_FRAMES,
        "glide_height_m": GLIDE_HEIGHT,
        "glide_target_m_s": GLIDE_TARGET,
        "glide_percentile": GLIDE_PERCENTILE,
    }


def build_report(frames: pd.DataFrame, params: Params, collection: str | Path) -> dict[str, Any]:
    """The report: per source, in total, the authors' figures and where it all came from."""
    sources = {name: summarise(part) for name, part in sorted(frames.groupby("dataset"))}
    sources[TOTAL] = summarise(frames)
    return {
        "collection": str(collection),
        "profile": params.profile,
        "params": {
            "data": as_dict(params.data),
            "contacts": as_dict(params.contacts),
            "evaluate": {key: getattr(params.evaluate, key) for key in METRIC_KEYS},
            "features": {
                "window": params.features.window,
                "contact_margin_s": params.features.contact_margin_s,
            },
        },
        "thresholds": thresholds(),
        "authors": {
            "minutes": AUTHORS_MINUTES,
            "samples": AUTHORS_SAMPLES,
            "baseline_model_sliding": PAPER_BASELINE_RMSE,
        },
        "sources": sources,
    }


def data_report(collection: str | Path, params: Params, workers: int = 1) -> dict[str, Any]:
    """The report of a trajectory collection file."""
    frames = collection_frames(iter_collection(collection), params, workers)
    return build_report(frames, params, collection)
