"""What a contact-consistent rollout costs (pimann.generate.contact_consistent), on one core.

1. post-process: a 10-s trajectory (500 steps at 50 Hz) made contact-consistent, the fastest
   of three runs: a retargeted walking clip of `--collection` (default the repository's
   features.input) cut to 10 s, or, without it, a 10-s rollout of a full-size random MANN;
2. in the loop: the batched generator's step with and without `consistent`, for one rollout
   and a batch of 32 10-s rollouts (a full-size random MANN, half of them steered): the hold's
   time a step and a rollout's, and the whole step's.

Run from the repository root: python -m benchmarks.consistent_speed [--smoke]
(`--smoke`: 1-s trajectories, batches of 1 and 4, one run each.)
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time
from pathlib import Path

import numpy as np
import torch
from threadpoolctl import threadpool_limits

from pimann.core.params import MotionSegment, load_params
from pimann.core.paths import REPO_ROOT
from pimann.core.robot import load_robot
from pimann.core.trajectory import Trajectory, iter_collection
from pimann.generate.contact_consistent import LegSolver, make_consistent
from pimann.generate.rollout_batch import RolloutSpec, generate_batch
from pimann.learn.feature_layout import window_layout

RATE = 50.0
WIDTHS = (5, 12, 8, 11, 14)  # the loop table's columns


def cut(trajectory: Trajectory, frames: int) -> Trajectory:
    """The first `frames` frames, the file's contacts dropped (the rule finds its own)."""
    fields = ("time", "base_position", "base_quaternion_xyzw", "joint_positions")
    parts = {name: getattr(trajectory, name)[:frames] for name in fields}
    return dataclasses.replace(trajectory, **parts, contacts=None, joint_velocities=None)


def walking_clip(collection: Path, frames: int) -> tuple[Trajectory, str] | None:
    """A walking clip of the collection at least `frames` long, cut to it."""
    if not collection.is_file():
        return None
    fallback = None
    for name, trajectory in iter_collection(collection):
        if len(trajectory) < frames:
            continue
        if "walk" in name:
            return cut(trajectory, frames), f"clip {name} of {collection.name}"
        fallback = fallback or (cut(trajectory, frames), f"clip {name} of {collection.name}")
    return fallback


def network(params, seed: int = 0):
    """A full-size random MANN whose outputs stay near the standing state."""
    from benchmarks.generate_speed import near_standing, random_model

    layout = window_layout(params.features, RATE, "full")
    return random_model(params, layout, seed), layout, near_standing(layout)


def rollouts(params, rows: int, seconds: float, consistent, timings: dict) -> list[Trajectory]:
    model, layout, stats = network(params)
    specs = [
        RolloutSpec([MotionSegment(seconds, 0.6, 0.0, 0.0)], bool(row % 2)) for row in range(rows)
    ]
    out = generate_batch(
        model,
        layout,
        stats,
        specs,
        params.rollout,
        load_robot(),
        contact_params=params.contacts,
        consistent=consistent,
        timings=timings,
    )
    return [rollout.trajectory for rollout in out]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--collection", type=Path, default=None)
    parser.add_argument("--smoke", action="store_true", help="tiny sizes: seconds")
    args = parser.parse_args(argv)
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    torch.set_num_threads(1)
    params = load_params()
    consistent = params.rollout.consistent
    seconds, batches, repeats = (1.0, (1, 4), 1) if args.smoke else (10.0, (1, 32), 3)
    frames = int(seconds * RATE) + 1
    robot = load_robot()
    solver = LegSolver(robot, consistent)
    with threadpool_limits(limits=1):
        collection = args.collection or REPO_ROOT / params.features.input
        found = walking_clip(collection, frames)
        if found is None:
            trajectory = rollouts(params, 1, seconds, None, {})[0]
            found = cut(trajectory, frames), "a random full-size MANN's rollout"
        trajectory, what = found
        best, held = np.inf, 0.0
        for _ in range(repeats):
            start = time.perf_counter()
            out = make_consistent(trajectory, robot, consistent, params.contacts, solver)
            best = min(best, time.perf_counter() - start)
            held = float((out.weights.min(axis=-1) >= 1.0).mean())
        print(f"post-process, {seconds:g} s ({frames - 1} steps), {what}, 1 core:")
        print(f"  {best:.3f} s (fastest of {repeats}); feet held in {100 * held:.0f}% of frames")
        print(f"in the loop, {seconds:g}-s rollouts of a full-size random MANN, 1 core:")
        header = ("batch", "hold/step ms", "step ms", "raw step ms", "hold/rollout s")
        print("  " + " ".join(f"{h:>{w}}" for h, w in zip(header, WIDTHS, strict=True)))
        for rows in batches:
            times = []
            for variant in (consistent, None):
                timings: dict[str, float] = {}
                start = time.perf_counter()
                rollouts(params, rows, seconds, variant, timings)
                times.append((time.perf_counter() - start, timings.get("consistent", 0.0)))
            steps = frames - 1
            (held_wall, hold), (raw_wall, _) = times
            row = (rows, 1e3 * hold / steps, 1e3 * held_wall / steps, 1e3 * raw_wall / steps)
            cells = [f"{row[0]:>5}"] + [
                f"{v:>{w}.2f}" for v, w in zip(row[1:], WIDTHS[1:4], strict=True)
            ]
            print("  " + " ".join([*cells, f"{hold / rows:>14.3f}"]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
