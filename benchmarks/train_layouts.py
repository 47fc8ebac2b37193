"""Training layouts on the CPU, side by side: member-samples per second of the quick sweep.

The training stages' work is 12 members (5 PI weights x 2 seeds, and the baseline's 2 seeds)
stepping through the same samples; what a layout buys is how many member-samples the machine
steps through a second. Measured here, in interleaved rounds on the same machine (the median
of the rounds, so a neighbour's burst moves every layout alike):

- `today`: what `train@<w>` does, one member per process, `train.workers` (2) processes of
  one thread (the seeds [0, 1] of one weight);
- `1x2 E=2`: one weight's 2 seeds as one ensemble in one process of 2 threads;
- `sweep 1x2 E=10`: every (w, seed) of the sweep as one ensemble (pimann.learn.sweep's step,
  eager), one process of 2 threads;
- `sweep 2x1 E=5`: the same sweep split in two processes of one thread, 5 members each;
- `today w=0` (no L_B: train@0 and the baseline) and the same 2 seeds as one ensemble in one
  process of 2 threads (how train_adherent trains its seeds, without L_B as there);
- each of `today` and the sweeps again in bfloat16 (train.precision: the products under
  autocast).

The step is the trainer's (pimann.learn.sweep's `_Step`: batch gather, the dropout-free
doubled pass where a member has w > 0, L_D + w L_B with L_B's kinematics, fused AdamW) on
random data of the study's layout; one step's cost does not depend on the data's values.
Prints member-samples/s of the whole machine (and per member) and the ratio to `today`, by
the wall clock and by the CPU seconds the processes got: on a shared machine a 2-thread
process loses far more to a neighbour than two 1-thread ones (each barrier waits for the
descheduled thread), which the wall clock shows and CPU time hides.

    python -m benchmarks.train_layouts [--seconds 6] [--rounds 3] [--only NAME ...] [--smoke]

`--smoke`: tiny network, 0.2 s a case, one round, the processes not started together: checks
that it runs.
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import sys
import time

import numpy as np
import torch

from pimann.core.parallel import pool_map
from pimann.core.params import ModelParams, load_params
from pimann.learn.feature_layout import Normalisation, window_layout
from pimann.learn.mann import MANN
from pimann.learn.sweep import _Step
from pimann.learn.training_loss import TrainingLoss


@dataclasses.dataclass(frozen=True)
class Layout:
    """`processes` processes of `threads` threads, each stepping `weights` x its seeds."""

    name: str
    processes: int
    threads: int
    weights: tuple[float, ...]  # each process's members' PI weights
    precision: str = "float32"

    @property
    def members(self) -> int:
        return self.processes * len(self.weights)


@dataclasses.dataclass(frozen=True)
class _Job:
    layout: Layout
    model: ModelParams
    seconds: float
    start_at: float  # time.time() at which every process of the layout starts stepping


def _run(job: _Job) -> tuple[int, float, float]:
    """One process's share: (steps, wall seconds, CPU seconds) stepped from `start_at`."""
    torch.set_num_threads(job.layout.threads)
    params = load_params()
    config = params.train
    layout = window_layout(params.features, 50.0, "full")
    rng = np.random.default_rng(0)
    n = 4096
    x = rng.normal(size=(n, layout.input_dim))
    y = rng.normal(size=(n, layout.output_dim))
    stats = Normalisation.fit(x, y)
    device = torch.device("cpu")
    loss_fn = TrainingLoss.from_params(config, layout, stats, device)
    weights = torch.tensor(job.layout.weights)
    seeds = list(range(len(weights)))
    model = MANN.from_seeds(layout.input_dim, layout.output_dim, job.model, seeds).train()
    model.seed_dropout(seeds)
    optimizer = torch.optim.AdamW(model.parameters(), lr=1e-4, weight_decay=0.0, fused=True)
    batch = config.batch_size
    step = _Step(
        model,
        optimizer,
        loss_fn,
        (torch.as_tensor(x, dtype=torch.float32), torch.as_tensor(y, dtype=torch.float32)),
        weights,
        torch.ones(()),
        torch.zeros(2, len(weights)),
        batch,
        bool((weights != 0).any()) and not config.pi_dropout,
        job.layout.precision,
    )
    orders = torch.as_tensor(np.stack([rng.permutation(n) for _ in seeds]))
    for k in range(2):  # warm-up
        step.index.copy_(orders[:, k * batch : (k + 1) * batch])
        step()
    time.sleep(max(0.0, job.start_at - time.time()))
    start, cpu, steps = time.perf_counter(), time.process_time(), 0
    while time.perf_counter() - start < job.seconds:
        at = (steps * batch) % (n - batch)
        step.index.copy_(orders[:, at : at + batch])
        step()
        steps += 1
    return steps, time.perf_counter() - start, time.process_time() - cpu


def measure(
    layout: Layout, model: ModelParams, seconds: float, delay: float = 8.0
) -> tuple[float, float]:
    """Member-samples per second of the whole machine in `layout`: by the wall clock, and
    by the CPU seconds the processes got (x their threads: what a machine of its own would
    reach; a neighbour's load slows the first, much less the second)."""
    delay = delay if layout.processes > 1 else 0.0  # the spawned processes' imports first
    job = _Job(layout, model, seconds, time.time() + delay)
    results = pool_map(_run, [job] * layout.processes, layout.processes, None)
    batch = load_params().train.batch_size
    per_member = min(steps * batch / elapsed for steps, elapsed, _ in results)
    members = len(layout.weights)
    cores = layout.processes * layout.threads
    cpu = sum(steps * batch * members / used for steps, _, used in results) / layout.processes
    return per_member * layout.members, cpu * cores


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--seconds", type=float, default=6.0, help="timed seconds a case")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--only", nargs="*", help="the layouts whose names contain one of these")
    parser.add_argument("--smoke", action="store_true", help="tiny sizes: check that it runs")
    args = parser.parse_args(argv)
    params = load_params()
    model = params.model
    if args.smoke:
        model = dataclasses.replace(model, prediction_hidden=32, gating_hidden=8)
        args.seconds, args.rounds = 0.2, 1
    delay = 0.0 if args.smoke else 8.0  # smoke: the processes need not start together
    sweep = tuple(float(w) for w in params.train.pi_weights)  # 5 weights
    layouts = [
        Layout("today w=10: 2x1, E=1", 2, 1, (10.0,)),
        Layout("w=10: 1x2 threads, E=2", 1, 2, (10.0, 10.0)),
        Layout("sweep: 1x2 threads, E=10", 1, 2, sweep * 2),
        Layout("sweep: 2x1, E=5", 2, 1, sweep),
        Layout("today w=0: 2x1, E=1", 2, 1, (0.0,)),
        Layout("w=0: 1x2 threads, E=2", 1, 2, (0.0, 0.0)),
        Layout("today w=10 bf16: 2x1, E=1", 2, 1, (10.0,), "bfloat16"),
        Layout("sweep bf16: 2x1, E=5", 2, 1, sweep, "bfloat16"),
        Layout("sweep bf16: 1x2 threads, E=10", 1, 2, sweep * 2, "bfloat16"),
    ]
    if args.only:  # the first (today's) always, as the reference
        layouts = layouts[:1] + [x for x in layouts[1:] if any(o in x.name for o in args.only)]
    rates: dict[str, list[tuple[float, float]]] = {layout.name: [] for layout in layouts}
    for round_ in range(args.rounds):
        for layout in layouts:
            rates[layout.name].append(measure(layout, model, args.seconds, delay))
            wall, cpu = rates[layout.name][-1]
            print(f"round {round_ + 1} {layout.name}: wall {wall:.0f}, cpu {cpu:.0f}", flush=True)
    medians = {
        name: [statistics.median(r[i] for r in rounds) for i in (0, 1)]
        for name, rounds in rates.items()
    }
    base_wall, base_cpu = medians[layouts[0].name]
    print("\nmember-samples/s of the machine (per member), by the wall clock and by CPU time")
    print(f"{'layout':30s} {'wall':>12s} {'x today':>8s} {'CPU time':>12s} {'x today':>8s}")
    for layout in layouts:
        wall, cpu = medians[layout.name]
        print(
            f"{layout.name:30s} {wall:6.0f} ({wall / layout.members:4.0f}) {wall / base_wall:8.2f}"
            f" {cpu:6.0f} ({cpu / layout.members:4.0f}) {cpu / base_cpu:8.2f}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
