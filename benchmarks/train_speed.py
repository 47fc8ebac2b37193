"""Training speed: seconds per optimiser step of a full-size MANN ensemble, with and without L_B.

Prints the time per step and per 1000 training samples (batch 32) for an ensemble of
`--members` seeds, so one full model (150 epochs) can be estimated from the sample count:
hours = 150 * samples / 1000 * (seconds per 1000 samples) / 3600.

    python -m benchmarks.train_speed [--device cuda] [--members 5] [--steps 30]
        [--precision float32|bfloat16|auto] [--smoke]

`--precision`: the network's products in that precision, as train.precision (auto: bfloat16
where the hardware has it).

`--smoke`: the same steps with tiny sizes (2 members of a MANN with 32 hidden units, 2 timed
steps after 1 warm-up step), to check that the benchmark still runs.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time

import numpy as np
import torch

from pimann.core.params import load_params
from pimann.learn.feature_layout import Normalisation, window_layout
from pimann.learn.mann import MANN
from pimann.learn.train import autocast, pick_device, pick_precision
from pimann.learn.training_loss import TrainingLoss


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--device", default="auto")
    parser.add_argument("--members", type=int, default=None, help="ensemble members (5)")
    parser.add_argument("--steps", type=int, default=None, help="timed steps (30)")
    parser.add_argument("--precision", choices=("float32", "bfloat16", "auto"), default="float32")
    parser.add_argument("--smoke", action="store_true", help="tiny sizes: check that it runs")
    args = parser.parse_args(argv)
    if args.members is None:
        args.members = 2 if args.smoke else 5
    if args.steps is None:
        args.steps = 2 if args.smoke else 30
    warm_up = 1 if args.smoke else 3
    params = load_params()
    model_params = params.model
    if args.smoke:
        model_params = dataclasses.replace(model_params, prediction_hidden=32, gating_hidden=8)
    device = pick_device(args.device)
    precision = pick_precision(args.precision, device)
    layout = window_layout(params.features, 50.0, "full")
    rng = np.random.default_rng(0)
    raw_y = rng.normal(size=(1000, layout.output_dim)) * 0.1
    stats = Normalisation.fit(rng.normal(size=(1000, layout.input_dim)), raw_y)
    loss_fn = TrainingLoss.from_params(params.train, layout, stats, device)
    batch = params.train.batch_size
    seeds = list(range(args.members))
    x = torch.randn(args.members, batch, layout.input_dim, device=device)
    y = torch.randn(args.members, batch, layout.output_dim, device=device)
    for weight in (0.0, 10.0):
        model = MANN.from_seeds(layout.input_dim, layout.output_dim, model_params, seeds)
        model.to(device).train()
        optimizer = torch.optim.AdamW(model.parameters(), lr=1e-4)
        for step in range(args.steps + warm_up):
            if step == warm_up:  # warm-up excluded
                if device.type == "cuda":
                    torch.cuda.synchronize()
                start = time.perf_counter()
            with autocast(device, precision):
                prediction = model(x)
            mse, pi = loss_fn(prediction.float(), y, weight != 0.0)
            optimizer.zero_grad()
            (mse + weight * pi).sum().backward()
            optimizer.step()
        if device.type == "cuda":
            torch.cuda.synchronize()
        per_step = (time.perf_counter() - start) / args.steps
        print(
            f"{device.type} {precision} w={weight:g} members={args.members} batch={batch}: "
            f"{per_step * 1e3:.1f} ms/step, {per_step * 1000 / batch:.2f} s per 1000 samples "
            f"(all {args.members} members), threads={torch.get_num_threads()}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
