"""The study on one accelerator: step times, the paper-size sweep projected, and a training.

1. The PI training step (L_D + 10 L_B, AdamW as pimann.learn.train builds it) of the 5-seed
   ensemble at the paper's batch (train.batch_size), in float32 and, where the device has
   it, bfloat16; also the plain step of w = 0 and of the single baseline model.
2. The paper-size sweep projected from them: 26 models (5 PI weights x 5 seeds as one
   ensemble each, w = 0 without L_B, and the ground-projected baseline), 150 epochs over
   every clip (254k training samples, as benchmarks.train_step counts them).
3. The largest real training (pimann.learn.train.train_models, 5 seeds, w = 10) that fits
   `--budget-s`: every training sample of `--dataset` and as many epochs as the measured
   step time allows (at most train.epochs), with its wall time against the projection.
4. The sweep as the stages train it on a GPU (pimann.learn.sweep: every weight of
   train.pi_weights x 5 seeds in one ensemble), eager and, on CUDA, replayed as a CUDA graph,
   side by side in this run: wall seconds an epoch on `--dataset` and the paper-size sweep
   (150 epochs over 254k samples) projected from them.

    python -m benchmarks.gpu_study [--device cuda] [--budget-s 300] [--dataset PATH] [--smoke]

On a CPU it runs too (what `--smoke` checks: a tiny network, 0.05 s per timed case, a
synthetic dataset of a few clips and a few seconds of training). Without `--dataset` (and
no data/features/full.h5 in the checkout) the training part uses that synthetic dataset.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch
from scipy.spatial.transform import Rotation

from benchmarks.train_step import EPOCHS, SAMPLES, model_params
from pimann.core.params import Params, load_params
from pimann.core.paths import REPO_ROOT
from pimann.core.robot import STANDING_JOINTS
from pimann.core.trajectory import Trajectory
from pimann.learn.dataset import read_dataset, write_dataset
from pimann.learn.feature_layout import Normalisation, window_layout
from pimann.learn.features import build_dataset
from pimann.learn.mann import MANN
from pimann.learn.sweep import train_sweep
from pimann.learn.train import autocast, pick_device, train_models
from pimann.learn.training_loss import TrainingLoss

SEEDS = [0, 1, 2, 3, 4]
PI_WEIGHT = 10.0


def step_seconds(
    params: Params,
    members: int,
    pi_weight: float,
    precision: str,
    device: torch.device,
    seconds: float,
) -> float:
    """Wall seconds of one training step (the best of 5 timed rounds after a warm-up)."""
    layout = window_layout(params.features, 50.0, "full")
    rng = np.random.default_rng(0)
    stats = Normalisation.fit(
        rng.normal(size=(1000, layout.input_dim)), rng.normal(size=(1000, layout.output_dim)) * 0.1
    )
    loss_fn = TrainingLoss.from_params(params.train, layout, stats, device)
    batch = params.train.batch_size
    model = MANN.from_seeds(layout.input_dim, layout.output_dim, params.model, SEEDS[:members])
    model.to(device).train()
    model.seed_dropout(SEEDS[:members])
    fused = device.type in ("cpu", "cuda")
    optimizer = torch.optim.AdamW(model.parameters(), lr=1e-4, fused=fused)
    x = torch.randn(members, batch, layout.input_dim, device=device)
    y = torch.randn(members, batch, layout.output_dim, device=device)

    def step() -> None:
        with autocast(device, precision):
            prediction = model(x)
        mse, pi = loss_fn(prediction.float(), y, pi_weight != 0.0)
        optimizer.zero_grad(set_to_none=True)
        (mse + pi_weight * pi).sum().backward()
        optimizer.step()

    def sync() -> None:
        if device.type == "cuda":
            torch.cuda.synchronize()

    for _ in range(3):
        step()
    best = math.inf
    for _ in range(5):
        sync()
        start, count = time.perf_counter(), 0
        while count == 0 or time.perf_counter() - start < seconds / 5:
            step()
            count += 1
        sync()
        best = min(best, (time.perf_counter() - start) / count)
    return best


def sweep_hours(
    ensemble_pi: float, ensemble_plain: float, single_plain: float, batch: int
) -> float:
    """The 26-model sweep: 4 PI ensembles, the w = 0 ensemble, the single baseline."""
    steps = EPOCHS * math.ceil(SAMPLES / batch)
    return steps * (4 * ensemble_pi + ensemble_plain + single_plain) / 3600


def synthetic_dataset(path: Path, params: Params, clips: int = 6, frames: int = 200) -> Path:
    """Walking-like clips (a base at constant velocity, sinusoidal joints) as features."""
    collection = []
    rate = 50.0
    for k in range(clips):
        for mirrored in (False, True):
            t = np.arange(frames) / rate
            gait = np.sin(2 * np.pi * 1.1 * t + k + float(mirrored))
            trajectory = Trajectory(
                contacts=np.stack([gait > -0.3, gait < 0.3], axis=1),
                time=t,
                base_position=np.array([0.0, 0.0, 0.77]) + t[:, None] * [0.2 + 0.1 * k, 0, 0],
                base_quaternion_xyzw=Rotation.from_euler("z", 0.1 * (k - 2) * t[:, None]).as_quat(),
                joint_positions=STANDING_JOINTS + 0.2 * gait[:, None],
                source=f"src{k}",
                rate_hz=rate,
                attrs={"mirrored": mirrored},
            )
            collection.append((f"src{k}" + ("_mirror" if mirrored else ""), trajectory))
    write_dataset(path, build_dataset(collection, params.features, "full"))
    return path


def whole_data_run(
    params: Params, epochs: int, precision: str, device: torch.device, **train: object
) -> Params:
    """`params` training on every sample for `epochs`, at `precision` on `device`."""
    changes = dict(epochs=epochs, max_train_samples=None, precision=precision)
    whole = dataclasses.replace(params.train, **changes, device=device.type, **train)
    return dataclasses.replace(params, train=whole)


def largest_training(
    params: Params,
    dataset: Path,
    samples: int,
    step_s: float,
    budget_s: float,
    device: torch.device,
    precision: str,
    out: Path,
) -> None:
    """Train the 5 seeds on the `samples` of `dataset` for the epochs that fit `budget_s`."""
    epoch_s = math.ceil(samples / params.train.batch_size) * step_s
    # the test loss, the checkpoint and the start take their share: plan on 70% for steps
    epochs = max(1, min(params.train.epochs, int(0.7 * budget_s / epoch_s)))
    run = whole_data_run(params, epochs, precision, device)
    print(
        f"training that fits {budget_s:.0f} s: 5 seeds, w={PI_WEIGHT:g}, {samples} samples, "
        f"{epochs} epochs ({epochs * epoch_s:.1f} s of steps projected), {precision}"
    )
    start = time.perf_counter()
    metas = train_models(dataset, out / "models", PI_WEIGHT, SEEDS, run, device)
    wall = time.perf_counter() - start
    best = ", ".join(f"{seed}: {meta['best_test_loss']:.4f}" for seed, meta in metas.items())
    print(f"  trained in {wall:.1f} s ({wall / epochs:.2f} s an epoch); best test loss {best}")


def sweep_epochs(
    params: Params,
    dataset: Path,
    samples: int,
    step_s: float,
    budget_s: float,
    device: torch.device,
    precision: str,
) -> None:
    """The stages' sweep, eager and (on CUDA) graphed, each for the epochs that fit half of
    `budget_s`; wall seconds an epoch and the paper-size sweep projected from them."""
    weights = list(params.train.pi_weights)
    members = len(weights) * len(SEEDS)
    steps = math.ceil(samples / params.train.batch_size)
    estimate = steps * step_s * members / len(SEEDS)  # eager: the 5-seed step, scaled
    epochs = max(1, min(params.train.epochs, int(0.35 * budget_s / estimate)))
    run = whole_data_run(params, epochs, precision, device, seeds=SEEDS)
    modes = [False] + ([True] if device.type == "cuda" else [])
    print(
        f"the sweep as the stages train it: {members} models (w {weights} x seeds {SEEDS}), "
        f"{samples} samples, {epochs} epochs, {precision}"
    )
    per_epoch = {}
    for graph in modes:
        start = time.perf_counter()
        train_sweep(dataset, weights, SEEDS, run, device, graph=graph, progress=None)
        per_epoch[graph] = (time.perf_counter() - start) / epochs
    paper = EPOCHS * SAMPLES / samples
    cells = [
        f"{'graphed' if graph else 'eager'} {t:.2f} s an epoch "
        f"({t / steps * 1e3:.2f} ms a step), paper size {paper * t / 60:.1f} min"
        for graph, t in per_epoch.items()
    ]
    print("  " + " | ".join(cells))
    if len(per_epoch) == 2:
        print(f"  graphed / eager: {per_epoch[True] / per_epoch[False]:.2f}")
    else:
        print("  graphed: needs CUDA")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--device", default="auto")
    parser.add_argument("--budget-s", type=float, default=None, help="training part (300 s)")
    parser.add_argument("--dataset", type=Path, default=None, help="features (full.h5)")
    parser.add_argument("--seconds", type=float, default=None, help="timed seconds per case (2)")
    parser.add_argument("--smoke", action="store_true", help="tiny sizes: check that it runs")
    args = parser.parse_args(argv)
    seconds = args.seconds or (0.05 if args.smoke else 2.0)
    budget = args.budget_s or (3.0 if args.smoke else 300.0)
    device = pick_device(args.device)
    base = load_params()
    params = dataclasses.replace(base, model=model_params(args.smoke))
    if device.type == "cpu":
        torch.set_num_threads(1 if args.smoke else torch.get_num_threads())
    bf16 = torch.cuda.is_bf16_supported() if device.type == "cuda" else True
    name = torch.cuda.get_device_name(device) if device.type == "cuda" else "cpu"
    batch = params.train.batch_size
    print(f"device {device} ({name}), batch {batch}, torch threads {torch.get_num_threads()}")
    precisions = ["float32"] + (["bfloat16"] if bf16 else [])
    times = {}
    for precision in precisions:
        times[precision] = (
            step_seconds(params, 5, PI_WEIGHT, precision, device, seconds),
            step_seconds(params, 5, 0.0, precision, device, seconds),
            step_seconds(params, 1, 0.0, precision, device, seconds),
        )
        pi5, plain5, plain1 = times[precision]
        print(
            f"  {precision}: 5-seed PI step {pi5 * 1e3:.2f} ms, 5-seed plain {plain5 * 1e3:.2f} ms,"
            f" single plain {plain1 * 1e3:.2f} ms; paper-size sweep "
            f"({EPOCHS} epochs x {SAMPLES} samples, 26 models): "
            f"{sweep_hours(pi5, plain5, plain1, batch):.2f} h"
        )
    if bf16:
        print(
            f"  bf16/float32 time of the 5-seed PI step: "
            f"{times['bfloat16'][0] / times['float32'][0]:.2f}"
        )
    fastest = min(times, key=lambda p: times[p][0])
    with tempfile.TemporaryDirectory() as scratch:
        out = Path(scratch)
        dataset = args.dataset
        default = REPO_ROOT / base.features.output_dir / "full.h5"
        if dataset is None and not args.smoke and default.is_file():
            dataset = default
        if dataset is None:
            dataset = synthetic_dataset(out / "full.h5", params, 3 if args.smoke else 6)
            print(f"  (synthetic dataset: no features given, {default} absent or --smoke)")
        samples = len(read_dataset(dataset).x_train)
        step_s = times[fastest][0]
        largest_training(params, dataset, samples, step_s, budget, device, fastest, out)
        sweep_epochs(params, dataset, samples, step_s, budget, device, fastest)
    return 0


if __name__ == "__main__":
    sys.exit(main())
