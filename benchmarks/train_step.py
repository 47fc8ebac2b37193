"""Training-step throughput: plain MSE against MSE + physics-informed loss (SPEC 5, 6).

Random data of the study's sizes (input 130, output 100), one AdamW step per batch, for a
single MANN and a 5-member ensemble, at batch 32 and 256. Prints samples/s (model-samples:
an ensemble step trains E models on B samples each), the PI/plain time ratio (goal <= 1.3)
and projected wall time of one full-size model and of the 26-model sweep on this machine.

    python benchmarks/train_step.py [--seconds 4] [--device cpu] [--threads 1]
"""

from __future__ import annotations

import argparse
import time

import torch

from pimann.mann import MANN
from pimann.params import load_params
from pimann.physics_loss import PhysicsInformedLoss
from pimann.robot import load_robot

INPUT_DIM, OUTPUT_DIM = 130, 100
# output layout used here only to feed the PI loss: 7 future base linear and 7 angular
# velocities (the first is the current one), s, sdot, p, psi (SPEC 4)
V, W, S, SDOT = slice(0, 3), slice(21, 24), slice(42, 68), slice(68, 94)
P, PSI = slice(94, 97), slice(97, 100)
EPOCHS, SAMPLES = 150, 190_000


def make_step(model, pi_loss, mean, std, pi_weight):
    optimiser = torch.optim.AdamW(model.parameters(), lr=1e-4, weight_decay=0.0025, fused=True)

    def step(x, y):
        prediction = model(x)
        loss = (prediction - y).square().mean(dim=(-2, -1)).sum()  # summed over members
        if pi_weight:
            phys = prediction * std + mean  # denormalised prediction, physical units
            pi = pi_loss(
                phys[..., P], phys[..., PSI], phys[..., S], phys[..., V], phys[..., W],
                phys[..., SDOT],
            )  # fmt: skip
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=4.0, help="timed seconds per case")
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--threads", type=int, default=1, help="torch CPU threads")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    device = torch.device(args.device)
    params = load_params().model
    pi_loss = PhysicsInformedLoss(load_robot(), dtype=torch.float32).to(device)
    generator = torch.Generator().manual_seed(1)
    mean = (torch.randn(OUTPUT_DIM, generator=generator) * 0.1).to(device)
    std = (torch.rand(OUTPUT_DIM, generator=generator) * 0.5 + 0.1).to(device)
    print(f"device {device}, torch threads {torch.get_num_threads()}, float32")
    print(
        f"{'models':>7} {'batch':>6} {'plain samples/s':>16} {'PI samples/s':>13} {'PI/plain':>9}"
    )
    rates = {}
    for ensemble in (1, 5):
        for batch in (32, 256):
            steps = []
            for pi_weight in (0.0, 10.0):
                torch.manual_seed(0)
                model = MANN(INPUT_DIM, OUTPUT_DIM, params, ensemble=ensemble).to(device).train()
                steps.append(make_step(model, pi_loss, mean, std, pi_weight))
            rates[ensemble, batch] = row = throughputs(steps, ensemble, batch, args.seconds, device)
            plain, pi = row
            print(f"{ensemble:>7} {batch:>6} {plain:>16.0f} {pi:>13.0f} {plain / pi:>9.2f}")
    model_epochs = EPOCHS * SAMPLES
    single = model_epochs / rates[1, 32][1] / 3600
    # sweep: 26 models = 5 PI weights x 5 seeds (one 5-member ensemble per weight; w = 0 runs
    # without the PI term) + the ground-projected baseline (one model, no PI term)
    plain5, pi5 = rates[5, 32]
    sweep = (5 * model_epochs / plain5 + 4 * 5 * model_epochs / pi5) / 3600
    sweep += model_epochs / rates[1, 32][0] / 3600
    print(f"projected, {EPOCHS} epochs x {SAMPLES} samples at batch 32:")
    print(f"  one model with the PI term: {single:.1f} h")
    print(f"  26-model sweep (5-member ensembles + single baseline): {sweep:.1f} h")


if __name__ == "__main__":
    main()
