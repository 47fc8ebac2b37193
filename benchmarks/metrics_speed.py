"""Speed of contact detection and of the paper's metrics on a 10 s, 50 Hz trajectory.

Prints milliseconds per call and the ratio to the 50 ms budget for 500 frames.
Run from the repository root: python -m benchmarks.metrics_speed
"""

from __future__ import annotations

import time

import numpy as np

from pimann.contacts import detect_contacts
from pimann.metrics import trajectory_metrics, trajectory_time_series
from pimann.params import load_params
from pimann.robot import load_robot
from pimann.trajectory import Trajectory

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


def main() -> None:
    robot = load_robot("retarget")
    params = load_params().evaluate
    trajectory = walking_like(robot)
    for name, function in [
        ("detect_contacts", lambda: detect_contacts(robot, trajectory, params)),
        ("trajectory_metrics", lambda: trajectory_metrics(trajectory, robot, params)),
        ("trajectory_time_series", lambda: trajectory_time_series(trajectory, robot, params)),
    ]:
        ms = best_of(function)
        print(f"{name:24s} {ms:7.2f} ms / 500 frames  ({ms / BUDGET_MS:.2f} x the 50 ms budget)")


if __name__ == "__main__":
    main()
