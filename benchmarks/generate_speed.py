"""Where generation's time goes, and batched generation against one rollout at a time.

A full-size MANN (random weights, the layout of `features.window_layout`), 50 Hz:

1. the cost of a batch step by section (commands and state, network input, network, steering,
   leg odometry, contacts, recording; writing the files apart) for one rollout and for batches
   of 8, 32 and 128 10-s rollouts (half of them steered), the cost of one 10-s rollout
   amortised over its batch and its real-time factor;
2. a full set, 2 seeds x (5 named scenarios + 12 clip scripts) x 2 steering, generated one
   rollout at a time (`generate_rollout`) and batched (one batch per seed, as the rollout
   stage does), side by side in this run, each three times alternating (the fastest pass of
   each kept), and the ratio.

The clip scripts are the command-following benchmark's (the test clips of `--collection`,
default the repository's features.input) or, without the collection, 12 random scripts of
4-16 s. Run from the repository root: python -m benchmarks.generate_speed

`--smoke`: the same code paths in a few seconds (1-s rollouts, batches of 1 and 4, one pass
each, 1 named scenario and 2 clip scripts cut to 1 s), to check that the benchmark still runs.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

from pimann.core.params import MotionSegment, StandSegment, load_params
from pimann.core.paths import REPO_ROOT
from pimann.core.robot import STANDING_BASE_HEIGHT, STANDING_JOINTS, load_robot
from pimann.core.trajectory import write_trajectory
from pimann.generate.batch_generator import SECTIONS
from pimann.generate.benchmark_clips import benchmark_scripts
from pimann.generate.command_script import scenario_steps
from pimann.generate.rollout_batch import RolloutSpec, generate_batch, generate_rollout
from pimann.learn.feature_layout import Normalisation, window_layout
from pimann.learn.mann import MANN

SECONDS = 10.0
N_CLIPS = 12


def random_model(params, layout, seed: int) -> MANN:
    torch.manual_seed(seed)
    return MANN(layout.input_dim, layout.output_dim, params.model, seeds=[seed]).eval()


def near_standing(layout) -> Normalisation:
    """Outputs near the standing state, so a random network's rollout stays sane."""
    y_mean = np.zeros(layout.output_dim)
    y_mean[layout.y_slices["joints"]] = STANDING_JOINTS
    y_mean[layout.y_slices["base_position"].start + 2] = STANDING_BASE_HEIGHT
    return Normalisation(
        np.zeros(layout.input_dim),
        np.ones(layout.input_dim),
        y_mean,
        np.full(layout.output_dim, 0.01),
    )


def clip_scripts(params, collection: Path | None, n_clips: int = N_CLIPS) -> tuple[list[list], str]:
    """`n_clips` scripts of the command-following benchmark, or random ones of its kind."""
    if collection is not None and collection.is_file():
        features = dataclasses.replace(params.features, input=str(collection))
        scripts = list(benchmark_scripts(dataclasses.replace(params, features=features)).values())
        if len(scripts) >= n_clips:
            return scripts[:n_clips], f"the test clips of {collection}"
    rng = np.random.default_rng(0)
    scripts = []
    for _ in range(n_clips):
        script, total = [], rng.uniform(4.0, 16.0)
        while sum(s.duration for s in script) < total:
            duration = float(rng.uniform(0.5, 3.0))
            if rng.random() < 0.2:
                script.append(StandSegment(duration, True))
            else:
                vx, vy, yaw = rng.uniform([-0.6, -0.2, -0.4], [1.0, 0.2, 0.4])
                script.append(MotionSegment(duration, float(vx), float(vy), float(yaw)))
        scripts.append(script)
    return scripts, f"{n_clips} random scripts of 4-16 s (no collection)"


def shortened(script: list, seconds: float) -> list:
    """The script's first `seconds` (the smoke mode's short rollouts)."""
    kept, left = [], seconds
    for segment in script:
        if left <= 0.0:
            break
        kept.append(dataclasses.replace(segment, duration=min(segment.duration, left)))
        left -= segment.duration
    return kept


def sections(
    model,
    layout,
    stats,
    params,
    robot,
    rows: int,
    steering: list[bool],
    seconds: float = SECONDS,
    repeats: int | None = None,
) -> None:
    """One line: microseconds per batch step by section; one 10-s rollout's amortised cost.

    `repeats`: passes, the fastest kept (None: 5 for one row, 2 up to 32, else 1)."""
    script = [MotionSegment(seconds, 0.8, 0.0, 0.0)]
    specs = [RolloutSpec(script, steering[i % len(steering)]) for i in range(rows)]
    best = None
    if repeats is None:
        repeats = 5 if rows == 1 else 2 if rows <= 32 else 1
    for _ in range(repeats):  # best of: the CPU is shared
        timings: dict[str, float] = {}
        start = time.perf_counter()
        rollouts = generate_batch(
            model,
            layout,
            stats,
            specs,
            params.rollout,
            robot,
            contact_params=params.contacts,
            timings=timings,
        )
        wall = time.perf_counter() - start
        with tempfile.TemporaryDirectory() as folder:
            start = time.perf_counter()
            for i, rollout in enumerate(rollouts):
                write_trajectory(Path(folder) / f"{i}.h5", rollout.trajectory)
            timings["write"] = time.perf_counter() - start
        if best is None or wall < best[0]:
            best = wall, timings
    wall, timings = best
    steps = int(seconds * layout.rate_hz)
    per_step = [1e6 * timings[name] / steps for name in (*SECTIONS, "record", "write")]
    label = f"{rows:4d} {'steered' if steering == [True] else ('plain' if rows == 1 else 'half')}"
    rollout_s = (wall + timings["write"]) / rows
    print(
        f"{label:12s}"
        + "".join(f"{v:9.0f}" for v in per_step)
        + f"{1e6 * wall / steps:9.0f} {1e6 * wall / steps / rows:8.0f}"
        + f"{rollout_s:9.3f} s {seconds / rollout_s:6.0f}x"
    )


def full_set(params, layout, stats, robot, scripts: list[list], repeats: int = 3) -> None:
    """2 seeds x scripts x steering: one rollout at a time against one batch per seed.

    Each way runs `repeats` times, alternating, and keeps its fastest: a busy neighbour on a
    shared machine slows one pass, not the comparison."""
    models = [random_model(params, layout, seed) for seed in (0, 1)]
    jobs = [(script, steering) for script in scripts for steering in (False, True)]
    frames = sum(len(scenario_steps(script, layout.rate_hz)) for script, _ in jobs)
    kwargs = {"contact_params": params.contacts}

    def one_at_a_time() -> None:
        for model in models:
            for script, steering in jobs:
                generate_rollout(
                    model, layout, stats, script, params.rollout, steering, robot, **kwargs
                )

    def batched() -> None:
        for model in models:
            specs = [RolloutSpec(script, steering) for script, steering in jobs]
            generate_batch(model, layout, stats, specs, params.rollout, robot, **kwargs)

    walls: dict[str, list[float]] = {"one at a time": [], "batched (one batch per seed)": []}
    for _ in range(repeats):
        for name, run in zip(walls, (one_at_a_time, batched), strict=True):
            start = time.perf_counter()
            run()
            walls[name].append(time.perf_counter() - start)
    n = len(models) * len(jobs)
    generated = len(models) * frames / layout.rate_hz
    print(
        f"full set: {n} rollouts ({len(models)} seeds x {len(scripts)} scripts x 2 steering), "
        f"{generated:.0f} s generated; fastest of {repeats} alternating passes each"
    )
    for name, times in walls.items():
        wall = min(times)
        print(
            f"  {name:30s} {wall:7.1f} s, {wall / n:.3f} s a rollout, real-time factor "
            f"{generated / wall:5.0f}x  (passes: {', '.join(f'{t:.1f}' for t in times)} s)"
        )
    alone, batch = (min(times) for times in walls.values())
    print(f"  batched is {alone / batch:.1f}x faster")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--collection", type=Path, default=None)
    parser.add_argument("--smoke", action="store_true", help="tiny sizes: check that it runs")
    args = parser.parse_args(argv)
    seconds = 1.0 if args.smoke else SECONDS
    torch.set_num_threads(1)  # as the rollout stage: one process per core
    params = load_params()
    layout = window_layout(params.features, 50.0, "full")
    stats, robot = near_standing(layout), load_robot()
    model = random_model(params, layout, 0)
    print(
        f"{os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}, 1 torch thread; "
        f"MANN {layout.input_dim} -> {layout.output_dim}, {params.model.n_experts} experts, "
        f"hidden {params.model.prediction_hidden}"
    )
    print(
        f"\nus per batch step by section; a {seconds:.0f}-s rollout ({seconds * 50:.0f} steps) "
        "amortised over its batch (writing included)"
    )
    print(
        f"{'batch':12s}"
        + "".join(f"{n:>9s}" for n in (*SECTIONS, "record", "write"))
        + f"{'step':>9s} {'per row':>8s}{'rollout':>11s} {'RTF':>6s}"
    )
    repeats = 1 if args.smoke else None
    sections(model, layout, stats, params, robot, 1, [False], seconds, repeats)
    sections(model, layout, stats, params, robot, 1, [True], seconds, repeats)
    for rows in (4,) if args.smoke else (8, 32, 128):
        sections(model, layout, stats, params, robot, rows, [False, True], seconds, repeats)
    collection = args.collection or REPO_ROOT / params.features.input
    scripts, origin = clip_scripts(params, collection, 2 if args.smoke else N_CLIPS)
    names = params.rollout.scenario_names[:1] if args.smoke else params.rollout.scenario_names
    named = [params.rollout.scenarios[name] for name in names]
    print(f"\nclip scripts: {origin}")
    if args.smoke:
        print(f"smoke: {len(named)} named scenario and {len(scripts)} clip scripts cut to 1 s")
        named, scripts = ([shortened(s, seconds) for s in group] for group in (named, scripts))
    full_set(params, layout, stats, robot, named + scripts, repeats=1 if args.smoke else 3)
    return 0


if __name__ == "__main__":
    sys.exit(main())
