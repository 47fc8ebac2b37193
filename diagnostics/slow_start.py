"""The standing start at a slow command: why a model that sets off at 0.8 m/s may stay standing
at 0.4 m/s from the same start, with the evidence.

    python -m diagnostics.slow_start --model models/w10/0 [--model models/adherent/0 ...]
        [--slow 0.4] [--fast 0.8] [--swap-s 0.2 1.0] [--seconds 10] [--takes]

prints:
1. Data coverage (the features stage's training side): how many training clips start from
   rest (planar speed under 0.1 m/s over their first 0.2 s), how long they stand (until 2 cm
   from the start) and what speed they reach in the first and second second after, and
   whether their set-off is in the features at all (a sample needs a full past window: the
   first second of every clip is never an input's present); the training samples at rest
   (the past window's planar speed under 0.1 m/s at every past offset) by the speed their
   future window asks for, the slow and the fast band; the gait phase at rest (what the
   rollout's start, phase 0, meets there). With --takes, the same starts on the pelvis of
   every take of every source (`max_takes` ignored: what the paper profile reads), cut into
   clips as the retargeting cuts them, per source and by whether this profile picks the take:
   whether the rest of the shared data holds set-offs from rest the profile leaves out.
2. Per model: the authors' unsteered protocol (`rollout.protocols.authors`, its rollout keys)
   at --slow and, from the same start, at --fast: the network's predicted forward base
   velocity (its current sample), the legs' realised forward velocity (leg odometry), both
   feet's lowest-corner heights and the predicted gait phase, every 0.1 s over the first 2 s;
   and the network's response at the first input that carries the command, that input taken
   between the two runs' (the only difference there is the command) over a range of speeds.
3. Per model: which inputs decide it. Counterfactual rows in the same batch: the slow run
   with one input block taken from the fast run at the same step for the first --swap-s
   seconds (and the fast run with the slow run's), then left to its own rules; the blocks:
   the velocity window's future half (the command), its past half, the joints, the joint
   velocities, the gait phase and the fed-back pose; the slow run started at other gait
   phases; and the same start at speeds from 0.2 to 1.0 m/s. Each row: the forward distance
   in the test, touchdowns, whether it walks (the evaluate stage's rule:
   `evaluate.walk_distance` and two touchdowns), when a foot first lifts.

ADHERENT models (meta variant `adherent`) run through their own generator
(pimann.generate.adherent_rollout, the loop `rollout.adherent_past_velocity` names), with its
blocks (the future and past halves of positions, directions and velocities, joints, joint
velocities). Outside the pipeline: nothing imports this module.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import torch

from pimann.core.contacts import touchdowns
from pimann.core.errors import PimannError
from pimann.core.params import DataParams, MotionSegment, Params, load_params
from pimann.core.paths import REPO_ROOT
from pimann.core.robot import SOLE_CORNERS, Robot, load_robot
from pimann.core.trajectory import iter_collection
from pimann.evaluate.metrics import WALK_TOUCHDOWNS
from pimann.generate.adherent_rollout import (
    LOOP_FIRST_INPUT,
    AdherentGenerator,
    AdherentNetwork,
    command_future,
)
from pimann.generate.batch_generator import BatchGenerator
from pimann.generate.benchmark_clips import held_out_clips
from pimann.generate.command_script import ScriptSteps
from pimann.learn.adherent_train import load_adherent_model
from pimann.learn.dataset import FeatureDataset, read_dataset
from pimann.learn.model_files import META_FILE, load_model
from pimann.learn.motion_classes import STANDING_SPEED
from pimann.learn.standing import StandingPose
from pimann.mocap.clips import clip_motion, read_take, select_takes, source_takes, take_clips

REST_SPEED = STANDING_SPEED  # m/s: slower is at rest (the motion classes' standing)
REST_WINDOW_S = 0.2  # s over which a clip's start speed is measured
SET_OFF_DISTANCE = 0.02  # m from its first position: a clip has set off
WALKING_AFTER = 0.3  # m/s in the second second after a set-off: it turned into walking
SLOW_BAND, FAST_BAND = (0.3, 0.5), (0.7, 0.9)  # m/s, the future window's forward speed
SERIES_S, SERIES_EVERY_S = 2.0, 0.1  # the first seconds printed, one row every
START_PHASES = (0.5 * np.pi, np.pi, 1.5 * np.pi)  # the slow run's other starts (rad)
SWEEP_SPEEDS = (0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 1.0)  # m/s, the start's other commands
LIFT_HEIGHT = 0.02  # m, a foot's lowest corner above this has lifted (the contact rule's)
RESPONSE_SPEEDS = np.round(np.arange(0.0, 1.01, 0.1), 2)


# 1. data coverage


def _forward_speed(position: np.ndarray, frames: int, rate: float) -> np.ndarray:
    """(T - frames,) planar speed over the `frames` frames after each frame."""
    step = position[frames:, :2] - position[:-frames, :2]
    return np.hypot(step[:, 0], step[:, 1]) * rate / frames


def _mean_speed(position: np.ndarray, rate: float, start: int, stop: int) -> float:
    """Planar speed from frame start to stop (NaN past the clip's end)."""
    if stop >= len(position):
        return float("nan")
    step = position[stop, :2] - position[start, :2]
    return float(np.hypot(*step) * rate / (stop - start))


def start_row(position: np.ndarray, rate: float) -> dict[str, Any] | None:
    """A clip's start (base or pelvis planar positions (T, >=2) at `rate` Hz): its start
    speed, whether it starts from rest, how long it stands (until 2 cm from its start), the
    speed it reaches in the first and the second second after setting off, its median speed,
    and whether a feature sample sees the set-off from a past at rest (it stands at least the
    input window's past span, 1 s). None: a clip too short to tell."""
    window = max(1, round(REST_WINDOW_S * rate))
    if len(position) <= 2 * rate + window:
        return None
    speed = _forward_speed(position, window, rate)
    moved = np.hypot(*(position[:, :2] - position[0, :2]).T) >= SET_OFF_DISTANCE
    set_off = int(np.argmax(moved)) if moved.any() else len(position)
    second = round(rate)
    return {
        "start_speed": float(speed[0]),
        "from_rest": bool(speed[0] < REST_SPEED),
        "rest_s": set_off / rate,
        "speed_0_1s": _mean_speed(position, rate, set_off, set_off + second),
        "speed_1_2s": _mean_speed(position, rate, set_off + second, set_off + 2 * second),
        "median_speed": float(np.median(speed)),
        "set_off_sampled": bool(set_off / rate >= 1.0 and speed[0] < REST_SPEED),
    }


def clip_starts(collection: str | Path, params: Params) -> pd.DataFrame:
    """One `start_row` per unmirrored training clip of the retargeted collection."""
    test = {name for name, _ in held_out_clips(collection, params)}
    rows = []
    for name, trajectory in iter_collection(collection):
        if name in test or trajectory.attrs.get("mirrored", False):
            continue
        position = np.asarray(trajectory.base_position, dtype=float)
        row = start_row(position, float(trajectory.rate_hz))
        if row is not None:
            rows.append({"clip": name, **row})
    return pd.DataFrame(rows)


def source_starts(data: DataParams) -> pd.DataFrame:
    """One `start_row` per clip of every take of every source, `max_takes` ignored (what the
    paper profile reads), on the mocap's pelvis before retargeting, cut as the retargeting
    cuts (pimann.mocap.clips.take_clips); `picked`: the take is in `data`'s own selection.
    Whether more takes of the shared data would add set-offs from rest."""
    picked = {take.name for take in select_takes(data)}
    rows = []
    for key, source in data.sources.items():
        every = dataclasses.replace(source, max_takes=None)
        for take in source_takes(key, every, data):
            motion = read_take(take)
            for clip in take_clips(take, motion, source.clip_s, source.max_speed):
                part = clip_motion(motion, clip)
                row = start_row(part.pelvis_position, float(part.rate_hz))
                if row is not None:
                    rows.append(
                        {"source": key, "clip": clip.name, "picked": take.name in picked, **row}
                    )
    return pd.DataFrame(rows)


def source_start_summary(starts: pd.DataFrame) -> pd.DataFrame:
    """Per source and selection (picked by the profile or only in the whole data): clips, those
    starting from rest, those standing >= 1 s first (a sample sees the set-off), and of these
    how many walk (over 0.3 m/s) in their second second after setting off."""
    rows = []
    for (source, picked), group in starts.groupby(["source", "picked"], sort=True):
        rest = group[group["from_rest"]]
        sampled = rest[rest["set_off_sampled"]]
        rows.append(
            {
                "source": source,
                "picked": bool(picked),
                "clips": len(group),
                "from_rest": len(rest),
                "set_off_sampled": len(sampled),
                "walk_after": int((sampled["speed_1_2s"] > WALKING_AFTER).sum()),
                "start_speed_median": float(group["start_speed"].median()),
            }
        )
    return pd.DataFrame(rows)


def _window_columns(names: Sequence[str], prefixes: tuple[str, ...], keep) -> np.ndarray:
    """Boolean mask of the x columns `prefix[offset].axis` whose offset `keep` accepts."""
    mask = np.zeros(len(names), dtype=bool)
    for k, name in enumerate(names):
        if name.startswith(tuple(f"{p}[" for p in prefixes)):
            mask[k] = keep(int(name.split("[", 1)[1].split("]", 1)[0]))
    return mask


def rest_coverage(dataset: FeatureDataset) -> dict[str, float]:
    """The training samples at rest (every past sample of the linear velocity window under
    REST_SPEED, planar) by the forward speed their future half asks for (its mean), with the
    clips they come from; the gait phase at rest by quarter turn (when the layout has it)."""
    layout = dataset.layout
    x = dataset.stats.denormalise_x(dataset.x_train.astype(float))
    names = layout.names("x")
    linear = ("base_linear_window",)
    past = x[:, _window_columns(names, linear, lambda o: o <= 0)].reshape(len(x), -1, 3)
    future = x[:, _window_columns(names, linear, lambda o: o > 0)].reshape(len(x), -1, 3)
    rest = np.hypot(past[..., 0], past[..., 1]).max(axis=1) < REST_SPEED
    asked = future[..., 0].mean(axis=1)
    clips = dataset.train_origin[:, 0]
    out: dict[str, float] = {"samples": len(x), "at_rest": int(rest.sum())}
    for label, (low, high) in (("slow", SLOW_BAND), ("fast", FAST_BAND)):
        band = rest & (asked >= low) & (asked < high)
        out[f"at_rest_{label}_band"] = int(band.sum())
        out[f"at_rest_{label}_band_clips"] = len(np.unique(clips[band]))
        moving = (asked >= low) & (asked < high)
        out[f"{label}_band"] = int(moving.sum())
    out["at_rest_asked_over_0.1"] = int((rest & (asked >= 0.1)).sum())
    if "gait_phase" in layout.x_slices:
        phase = x[:, layout.x_slices["gait_phase"]][rest]
        angle = np.mod(np.arctan2(phase[:, 1], phase[:, 0]) + np.pi / 4, 2 * np.pi)
        quarter = (angle // (np.pi / 2)).astype(int)  # 0: near 0, 1: pi/2, 2: pi, 3: 3pi/2
        for k, label in enumerate(("0", "pi/2", "pi", "3pi/2")):
            out[f"at_rest_phase_{label}"] = int((quarter == k).sum())
    return out


# 2 and 3. a model's slow and fast starts, and the swaps


@dataclasses.dataclass(frozen=True)
class Row:
    """One rollout of the probe: its command speed, and what it takes from another row."""

    name: str
    speed: float
    donor: int | None = None  # the row whose input block it takes, at the same step
    block: str | None = None
    swap_steps: int = 0  # for the first this many network steps
    phase: float | None = None  # the start's gait phase (rad); None: the rollout's own


class Swapping:
    """The network, with a block of some rows' inputs taken from another row's input at the
    same step for their first steps; it keeps every input and output."""

    def __init__(self, network: Callable, rows: Sequence[Row], blocks: dict[str, np.ndarray]):
        self.network, self.rows, self.blocks = network, rows, blocks
        self.inputs: list[np.ndarray] = []
        self.outputs: list[np.ndarray] = []

    def __call__(self, x: np.ndarray) -> np.ndarray:
        step = len(self.inputs) + 1
        if len(x) != len(self.rows):
            raise PimannError(None, "a row stopped: the probe needs every row walking")
        x = x.copy()
        for k, row in enumerate(self.rows):
            if row.donor is not None and step <= row.swap_steps:
                columns = self.blocks[row.block]
                x[k, columns] = x[row.donor, columns]
        y = self.network(x)
        self.inputs.append(x)
        self.outputs.append(np.asarray(y, dtype=float).copy())
        return y


def mann_blocks(names: Sequence[str], slices: dict[str, slice]) -> dict[str, np.ndarray]:
    """The input blocks a swap exchanges (boolean masks over x) of a MANN layout."""
    windows = ("base_linear_window", "base_angular_window")
    blocks = {
        "future window": _window_columns(names, windows, lambda o: o > 0),
        "past window": _window_columns(names, windows, lambda o: o <= 0),
    }
    for block, parts in (
        ("joints", ("joints",)),
        ("joint velocities", ("joint_velocities",)),
        ("gait phase", ("gait_phase",)),
        ("pose", ("base_position", "base_rpy")),
    ):
        if all(p in slices for p in parts):
            mask = np.zeros(len(names), dtype=bool)
            for p in parts:
                mask[slices[p]] = True
            blocks[block] = mask
    return blocks


def adherent_blocks(names: Sequence[str], slices: dict[str, slice]) -> dict[str, np.ndarray]:
    """The input blocks a swap exchanges of ADHERENT's layout."""
    windows = ("base_positions", "facing_directions", "base_velocities")
    blocks = {
        "future window": _window_columns(names, windows, lambda o: o > 0),
        "past window": _window_columns(names, windows, lambda o: o <= 0),
    }
    for block, part in (("joints", "joints"), ("joint velocities", "joint_velocities")):
        mask = np.zeros(len(names), dtype=bool)
        mask[slices[part]] = True
        blocks[block] = mask
    return blocks


def probe_rows(
    slow: float, fast: float, blocks: Sequence[str], swap_steps: Sequence[int], phases: bool
) -> list[Row]:
    """The slow and fast runs (rows 0, 1), each block swapped both ways for each length,
    (`phases`) the slow run from other gait phases, and the same start at the other speeds of
    SWEEP_SPEEDS (where the set-off appears)."""
    rows = [Row("slow", slow), Row("fast", fast)]
    for steps in swap_steps:
        for block in blocks:
            rows.append(Row(f"slow + fast's {block}", slow, 1, block, steps))
            rows.append(Row(f"fast + slow's {block}", fast, 0, block, steps))
    if phases:
        rows += [Row(f"slow, start phase {a / np.pi:.1f} pi", slow, phase=a) for a in START_PHASES]
    between = [v for v in SWEEP_SPEEDS if v not in (slow, fast)]
    rows += [Row(f"command {v:.2f} m/s", v) for v in between]
    return rows


@dataclasses.dataclass
class Probe:
    """What one batch of probe rows did, per step (index 0: the start)."""

    rows: list[Row]
    rate: float
    position: np.ndarray  # (T, B, 3)
    heights: np.ndarray  # (T, B, 2) lowest corner of each foot
    contacts: np.ndarray  # (T, B, 2)
    predicted_vx: np.ndarray  # (T, B) the network's current forward base velocity (NaN at 0)
    phase: np.ndarray  # (T, B) the predicted gait phase's angle (NaN: none)
    inputs: list[np.ndarray]  # per network step (B, in)
    network: Callable  # the model, x -> y physical
    predicted_vx_of: Callable[[np.ndarray], np.ndarray]  # y -> (B,)
    leg_speed_of: Callable[[np.ndarray], np.ndarray]  # y -> (B,) leg joint velocities' rms


def _is_adherent(model_dir: Path) -> bool:
    import json

    try:
        meta = json.loads((model_dir / META_FILE).read_text())
    except (OSError, ValueError) as error:
        raise PimannError(model_dir / META_FILE, f"unreadable ({error})") from None
    return meta.get("variant") == "adherent"


def run_probe(
    model_dir: Path,
    params: Params,
    slow: float,
    fast: float,
    seconds: float,
    swap_s: Sequence[float],
    robot: Robot,
) -> Probe:
    """Every probe row of one model rolled out together (the authors' unsteered protocol; an
    ADHERENT model through its own generator)."""
    script = lambda speed: [MotionSegment(seconds, speed, 0.0, 0.0)]  # noqa: E731
    if _is_adherent(model_dir):
        return _adherent_probe(model_dir, params, slow, fast, script, swap_s, robot)
    model, layout, stats, meta = load_model(model_dir)
    rate = float(layout.rate_hz)
    names, slices = layout.names("x"), layout.x_slices
    blocks = mann_blocks(names, slices)
    steps = [max(1, round(s * rate)) for s in swap_s]
    rows = probe_rows(slow, fast, list(blocks), steps, layout.gait_phase)
    rollout = params.rollout.for_protocol("authors", False)
    standing = StandingPose.from_json(meta.get("standing"))
    generator = BatchGenerator(
        model,
        layout,
        stats,
        rollout,
        np.zeros(len(rows), dtype=bool),
        robot,
        params.contacts,
        standing,
    )
    for k, row in enumerate(rows):
        if row.phase is not None:
            generator.phase[k, :2] = np.cos(row.phase), np.sin(row.phase)
    network = generator.network
    swapping = generator.network = Swapping(network, rows, blocks)
    plan = ScriptSteps([script(row.speed) for row in rows], rate)
    ys, now = layout.y_slices, layout.current_output
    legs = np.zeros(layout.output_dim, dtype=bool)
    legs[ys["joint_velocities"].start : ys["joint_velocities"].start + 12] = True

    def predicted_vx(y: np.ndarray) -> np.ndarray:
        return y[:, ys["base_linear_future"]].reshape(len(y), -1, 3)[:, now, 0]

    def phase_of(y: np.ndarray) -> np.ndarray:
        if "gait_phase" not in ys:
            return np.full(len(y), np.nan)
        pair = y[:, ys["gait_phase"]]
        return np.arctan2(pair[:, 1], pair[:, 0])

    def record() -> tuple[np.ndarray, ...]:
        heights = generator.odometry.world_corners[:, :, 2].min(axis=2)
        return generator.position.copy(), heights, generator.contacts.copy()

    first = record()
    series = [first]
    with torch.inference_mode():
        for k in range(1, len(plan.active)):
            generator.step(k, *plan.at(k))
            series.append(record())
    return _probe(rows, rate, series, swapping, network, predicted_vx, phase_of, legs)


def _adherent_probe(
    model_dir: Path,
    params: Params,
    slow: float,
    fast: float,
    script: Callable,
    swap_s: Sequence[float],
    robot: Robot,
) -> Probe:
    """`run_probe` for an ADHERENT model: its own generator, its blocks, no gait phase."""
    model, layout, stats, meta = load_adherent_model(model_dir)
    rate = float(layout.rate_hz)
    blocks = adherent_blocks(layout.names("x"), layout.x_slices)
    steps = [max(1, round(s * rate)) for s in swap_s]
    rows = probe_rows(slow, fast, list(blocks), steps, phases=False)
    network = AdherentNetwork(model, stats)
    swapping = Swapping(network, rows, blocks)
    loop = params.rollout.adherent_past_velocity
    generator = AdherentGenerator(
        swapping,
        layout,
        robot,
        params.contacts,
        StandingPose.from_json(meta.get("standing")),
        len(rows),
        loop,
        LOOP_FIRST_INPUT[loop],
    )
    plan = ScriptSteps([script(row.speed) for row in rows], rate)
    ys = layout.y_slices
    legs = np.zeros(layout.output_dim, dtype=bool)
    legs[ys["joint_velocities"].start : ys["joint_velocities"].start + 12] = True

    def record() -> tuple[np.ndarray, ...]:
        corners, _ = generator._corners(
            generator.rotation, generator.position, generator.joints, SOLE_CORNERS
        )
        return generator.position.copy(), corners[..., 2].min(axis=2), generator.contacts.copy()

    series = [record()]
    for k in range(1, len(plan.active)):
        generator.step(
            command_future(plan.velocity[k], plan.yaw_rate[k], layout.future_offsets, rate)
        )
        series.append(record())

    def predicted_vx(y: np.ndarray) -> np.ndarray:
        return y[:, ys["base_twist"]][:, 0]

    def no_phase(y: np.ndarray) -> np.ndarray:
        return np.full(len(y), np.nan)

    return _probe(rows, rate, series, swapping, network, predicted_vx, no_phase, legs)


def _probe(
    rows: Sequence,
    rate: float,
    series: list[tuple[np.ndarray, ...]],
    swapping: Swapping,
    network: Any,
    predicted_vx: Callable,
    phase_of: Callable,
    legs: np.ndarray,
) -> Probe:
    """A `Probe` of the recorded series (position, lowest corner heights, contacts a frame)
    and the network's outputs at each step, the first frame's predictions NaN."""
    position, heights, contacts = (np.stack(part) for part in zip(*series, strict=True))
    outputs = np.stack(swapping.outputs)
    nan = np.full((1, len(rows)), np.nan)
    return Probe(
        rows,
        rate,
        position,
        heights,
        contacts,
        np.concatenate([nan, np.stack([predicted_vx(y) for y in outputs])]),
        np.concatenate([nan, np.stack([phase_of(y) for y in outputs])]),
        swapping.inputs,
        network,
        predicted_vx,
        lambda y: np.sqrt((y[:, legs] ** 2).mean(axis=1)),
    )


def first_seconds(probe: Probe) -> pd.DataFrame:
    """The slow and fast runs every SERIES_EVERY_S over the first SERIES_S: predicted and
    realised forward velocity (m/s; the realised one over the interval before), the feet's
    lowest-corner heights (cm) and the predicted gait phase (turns)."""
    every = max(1, round(SERIES_EVERY_S * probe.rate))
    last = min(len(probe.position) - 1, round(SERIES_S * probe.rate))
    frames = np.arange(every, last + 1, every)
    table = {"t": frames / probe.rate}
    for k, label in ((0, "slow"), (1, "fast")):
        x = probe.position[:, k, 0]
        table[f"{label}_vx_net"] = probe.predicted_vx[frames, k]
        table[f"{label}_vx_legs"] = (x[frames] - x[frames - every]) * probe.rate / every
        table[f"{label}_left_cm"] = 100 * probe.heights[frames, k, 0]
        table[f"{label}_right_cm"] = 100 * probe.heights[frames, k, 1]
        phase = probe.phase[1:, k]
        turns = np.unwrap(phase) / (2 * np.pi) if np.isfinite(phase).all() else phase
        table[f"{label}_phase"] = np.concatenate([[np.nan], turns])[frames]
    return pd.DataFrame(table)


def first_input_response(probe: Probe, speeds: Sequence[float] = RESPONSE_SPEEDS) -> pd.DataFrame:
    """The network at the first step whose inputs differ between the slow and the fast run
    (there they differ by the command alone), that input moved linearly between the two to each
    commanded speed: the predicted forward velocity and the legs' joint-velocity rms."""
    slow, fast = probe.rows[0].speed, probe.rows[1].speed
    differ = [k for k, x in enumerate(probe.inputs) if not np.array_equal(x[0], x[1])]
    if not differ:
        raise PimannError(None, "the slow and fast runs never differ")
    step = differ[0]
    x_slow, x_fast = probe.inputs[step][0], probe.inputs[step][1]
    weights = (np.asarray(speeds, dtype=float) - slow) / (fast - slow)
    x = x_slow[None] + weights[:, None] * (x_fast - x_slow)[None]
    with torch.inference_mode():
        y = np.asarray(probe.network(x), dtype=float)
    return pd.DataFrame(
        {
            "step": step + 1,
            "speed": speeds,
            "vx_net": probe.predicted_vx_of(y),
            "leg_joint_velocity_rms": probe.leg_speed_of(y),
        }
    )


def _mean(values: np.ndarray) -> float:
    """The mean of the finite values; NaN without any (a rollout shorter than asked)."""
    finite = values[np.isfinite(values)]
    return float(finite.mean()) if len(finite) else float("nan")


def outcomes(probe: Probe, walk_distance: float) -> pd.DataFrame:
    """Per probe row: forward distance, touchdowns (both feet), whether it walks (the evaluate
    stage's rule), the mean predicted forward velocity over the first and second second, the
    highest foot lift over the first 2 s (cm), when a foot first lifts above LIFT_HEIGHT (s)
    and the gait phase's turns over the first 2 s."""
    second = round(probe.rate)
    rows = []
    for k, row in enumerate(probe.rows):
        distance = float(probe.position[-1, k, 0] - probe.position[0, k, 0])
        count = int(touchdowns(probe.contacts[:, k]).sum())
        predicted = probe.predicted_vx[:, k]
        lifted = np.flatnonzero(probe.heights[:, k].max(axis=1) > LIFT_HEIGHT)
        phase = probe.phase[1 : 2 * second + 1, k]
        turns = (
            float((np.unwrap(phase)[-1] - phase[0]) / (2 * np.pi))
            if np.isfinite(phase).all()
            else float("nan")
        )
        rows.append(
            {
                "row": row.name,
                "swap_s": row.swap_steps / probe.rate if row.donor is not None else 0.0,
                "distance": distance,
                "touchdowns": count,
                "walks": bool(distance >= walk_distance and count >= WALK_TOUCHDOWNS),
                "vx_net_0_1s": _mean(predicted[1 : second + 1]),
                "vx_net_1_2s": _mean(predicted[second + 1 : 2 * second + 1]),
                "lift_cm_2s": float(100 * probe.heights[: 2 * second + 1, k].max()),
                "first_lift_s": float(lifted[0] / probe.rate) if len(lifted) else float("nan"),
                "phase_turns_2s": turns,
            }
        )
    return pd.DataFrame(rows)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--model", type=Path, action="append", default=[], help="a trained seed's folder"
    )
    parser.add_argument("--slow", type=float, default=None, help="m/s; the authors' test's")
    parser.add_argument("--fast", type=float, default=0.8, help="m/s")
    parser.add_argument("--swap-s", type=float, nargs="+", default=[0.2, 1.0])
    parser.add_argument("--seconds", type=float, default=None, help="the authors' test's")
    parser.add_argument(
        "--features", type=Path, default=REPO_ROOT / "data" / "features" / "full.h5"
    )
    parser.add_argument("--no-data", action="store_true", help="skip the data coverage")
    parser.add_argument(
        "--takes",
        action="store_true",
        help="also every take of the shared mocap (max_takes ignored): its clips' starts",
    )
    args = parser.parse_args(argv)
    params = load_params()
    (authors,) = [s for s in params.rollout.protocols["authors"].script]
    slow, fast = (authors.vx if args.slow is None else args.slow), args.fast
    seconds = authors.duration if args.seconds is None else args.seconds
    wide = lambda: pd.option_context("display.width", 200, "display.max_rows", 500)  # noqa: E731
    try:
        if not args.no_data:
            collection = REPO_ROOT / params.features.input
            starts = clip_starts(collection, params)
            rest = starts[starts["from_rest"]]
            print(
                f"1. data: {len(rest)} of {len(starts)} unmirrored training clips start from rest"
                f" (< {REST_SPEED} m/s over the first {REST_WINDOW_S} s); "
                f"{int(rest['set_off_sampled'].sum())} stand >= 1 s, so a sample sees the set-off"
            )
            with wide():
                print(rest.round(2).to_string(index=False))
            dataset = read_dataset(args.features)
            print(f"training samples of {args.features}:")
            for key, value in rest_coverage(dataset).items():
                print(f"  {key}: {value}")
        if args.takes:
            starts = source_starts(params.data)
            print(
                "\n1b. every take of the shared mocap (max_takes ignored; picked: in this"
                f" profile's selection), its clips' starts on the pelvis ('{params.profile}')"
            )
            with wide():
                print(source_start_summary(starts).round(2).to_string(index=False))
        robot = load_robot()
        for model_dir in args.model:
            probe = run_probe(model_dir, params, slow, fast, seconds, args.swap_s, robot)
            print(f"\n2. {model_dir}: the authors' unsteered test at {slow} and {fast} m/s")
            with wide():
                print(first_seconds(probe).round(3).to_string(index=False))
                print("the first input that carries the command, moved to each speed:")
                print(first_input_response(probe).round(3).to_string(index=False))
                print(f"\n3. {model_dir}: swaps")
                table = outcomes(probe, params.evaluate.walk_distance)
                print(table.round(3).to_string(index=False))
    except PimannError as error:
        print(f"slow_start: {error}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
