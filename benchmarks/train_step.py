"""Training-step throughput: plain MSE against MSE + physics-informed loss (paper Sec. III-B).

Random data of the study's sizes (input 130, output 100), one AdamW step per batch, for a
single MANN and a 5-member ensemble, at batch 32 and 256. Prints samples/s (model-samples:
an ensemble step trains E models on B samples each), the PI/plain time ratio (goal <= 1.3),
the PI step in bfloat16 (train.precision: the products under autocast, the losses float32)
beside it with the bf16/float32 time ratio, and projected wall time of one full-size model
and of the 26-model sweep on this machine in both precisions.

Then, on the whole machine, the 5 seeds of one weight at batch 32 with the PI term: one
process with every core's thread against `train.workers` single-threaded processes (what the
`train` stage does), wall-clock throughput, and the projected cost of the paper-size study.

    python -m benchmarks.train_step [--seconds 4] [--device cpu] [--threads 1] [--smoke]

`--smoke`: every part with tiny sizes (a MANN of 32 hidden units, 0.05 timed seconds per case,
the workers' clocks 1 s after the start), to check that it still runs.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time

import torch

from pimann.core.parallel import pool_map
from pimann.core.params import load_params
from pimann.core.robot import load_robot
from pimann.learn.mann import MANN
from pimann.learn.physics_loss import PhysicsInformedLoss
from pimann.learn.train import autocast, cpu_has_bf16, seed_groups

INPUT_DIM, OUTPUT_DIM = 130, 100
# output layout used here only to feed the PI loss: 7 future base linear and 7 angular
# velocities (the first is the current one), s, sdot, p, psi (paper Sec. III-A)
V, W, S, SDOT = slice(0, 3), slice(21, 24), slice(42, 68), slice(68, 94)
P, PSI = slice(94, 97), slice(97, 100)
# the paper's size: 150 epochs over the whole walking set (720 clips + mirrors, minus the
# 2.2 s window at the clip ends, 90% for training: ~254k samples; the paper's data ~200k)
EPOCHS, SAMPLES = 150, 254_000


def model_params(smoke: bool = False):
    """params `model`; `smoke`: its tiny version (32 hidden units, 8 in the gate)."""
    params = load_params().model
    if smoke:
        params = dataclasses.replace(params, prediction_hidden=32, gating_hidden=8)
    return params


def make_step(
    model, pi_loss, mean, std, pi_weight, clean: str | None = None, precision: str = "float32"
):
    """One AdamW step; `clean` (train.pi_dropout: false): L_B on the dropout-free prediction,
    from a second eval-mode pass ("two_pass") or one doubled pass ("fused", what train does);
    `precision` bfloat16: the network under autocast, as pimann.learn.train runs it."""
    optimiser = torch.optim.AdamW(model.parameters(), lr=1e-4, weight_decay=0.0025, fused=True)
    device = next(model.parameters()).device

    def step(x, y):
        pi_prediction = None
        with autocast(device, precision):
            if clean == "fused":
                prediction, pi_prediction = model.forward_with_clean(x)
            else:
                prediction = model(x)
            if clean == "two_pass":
                pi_prediction = model.eval()(x)
                model.train()
        prediction = prediction.float()
        pi_prediction = None if pi_prediction is None else pi_prediction.float()
        loss = (prediction - y).square().mean(dim=(-2, -1)).sum()  # summed over members
        if pi_weight:
            pi_prediction = prediction if pi_prediction is None else pi_prediction
            phys = pi_prediction * std + mean  # denormalised prediction, physical units
            pi = pi_loss(
                phys[..., P],
                phys[..., PSI],
                phys[..., S],
                phys[..., V],
                phys[..., W],
                phys[..., SDOT],
            )
            loss = loss + pi_weight * pi.mean(-1).sum()
        optimiser.zero_grad(set_to_none=True)
        loss.backward()
        optimiser.step()

    return step


def throughputs(steps, ensemble, batch, seconds, device) -> list[float]:
    """Model-samples per second of each step function, best of 5 interleaved timed rounds.

    Interleaving and taking the best round keep the ratio fair when other processes share
    the CPU; CPU time of this process (not wall time) is what is measured on the CPU.
    """
    generator = torch.Generator().manual_seed(0)
    x = torch.randn(ensemble, batch, INPUT_DIM, generator=generator).to(device)
    y = torch.randn(ensemble, batch, OUTPUT_DIM, generator=generator).to(device)
    clock = time.perf_counter if device.type == "cuda" else time.process_time
    best = [0.0] * len(steps)
    for step in steps:
        for _ in range(3):
            step(x, y)
    for _ in range(5):
        for i, step in enumerate(steps):
            if device.type == "cuda":
                torch.cuda.synchronize()
            start, count = clock(), 0
            while clock() - start < seconds / 5:
                step(x, y)
                count += 1
            if device.type == "cuda":
                torch.cuda.synchronize()
            best[i] = max(best[i], count * batch * ensemble / (clock() - start))
    return best


def _ensemble_rate(job: tuple[list[int], int, float, float, bool]) -> float:
    """Wall-clock model-samples/s of one PI ensemble of `seeds` (one worker process)."""
    seeds, threads, seconds, start_at, smoke = job
    torch.set_num_threads(threads)
    params = model_params(smoke)
    pi_loss = PhysicsInformedLoss(load_robot(), dtype=torch.float32)
    generator = torch.Generator().manual_seed(1)
    mean, std = torch.zeros(OUTPUT_DIM), torch.ones(OUTPUT_DIM) * 0.3
    model = MANN.from_seeds(INPUT_DIM, OUTPUT_DIM, params, seeds).train()
    model.seed_dropout(seeds)
    step = make_step(model, pi_loss, mean, std, 10.0)
    x = torch.randn(len(seeds), 32, INPUT_DIM, generator=generator)
    y = torch.randn(len(seeds), 32, OUTPUT_DIM, generator=generator)
    for _ in range(5):
        step(x, y)
    while time.time() < start_at:  # the workers start their clocks together
        time.sleep(0.001)
    start, count = time.perf_counter(), 0
    while time.perf_counter() - start < seconds:
        step(x, y)
        count += 1
    return count * 32 * len(seeds) / (time.perf_counter() - start)


def whole_machine(seconds: float, smoke: bool = False) -> None:
    """The 5 seeds of one weight: one multi-threaded process vs single-threaded workers."""
    cores = os.cpu_count() or 1
    workers = min(load_params().train.workers, cores)
    seeds = list(range(5))
    print(f"whole machine ({cores} cores), 5 seeds, batch 32, MSE + PI, wall clock:")
    one = _ensemble_rate((seeds, cores, seconds, 0.0, smoke))
    print(f"  1 process x {cores} threads: {one:8.0f} model-samples/s")
    start_at = time.time() + (1.0 if smoke else 15.0)  # after every worker has built its model
    jobs = [(group, 1, seconds, start_at, smoke) for group in seed_groups(seeds, workers)]
    split = sum(pool_map(_ensemble_rate, jobs, workers, "workers"))
    print(f"  {workers} processes x 1 thread: {split:8.0f} model-samples/s ({split / one:.2f}x)")
    best = max(one, split)
    hours = EPOCHS * SAMPLES / best / 3600
    print(f"  one paper-size model ({EPOCHS} epochs x {SAMPLES} samples): {hours:.2f} h")
    print(f"  26 models (5 weights x 5 seeds + baseline): {26 * hours:.1f} h")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=None, help="timed seconds per case (4)")
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--threads", type=int, default=1, help="torch CPU threads")
    parser.add_argument("--smoke", action="store_true", help="tiny sizes: check that it runs")
    args = parser.parse_args(argv)
    if args.seconds is None:
        args.seconds = 0.05 if args.smoke else 4.0
    torch.set_num_threads(args.threads)
    device = torch.device(args.device)
    params = model_params(args.smoke)
    pi_loss = PhysicsInformedLoss(load_robot(), dtype=torch.float32).to(device)
    generator = torch.Generator().manual_seed(1)
    mean = (torch.randn(OUTPUT_DIM, generator=generator) * 0.1).to(device)
    std = (torch.rand(OUTPUT_DIM, generator=generator) * 0.5 + 0.1).to(device)
    fast_bf16 = cpu_has_bf16() if device.type == "cpu" else torch.cuda.is_bf16_supported()
    print(
        f"device {device}, torch threads {torch.get_num_threads()}, "
        f"bf16 in hardware: {'yes' if fast_bf16 else 'no'}"
    )
    print(
        f"{'models':>7} {'batch':>6} {'plain samples/s':>16} {'PI samples/s':>13} {'PI/plain':>9}"
        f" {'PI bf16 samples/s':>18} {'bf16/f32 time':>14}"
    )
    rates = {}
    for ensemble in (1, 5):
        for batch in (32, 256):
            steps = []
            for pi_weight, precision in ((0.0, "float32"), (10.0, "float32"), (10.0, "bfloat16")):
                torch.manual_seed(0)
                model = MANN(INPUT_DIM, OUTPUT_DIM, params, ensemble=ensemble).to(device).train()
                steps.append(make_step(model, pi_loss, mean, std, pi_weight, None, precision))
            rates[ensemble, batch] = row = throughputs(steps, ensemble, batch, args.seconds, device)
            plain, pi, pi_bf16 = row
            print(
                f"{ensemble:>7} {batch:>6} {plain:>16.0f} {pi:>13.0f} {plain / pi:>9.2f}"
                f" {pi_bf16:>18.0f} {pi / pi_bf16:>14.2f}"
            )
    print("L_B on the dropout-free prediction (train.pi_dropout: false), 1 model, batch 32:")
    steps = []
    for clean in (None, "two_pass", "fused"):
        torch.manual_seed(0)
        model = MANN(INPUT_DIM, OUTPUT_DIM, params).to(device).train()
        steps.append(make_step(model, pi_loss, mean, std, 10.0, clean))
    same, two_pass, fused = throughputs(steps, 1, 32, args.seconds, device)
    print(
        f"  time over pi_dropout true: two passes {same / two_pass:.2f}x, "
        f"one doubled pass {same / fused:.2f}x (two/one {fused / two_pass:.2f}x)"
    )
    model_epochs = EPOCHS * SAMPLES
    single = model_epochs / rates[1, 32][1] / 3600
    # sweep: 26 models = 5 PI weights x 5 seeds (one 5-member ensemble per weight; w = 0 runs
    # without the PI term) + the ground-projected baseline (one model, no PI term)
    plain5, pi5, _ = rates[5, 32]
    sweep = (5 * model_epochs / plain5 + 4 * 5 * model_epochs / pi5) / 3600
    sweep += model_epochs / rates[1, 32][0] / 3600
    sweep_bf16 = sweep * rates[5, 32][1] / rates[5, 32][2]  # the PI steps' ratio for all
    print(f"projected, {EPOCHS} epochs x {SAMPLES} samples at batch 32, one process:")
    print(
        f"  one model with the PI term: {single:.1f} h float32, "
        f"{single * rates[1, 32][1] / rates[1, 32][2]:.1f} h bfloat16"
    )
    print(
        f"  26-model sweep (5-member ensembles + single baseline): {sweep:.1f} h float32, "
        f"{sweep_bf16:.1f} h bfloat16"
    )
    if device.type == "cpu":
        whole_machine(args.seconds, args.smoke)
    return 0


if __name__ == "__main__":
    sys.exit(main())
