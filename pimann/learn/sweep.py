"""The PI-weight sweep as one ensemble on one device, its training step a CUDA graph.

Why: on a GPU, pimann.learn.train's ensemble of one weight's seeds leaves the device idle. A
step at the paper's batch of 32 is a few hundred tiny kernels whose launches, not their
arithmetic, set its time. Here every (PI weight, seed) of the sweep is one member of one
ensemble, member k's loss L_D + w_k L_B with its own w_k, and the whole step (forward, loss,
backward, AdamW) is captured once in a CUDA graph and replayed. The training data stay on
the device, each step's batch is a device-side copy out of the epoch's sample orders, and
the test loss, each member's best epoch and the loss history stay on the device until the
run ends, so nothing inside an epoch waits for the host.

Members never mix (pimann.learn.mann): member (w, s) draws its sample order, initial weights
and dropout masks from seed s exactly as pimann.learn.train's ensemble of weight w does, so
it ends within float tolerance of that training on the same device. Tolerance, not bit
identity, because the learning rate and the decoupled weight decay are device tensors here
(a replay reads them, so the per-epoch schedule needs no new capture): the decay is one
multiply, 1 - lr wd, before a weight-decay-free AdamW step; and with `train.pi_dropout`
false a w = 0 member takes the doubled forward pass the PI members need.

Off CUDA the same step runs eagerly (what the CPU's tests check); on the CPU the stages keep
pimann.learn.train, so the CPU's models do not change.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import dataclasses
import json
import logging
import math
import shutil
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch

from pimann.core.atomic import atomic_path
from pimann.core.errors import PimannError
from pimann.core.params import Params
from pimann.core.progress import Progress
from pimann.core.stage_times import note
from pimann.learn.dataset import FeatureDataset, read_dataset
from pimann.learn.epochs import epoch_order, epoch_seed, schedule_factor
from pimann.learn.held_out_loss import batched_loss
from pimann.learn.mann import MANN
from pimann.learn.train import (
    _deterministic,
    _fingerprint,
    check_cublas,
    pick_precision,
    training_subset,
    write_models,
)
from pimann.learn.training_loss import TrainingLoss

log = logging.getLogger(__name__)

SWEEP_DIR = ".sweep"  # beside the weights' model folders: the trained sweep until all are out
CHECKPOINT_EVERY_S = 120.0  # a checkpoint costs a host copy of every member's optimiser state


@dataclasses.dataclass(frozen=True)
class SweepMember:
    """One model of the sweep: its PI weight w and its seed."""

    pi_weight: float
    seed: int


def sweep_members(pi_weights: list[float], seeds: list[int]) -> list[SweepMember]:
    """Every (w, seed), weight-major: the ensemble's member order."""
    return [SweepMember(float(w), int(s)) for w in pi_weights for s in seeds]


def uses_sweep(device: torch.device) -> bool:
    """Whether the stages train the sweep together: on a CUDA device. Not on the CPU, where
    its step is bound by the products' arithmetic and the sweep trains the five weights only
    about 1.15x faster than their own stages (docs/performance.md), not worth other models."""
    return device.type == "cuda"


class _Step:
    """One training step of every member on fixed buffers, so that a CUDA graph can replay it.

    Reads the batch from `index` (E, size) and the schedule from the `lr` and `decay`
    tensors; steps on each member's L = L_D + w L_B (`weights` (E,) its w) and adds its
    batch-summed (L_D, L_B) to `totals` (2, E).
    """

    def __init__(
        self,
        model: MANN,
        optimizer: torch.optim.Optimizer,
        loss_fn: TrainingLoss,
        data: tuple[torch.Tensor, torch.Tensor],
        weights: torch.Tensor,
        decay: torch.Tensor,
        totals: torch.Tensor,
        size: int,
        clean_pass: bool,
        precision: str,
    ):
        self.model, self.optimizer, self.loss_fn = model, optimizer, loss_fn
        self.x, self.y = data
        self.weights, self.decay, self.totals = weights, decay, totals
        self.clean_pass, self.precision, self.size = clean_pass, precision, size
        self.with_pi = bool((weights != 0).any())
        self.index = torch.zeros(len(weights), size, dtype=torch.long, device=weights.device)
        self.parameters = list(model.parameters())

    def __call__(self) -> None:
        x, y = self.x[self.index], self.y[self.index]
        clean = None
        # autocast's cast cache off: a graph must recast the weights at every replay
        with torch.autocast(x.device.type, torch.bfloat16, self.precision == "bfloat16", False):
            if self.clean_pass:
                prediction, clean = self.model.forward_with_clean(x)
            else:
                prediction = self.model(x)
        prediction = prediction.float()  # the losses in float32
        clean = None if clean is None else clean.float()
        loss = self.loss_fn(prediction, y, self.with_pi, clean)
        self.optimizer.zero_grad(set_to_none=True)
        loss.total(self.weights).sum().backward()
        with torch.no_grad():
            torch._foreach_mul_(self.parameters, self.decay)  # AdamW's decoupled decay
        self.optimizer.step()
        self.totals += torch.stack([loss.data.detach(), loss.physics.detach()]) * self.size


def _capture(steps: list[_Step], generators: list[torch.Generator]) -> list[Callable[[], None]]:
    """Each step captured in its own CUDA graph, after warm-up steps whose effects are undone.

    The warm-up (on a side stream, as torch's capture needs) creates the optimiser's state
    and moves the weights; both are put back in place, so the graphs see the same tensors and
    the run starts where it would have without them.

    Each member's dropout generator is registered with every graph: a replay first writes
    each generator's seed and offset into the graph's two device scalars (torch's replay
    prologue, two fills a generator, 50 launches a step for 25 members, outside the graph);
    the epoch's reseeding (manual_seed) only sets host values that the prologue then copies.
    One generator for the whole ensemble would make it 2 launches but draw other masks than
    pimann.learn.train's per-seed generators; masks hashed on the device from per-member seed
    tensors and a step counter would need no generator, but the CPU's trainer would have to
    draw its masks the same way, which changes its models.
    """
    model, optimizer = steps[0].model, steps[0].optimizer
    weights = [p.detach().clone() for p in model.parameters()]
    before = {p: {k: v.clone() for k, v in optimizer.state[p].items()} for p in optimizer.state}
    side = torch.cuda.Stream()
    side.wait_stream(torch.cuda.current_stream())
    with torch.cuda.stream(side):
        for _ in range(3):
            for step in steps:
                step()
    torch.cuda.current_stream().wait_stream(side)
    with torch.no_grad():
        for p, saved in zip(model.parameters(), weights, strict=True):
            p.copy_(saved)
        for p, state in optimizer.state.items():
            for key, value in state.items():
                if torch.is_tensor(value):
                    value.copy_(before[p][key]) if p in before else value.zero_()
    graphs = []
    for step in steps:
        graph = torch.cuda.CUDAGraph()
        for generator in generators:
            graph.register_generator_state(generator)
        with torch.cuda.graph(graph):
            step()
        graphs.append(graph.replay)
    torch.cuda.synchronize()
    return graphs


def _orders(seeds: list[int], epoch: int, n: int) -> np.ndarray:
    """(E, n) each member's sample order in `epoch` (members of one seed share theirs)."""
    unique = {seed: epoch_order(seed, epoch, n) for seed in dict.fromkeys(seeds)}
    return np.stack([unique[seed] for seed in seeds])


@_deterministic()  # torch's deterministic algorithms for the call
def train_sweep(
    dataset_path: str | Path,
    pi_weights: list[float],
    seeds: list[int],
    params: Params,
    device: torch.device | str,
    graph: bool | None = None,
    checkpoint: str | Path | None = None,
    stop_after: int | None = None,
    progress: str | None = "train sweep",
    data: FeatureDataset | None = None,
) -> dict[SweepMember, dict] | None:
    """Train every (w, seed) of the sweep as one ensemble; per member its best weights
    (`state_dict`, on the CPU), `best_epoch`, `best_loss` and per-epoch `history`.

    `graph`: replay the step as a CUDA graph (default: on CUDA). `checkpoint`: a file the run
    saves to every CHECKPOINT_EVERY_S and resumes from. `stop_after` stops after that many
    epochs in total (returning None), a stand-in for an interruption. `data`: the dataset at
    `dataset_path`, when the caller has read it already.
    """
    dataset_path, pi_weights, seeds = Path(dataset_path), list(pi_weights), list(seeds)
    device = torch.device(device)
    config = params.train
    if not seeds or len(set(seeds)) != len(seeds) or len(set(pi_weights)) != len(pi_weights):
        raise PimannError(
            None, f"the sweep needs distinct seeds and weights: {pi_weights} x {seeds}"
        )
    graph = device.type == "cuda" if graph is None else graph
    if graph and device.type != "cuda":
        raise PimannError(None, "a CUDA graph needs a CUDA device")
    check_cublas(device)
    members = sweep_members(pi_weights, seeds)
    count = len(members)
    data = read_dataset(dataset_path) if data is None else data
    keep = torch.as_tensor(training_subset(len(data.x_train), config.max_train_samples))
    keep = keep.to(device)
    x_train, y_train, x_test, y_test = (
        torch.as_tensor(a, dtype=torch.float32).to(device)
        for a in (data.x_train, data.y_train, data.x_test, data.y_test)
    )
    x_train, y_train = x_train[keep], y_train[keep]
    n, batch = len(x_train), config.batch_size
    weight_decay = config.weight_decay / math.sqrt(math.ceil(n / batch) * config.restart_period)
    precision = pick_precision(config.precision, device)

    model = (
        MANN.from_seeds(
            data.layout.input_dim, data.layout.output_dim, params.model, [m.seed for m in members]
        )
        .to(device)
        .train()
    )
    model.seed_dropout([0] * count)  # the generators, reseeded in place every epoch
    lr = torch.tensor(config.learning_rate, device=device)
    decay = torch.ones((), device=device)
    optimizer = torch.optim.AdamW(
        model.parameters(), lr=lr, weight_decay=0.0, fused=True, capturable=device.type == "cuda"
    )
    loss_fn = TrainingLoss.from_params(config, data.layout, data.stats, device)
    weights = torch.tensor([m.pi_weight for m in members], device=device)
    best = {k: v.detach().clone() for k, v in model.state_dict().items()}
    best_loss = torch.full((count,), math.inf, device=device)
    best_epoch = torch.full((count,), -1, dtype=torch.long, device=device)
    history = torch.zeros(config.epochs, 4, count, device=device)  # train mse, pi; test mse, pi
    fingerprint = _fingerprint(dataset_path, pi_weights, seeds, params)
    start = 0
    checkpoint = None if checkpoint is None else Path(checkpoint)
    if checkpoint is not None and checkpoint.is_file():
        saved = torch.load(checkpoint, map_location=device, weights_only=True)
        if saved.get("fingerprint") == fingerprint and saved["epoch"] <= config.epochs:
            model.load_state_dict(saved["model"])
            optimizer.load_state_dict(saved["optimizer"])
            for group in optimizer.param_groups:  # the schedule's tensors, not saved copies
                group["lr"], group["weight_decay"] = lr, 0.0
            for name, value in saved["best"].items():
                best[name].copy_(value)
            best_loss.copy_(saved["best_loss"])
            best_epoch.copy_(saved["best_epoch"])
            history[: saved["epoch"]] = saved["history"][: saved["epoch"]]
            start = int(saved["epoch"])
            log.info("resuming the sweep from epoch %d", start)
        else:
            log.info("ignoring a checkpoint of other data or parameters: %s", checkpoint)

    totals = torch.zeros(2, count, device=device)
    sizes = [batch] * (n // batch) + ([n % batch] if n % batch else [])
    clean_pass = any(m.pi_weight != 0.0 for m in members) and not config.pi_dropout
    steps = {
        size: _Step(
            model,
            optimizer,
            loss_fn,
            (x_train, y_train),
            weights,
            decay,
            totals,
            size,
            clean_pass,
            precision,
        )
        for size in dict.fromkeys(sizes)
    }
    run: dict[int, Callable[[], None]] = dict(steps)
    if graph:
        replays = _capture(list(steps.values()), model.dropout_generators or [])
        run = dict(zip(steps, replays, strict=True))
    note("train_precision", precision)
    last = config.epochs if stop_after is None else min(stop_after, config.epochs)
    log.info(
        "sweep of %d models (w %s x seeds %s, %d training samples, %s) on %s, %s",
        count,
        pi_weights,
        seeds,
        n,
        precision,
        device,
        "CUDA graph" if graph else "eager",
    )
    bar = Progress(
        config.epochs,
        progress or "",
        "epochs",
        initial=start,
        logger=log,
        enabled=progress is not None,
    )
    # a w = 0 member's in-step L_B is not what pimann.learn.train logs as its train_pi (it
    # takes none in its steps): that is L_B after the epoch, dropout off, on every
    # (n // 4096)-th training sample; taken here the same way, on the same samples
    unweighted = None
    if any(m.pi_weight == 0.0 for m in members):
        every = max(1, n // 4096)
        unweighted = (x_train[::every], y_train[::every])
    saved_at = time.monotonic()
    member_seeds = [m.seed for m in members]
    with concurrent.futures.ThreadPoolExecutor(1) as pool:
        upcoming = pool.submit(_orders, member_seeds, start, n)
        for epoch in range(start, last):
            factor = schedule_factor(epoch, config.restart_period, config.restart_mult)
            lr.fill_(config.learning_rate * factor)
            decay.fill_(1.0 - config.learning_rate * factor * weight_decay * factor)
            for generator, member in zip(model.dropout_generators, members, strict=True):
                generator.manual_seed(epoch_seed(member.seed, epoch, "dropout"))
            order = torch.as_tensor(upcoming.result()).to(device)
            if epoch + 1 < last:  # the next epoch's orders while this one runs
                upcoming = pool.submit(_orders, member_seeds, epoch + 1, n)
            totals.zero_()
            at = 0
            for size in sizes:
                steps[size].index.copy_(order[:, at : at + size])
                run[size]()
                at += size
            test_mse, test_pi = batched_loss(model, loss_fn, x_test, y_test, config.eval_batch_size)
            train_pi = totals[1] / n
            if unweighted is not None:  # w = 0 members' train_pi as the CPU's trainer logs it
                sampled = batched_loss(model, loss_fn, *unweighted, config.eval_batch_size)[1]
                train_pi = torch.where(weights == 0, sampled, train_pi)
            history[epoch] = torch.stack([totals[0] / n, train_pi, test_mse, test_pi])
            test = test_mse + weights * test_pi
            better = test < best_loss
            best_loss.copy_(torch.where(better, test, best_loss))
            best_epoch.copy_(torch.where(better, epoch + 1, best_epoch))
            with torch.no_grad():
                for name, value in model.state_dict().items():
                    chosen = better.view((-1,) + (1,) * (value.dim() - 1))
                    best[name].copy_(torch.where(chosen, value, best[name]))
            if progress is not None:  # one wait for the device per epoch, for the bar
                mean = (history[epoch, 0] + weights * history[epoch, 1]).mean().item()
                bar.update(postfix=f"train {mean:.4f}")
            else:
                bar.update()
            due = (
                time.monotonic() - saved_at >= CHECKPOINT_EVERY_S
                or epoch + 1 == last < config.epochs
            )
            if checkpoint is not None and due:
                state = {
                    "epoch": epoch + 1,
                    "model": model.state_dict(),
                    "optimizer": optimizer.state_dict(),
                    "best": best,
                    "best_loss": best_loss,
                    "best_epoch": best_epoch,
                    "history": history,
                    "fingerprint": fingerprint,
                }
                with atomic_path(checkpoint) as tmp:
                    torch.save(state, tmp)
                saved_at = time.monotonic()
    bar.close()
    if last < config.epochs:
        return None
    model.load_state_dict(best)
    return _results(
        model,
        members,
        best_epoch,
        best_loss,
        history,
        config.learning_rate,
        config.restart_period,
        config.restart_mult,
    )


def _results(
    model: MANN,
    members: list[SweepMember],
    best_epoch: torch.Tensor,
    best_loss: torch.Tensor,
    history: torch.Tensor,
    learning_rate: float,
    period: int,
    mult: int,
) -> dict[SweepMember, dict]:
    """Per member: its best weights on the CPU, best epoch and loss, and its loss rows."""
    state = {k: v.detach().cpu() for k, v in model.state_dict().items()}
    epochs = history.shape[0]
    rows = history.cpu().double().numpy()  # (epochs, 4, E)
    results = {}
    for k, member in enumerate(members):
        w = member.pi_weight
        table = []
        for epoch in range(epochs):
            train_mse, train_pi, test_mse, test_pi = rows[epoch, :, k].tolist()
            table.append(
                {
                    "epoch": epoch + 1,
                    "lr": learning_rate * schedule_factor(epoch, period, mult),
                    "train_loss": train_mse + w * train_pi,
                    "train_mse": train_mse,
                    "train_pi": train_pi,
                    "test_loss": test_mse + w * test_pi,
                    "test_mse": test_mse,
                    "test_pi": test_pi,
                }
            )
        results[member] = {
            "state_dict": {name: value[k : k + 1].clone() for name, value in state.items()},
            "best_epoch": int(best_epoch[k]),
            "best_loss": float(best_loss[k]),
            "history": table,
        }
    return results


def train_from_sweep(
    dataset_path: str | Path,
    out_dir: str | Path,
    pi_weight: float,
    pi_weights: list[float],
    params: Params,
    device: torch.device | str,
    plots_dir: str | Path | None = None,
) -> dict[int, dict]:
    """Weight `pi_weight`'s models (as pimann.learn.train.train_models writes them) out of
    the sweep of `pi_weights` x train.seeds.

    The first call trains the whole sweep and keeps its members in <out's parent>/.sweep/
    until every weight's models are written, so one DVC stage per weight still writes its own
    outputs while the device trains them all at once. Returns each seed's meta data.
    """
    dataset_path, out_dir = Path(dataset_path), Path(out_dir)
    pi_weights = [float(w) for w in pi_weights]
    if float(pi_weight) not in pi_weights:
        raise PimannError(None, f"PI weight {pi_weight:g} is not in the sweep {pi_weights}")
    seeds = list(params.train.seeds)
    data = read_dataset(dataset_path)
    fingerprint = _fingerprint(dataset_path, pi_weights, seeds, params)
    folder = out_dir.parent / SWEEP_DIR / fingerprint[:16]
    trained = folder / "members.pt"
    if not trained.is_file():
        folder.mkdir(parents=True, exist_ok=True)
        results = train_sweep(
            dataset_path,
            pi_weights,
            seeds,
            params,
            device,
            checkpoint=folder / "checkpoint.pt",
            data=data,
        )
        assert results is not None  # no stop_after
        with atomic_path(trained) as tmp:
            torch.save({_key(m.pi_weight, m.seed): r for m, r in results.items()}, tmp)
        (folder / "checkpoint.pt").unlink(missing_ok=True)
    else:
        log.info("w=%g from the sweep trained before: %s", pi_weight, folder)
    saved = torch.load(trained, map_location="cpu", weights_only=True)
    members = {seed: saved[_key(float(pi_weight), seed)] for seed in seeds}
    samples = len(training_subset(len(data.x_train), params.train.max_train_samples))
    precision = pick_precision(params.train.precision, torch.device(device))
    metas = write_models(
        out_dir,
        plots_dir,
        dataset_path,
        data,
        float(pi_weight),
        members,
        params,
        precision,
        samples,
    )
    written_file = folder / "written.json"
    written = set(json.loads(written_file.read_text())) if written_file.is_file() else set()
    written.add(float(pi_weight))
    if written >= set(pi_weights):
        shutil.rmtree(folder, ignore_errors=True)  # every weight is out: a rerun starts afresh
        with contextlib.suppress(OSError):
            folder.parent.rmdir()  # when no other sweep is there
    else:
        written_file.write_text(json.dumps(sorted(written)))
    return metas


def _key(pi_weight: float, seed: int) -> str:
    return f"{pi_weight!r}/{seed}"
