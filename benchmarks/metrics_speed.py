"""Speed of contact detection and of the paper's metrics on a 10 s, 50 Hz trajectory.

Prints milliseconds per call and the ratio to the 50 ms budget for 500 frames.
Run from the repository root: python -m benchmarks.metrics_speed

`--smoke`: the same calls on 50 frames, once each, to check that the benchmark still runs.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from pimann.core.contacts import detect_contacts
from pimann.core.params import load_params
from pimann.core.robot import load_robot
from pimann.core.trajectory import Trajectory
from pimann.evaluate.metrics import trajectory_metrics, trajectory_time_series

BUDGET_MS = 50.0


def walking_like(robot, frames: int = 500, rate: float = 50.0) -> Trajectory:
    rng = np.random.default_rng(0)
    t = np.arange(frames) / rate
    _, quaternion, joints = robot.split_configuration(robot.standing_configuration())
    wiggle = 0.1 * np.sin(2 * np.pi * t[:, None] + rng.uniform(0, 6, size=len(joints)))
    base = np.stack([0.3 * t, 0.01 * np.sin(np.pi * t), 0.77 + 0.01 * np.sin(2 * np.pi * t)], 1)
    return Trajectory(
        time=t,
        base_position=base,
        base_quaternion_xyzw=np.tile(quaternion, (frames, 1)),
        joint_positions=joints + wiggle,
        source="benchmark",
        rate_hz=rate,
    )


def best_of(function, repeats: int = 5) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        times.append(time.perf_counter() - start)
    return 1e3 * min(times)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--smoke", action="store_true", help="tiny sizes: check that it runs")
    args = parser.parse_args(argv)
    frames, repeats = (50, 1) if args.smoke else (500, 5)
    budget = BUDGET_MS * frames / 500
    robot = load_robot("retarget")
    loaded = load_params()
    params, contacts = loaded.evaluate, loaded.contacts
    trajectory = walking_like(robot, frames)
    for name, function in [
        ("detect_contacts", lambda: detect_contacts(robot, trajectory, contacts)),
        ("trajectory_metrics", lambda: trajectory_metrics(trajectory, robot, params, contacts)),
        (
            "trajectory_time_series",
            lambda: trajectory_time_series(trajectory, robot, params, contacts),
        ),
    ]:
        ms = best_of(function, repeats)
        print(
            f"{name:24s} {ms:7.2f} ms / {frames} frames  "
            f"({ms / budget:.2f} x the {budget:g} ms budget)"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
