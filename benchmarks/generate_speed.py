"""Speed of autoregressive generation with a full-size MANN (random weights), 500 steps.

Prints steps per second and the real-time factor (generated seconds per wall-clock second,
50 Hz) with and without steering, and the share of the time spent in the network itself.
Run from the repository root: python -m benchmarks.generate_speed
"""

from __future__ import annotations

import time

import numpy as np
import torch

from pimann.features import Normalisation, window_layout
from pimann.generate import generate
from pimann.mann import MANN
from pimann.params import MotionSegment, load_params
from pimann.robot import STANDING_BASE_HEIGHT, STANDING_JOINTS, load_robot

STEPS = 500


def main() -> None:
    params = load_params()
    layout = window_layout(params.features, 50.0, "full")
    torch.manual_seed(0)
    model = MANN(layout.input_dim, layout.output_dim, params.model, seeds=[0]).eval()
    # outputs near the standing state, so the random network's rollout stays sane
    y_mean = np.zeros(layout.output_dim)
    y_mean[layout.y_slices["joints"]] = STANDING_JOINTS
    y_mean[layout.y_slices["base_position"].start + 2] = STANDING_BASE_HEIGHT
    stats = Normalisation(
        np.zeros(layout.input_dim), np.ones(layout.input_dim), y_mean,
        np.full(layout.output_dim, 0.01),
    )  # fmt: skip
    scenario = [MotionSegment(STEPS / layout.rate_hz, 0.5, 0.0, 0.0)]
    robot = load_robot()

    x = torch.zeros(1, layout.input_dim)
    with torch.inference_mode():
        model(x)
        start = time.perf_counter()
        for _ in range(STEPS):
            model(x)
        network_s = time.perf_counter() - start
    print(f"network alone        {STEPS / network_s:8.0f} steps/s")

    for steering in (False, True):
        times = []
        for _ in range(3):
            start = time.perf_counter()
            generate(
                model, layout, stats, scenario, params.rollout, steering, robot,
                contact_params=params.evaluate,
            )  # fmt: skip
            times.append(time.perf_counter() - start)
        wall = min(times)
        print(
            f"steering={steering!s:5s}       {STEPS / wall:8.0f} steps/s, "
            f"real-time factor {STEPS / layout.rate_hz / wall:5.1f}x, "
            f"{wall:.3f} s per 10 s trajectory, network {100 * network_s / wall:.0f}% of it"
        )


if __name__ == "__main__":
    main()
