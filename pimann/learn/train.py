"""Training of the (physics-informed) MANN: L = L_D + w L_B (paper Sec. III-B, Eq. overall_loss).

The seeds of one PI weight train together as vectorised ensembles (`MANN.from_seeds`), split
over `train.workers` single-threaded processes on the CPU: the members never mix (their
losses are summed, AdamW acts elementwise), and each member draws its data order, its
initial weights and its dropout masks from its own seed, so member k is the model seed k
would give alone whatever group it trains in. The dropout and order seeds are fixed per
epoch, so a run resumed from its per-epoch checkpoint continues exactly as an uninterrupted
one.

The loss is `pimann.learn.training_loss`, the per-epoch schedule, order and seeds
`pimann.learn.epochs`, the model folders `pimann.learn.model_files`.

Optimiser as in the authors' code: AdamW, lr 1e-4 and weight decay 0.0025 / sqrt(batches
per epoch x Te), both annealed per epoch by cosine warm restarts (Te = 10, Tmult = 2). The
epoch with the lowest test loss is kept, per member.

`train.precision` bfloat16 runs the network's forward and backward products under
`torch.autocast` (about 6x the float32 matmul rate on a CPU with AVX512-BF16): the weights,
the optimiser state, L_D, L_B's kinematics and the test loss stay float32, and the dropout
masks are drawn in float32, so both precisions draw the same masks from the same seeds.

On a CUDA device the stages train the whole sweep of PI weights as one ensemble instead
(pimann.learn.sweep); this module stays the CPU's trainer.
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import hashlib
import json
import logging
import math
import os
import shutil
from pathlib import Path

import numpy as np
import torch

from pimann.core.atomic import atomic_path
from pimann.core.errors import PimannError
from pimann.core.parallel import cpu_workers, pool_map, training_threads
from pimann.core.params import Params, as_dict
from pimann.core.paths import repo_relative
from pimann.core.progress import Progress
from pimann.core.stage_times import note
from pimann.learn.dataset import FeatureDataset, read_dataset
from pimann.learn.epochs import epoch_order, epoch_seed, schedule_factor
from pimann.learn.held_out_loss import batched_loss
from pimann.learn.mann import MANN
from pimann.learn.model_files import save_model
from pimann.learn.training_loss import TrainingLoss

log = logging.getLogger(__name__)

# Deterministic cuBLAS needs this workspace setting, which cuBLAS reads once, when it starts:
# set at import, ahead of the training's first CUDA call; check_cublas refuses a late one.
CUBLAS_VARIABLE, CUBLAS_SETTINGS = "CUBLAS_WORKSPACE_CONFIG", (":4096:8", ":16:8")
_CUBLAS_LATE = CUBLAS_VARIABLE not in os.environ and torch.cuda.is_initialized()
os.environ.setdefault(CUBLAS_VARIABLE, CUBLAS_SETTINGS[0])

CHECKPOINT_FILE = "checkpoint.pt"
LOSS_COLUMNS = ("train_loss", "train_mse", "train_pi", "test_loss", "test_mse", "test_pi")


def pick_device(setting: str = "auto") -> torch.device:
    """`auto`: CUDA when present, else CPU."""
    if setting == "cuda" and not torch.cuda.is_available():
        raise PimannError(None, "train.device is cuda but no CUDA device is available")
    if setting == "auto":
        setting = "cuda" if torch.cuda.is_available() else "cpu"
    return torch.device(setting)


def cpu_has_bf16(cpuinfo: Path = Path("/proc/cpuinfo")) -> bool:
    """True where the CPU's flags name AVX512-BF16 or AMX-BF16 (where bf16 products are fast:
    elsewhere torch emulates them, slower than float32)."""
    try:
        flags = set(cpuinfo.read_text().split())
    except OSError:
        return False
    return bool(flags & {"avx512_bf16", "amx_bf16"})


def pick_precision(setting: str, device: torch.device) -> str:
    """train.precision resolved: `auto` is bfloat16 on a bf16-capable CPU or CUDA device."""
    if setting != "auto":
        return setting
    if device.type == "cuda":
        return "bfloat16" if torch.cuda.is_bf16_supported() else "float32"
    return "bfloat16" if device.type == "cpu" and cpu_has_bf16() else "float32"


def autocast(device: torch.device, precision: str) -> contextlib.AbstractContextManager:
    """The network's products in bfloat16 (precision `bfloat16`), else a no-op."""
    if precision == "float32":
        return contextlib.nullcontext()
    return torch.autocast(device.type, dtype=torch.bfloat16)


def seed_groups(seeds: list[int], workers: int) -> list[list[int]]:
    """The seeds split into `workers` contiguous groups of near-equal size, one per process."""
    return [list(map(int, group)) for group in np.array_split(np.array(seeds), workers)]


@dataclasses.dataclass
class _State:
    """Everything a resumed run needs; saved after every epoch."""

    epoch: int  # epochs completed
    model: dict
    optimizer: dict
    best: dict  # per-parameter tensors holding each member's best epoch
    best_loss: list[float]
    best_epoch: list[int]
    history: list[list[dict]]  # per member, one row per epoch


def _fingerprint(
    dataset_path: Path, pi_weight: float | list[float], seeds: list[int], params: Params
) -> str:
    """What a checkpoint must match to be resumed (the epoch count may grow)."""
    train = {
        **as_dict(params.train),
        "epochs": 0,
        "eval_batch_size": 0,
        "device": "auto",
        "threads": "auto",
        "workers": 0,
    }  # what does not change the result
    digest = hashlib.sha256(dataset_path.read_bytes()).hexdigest()
    blob = json.dumps([digest, pi_weight, seeds, as_dict(params.model), train], sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()


def cublas_problem(
    device: torch.device, setting: str | None, late: bool = _CUBLAS_LATE
) -> str | None:
    """Why a training on `device` would not be deterministic under this cuBLAS `setting`
    (None: it would be): unset or another value, or set only after CUDA had started."""
    if device.type != "cuda":
        return None
    if setting not in CUBLAS_SETTINGS:
        return f"{CUBLAS_VARIABLE}={setting} is not one of {', '.join(CUBLAS_SETTINGS)}"
    if late:
        return f"{CUBLAS_VARIABLE} was set after CUDA started: export it before python starts"
    return None


def check_cublas(device: torch.device) -> None:
    """Refuse a CUDA training whose cuBLAS would not be deterministic (cublas_problem)."""
    problem = cublas_problem(device, os.environ.get(CUBLAS_VARIABLE))
    if problem is not None:
        raise PimannError(None, f"deterministic training on {device}: {problem}")


@contextlib.contextmanager
def _deterministic():
    """torch's deterministic algorithms for the run, the caller's setting restored after."""
    before = torch.are_deterministic_algorithms_enabled()
    warn = torch.is_deterministic_algorithms_warn_only_enabled()
    torch.use_deterministic_algorithms(True, warn_only=True)
    try:
        yield
    finally:
        torch.use_deterministic_algorithms(before, warn_only=warn)


@contextlib.contextmanager
def _torch_threads(threads: int):
    """torch's thread count for a training group, the caller's restored after (a group may
    train in the caller's process)."""
    before = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        yield
    finally:
        torch.set_num_threads(before)


def train_models(
    dataset_path: str | Path,
    out_dir: str | Path,
    pi_weight: float,
    seeds: list[int],
    params: Params,
    device: torch.device | str | None = None,
    checkpoint_dir: str | Path | None = None,
    plots_dir: str | Path | None = None,
    stop_after: int | None = None,
) -> dict[int, dict]:
    """Train one model per seed for `pi_weight`; write out_dir/<seed>/ and the loss CSVs.

    The seeds are split into `train.workers` groups, each trained by `_train_group` in its
    own process. Resumes from `checkpoint_dir` (default: out_dir's sibling
    `.checkpoints/<name>`) when a checkpoint of the same data and parameters is there (it is
    removed once the models are written). `stop_after` stops after that many epochs in total
    without writing the models (a stand-in for an interruption). Returns each seed's meta data.
    """
    dataset_path, out_dir, seeds = Path(dataset_path), Path(out_dir), list(seeds)
    if not seeds or len(set(seeds)) != len(seeds):
        raise PimannError(None, f"train.seeds must be distinct and non-empty, not {seeds}")
    config = params.train
    device = pick_device(config.device) if device is None else torch.device(device)
    checkpoint_dir = Path(checkpoint_dir or out_dir.parent / ".checkpoints" / out_dir.name)
    data = read_dataset(dataset_path)  # read here too: bad data fails before any worker starts
    precision = pick_precision(config.precision, device)
    threads = training_threads(config.threads)
    workers = 1 if device.type == "cuda" else cpu_workers(min(config.workers, len(seeds), threads))
    groups = seed_groups(seeds, workers)
    note("train_precision", precision)  # in the stage-time record
    note("train_threads", threads)
    # one progress for the stage: the first group's (the groups keep pace with each other)
    progress = f"train {out_dir.name} seeds {groups[0]}"
    jobs = [
        _GroupJob(
            dataset_path=dataset_path,
            seeds=group,
            pi_weight=pi_weight,
            params=params,
            device=str(device),
            checkpoint_dir=checkpoint_dir,
            stop_after=stop_after,
            threads=max(1, threads // workers),
            precision=precision,
            progress=progress if k == 0 else None,
        )
        for k, group in enumerate(groups)
    ]
    n = len(data.x_train)
    if config.max_train_samples is not None:
        n = min(n, config.max_train_samples)
    log.info(
        "%s (w=%g, %s data, %d of %d training samples, %s): seeds %s in %d process(es) "
        "of %d thread(s)",
        out_dir.name,
        pi_weight,
        data.layout.variant,
        n,
        len(data.x_train),
        precision,
        groups,
        workers,
        max(1, threads // workers),
    )
    results = pool_map(_train_group, jobs, workers, None)
    if any(result is None for result in results):
        return {}  # stopped early (stop_after)
    members = {seed: member for result in results for seed, member in result.items()}
    metas = write_models(
        out_dir, plots_dir, dataset_path, data, pi_weight, members, params, precision, n
    )
    shutil.rmtree(checkpoint_dir, ignore_errors=True)  # done: a rerun starts afresh
    return metas


@dataclasses.dataclass(frozen=True)
class _GroupJob:
    """What one training process needs (picklable, for spawned workers)."""

    dataset_path: Path
    seeds: list[int]
    pi_weight: float
    params: Params
    device: str
    checkpoint_dir: Path
    stop_after: int | None
    threads: int  # torch threads of the group's process
    precision: str  # float32 | bfloat16 (resolved)
    progress: str | None  # the label of the group that reports the stage's progress


def _train_group(job: _GroupJob) -> dict[int, dict] | None:
    """Train the ensemble of `job.seeds` (one worker process's share); per seed its best
    weights, epoch, loss and history.

    None when stopped by `stop_after` before the last epoch (the checkpoint is kept).
    """
    with _torch_threads(job.threads), _deterministic():
        config, seeds, pi_weight = job.params.train, job.seeds, job.pi_weight
        device = torch.device(job.device)
        check_cublas(device)
        checkpoint = job.checkpoint_dir / ("seeds-" + "-".join(map(str, seeds))) / CHECKPOINT_FILE

        # the data, on the device
        data = read_dataset(job.dataset_path)
        keep = training_subset(len(data.x_train), config.max_train_samples)
        if len(keep) < len(data.x_train):
            data.x_train, data.y_train = data.x_train[keep], data.y_train[keep]
            log.debug("training on %d evenly spaced of the training samples", len(keep))
        x_train, y_train, x_test, y_test = (
            torch.as_tensor(a, dtype=torch.float32, device=device)
            for a in (data.x_train, data.y_train, data.x_test, data.y_test)
        )
        n, batch = len(x_train), config.batch_size

        # the ensemble, its optimiser and its loss
        batches = math.ceil(n / batch)
        weight_decay = config.weight_decay / math.sqrt(batches * config.restart_period)
        model = MANN.from_seeds(
            data.layout.input_dim, data.layout.output_dim, job.params.model, seeds
        )
        model.to(device).train()
        # fused: one kernel over every parameter, 3.6x faster than the default per-tensor loop
        # on the CPU (4.2 vs 15.1 ms a step for a 5-member ensemble), the same update
        optimizer = torch.optim.AdamW(
            model.parameters(), lr=config.learning_rate, weight_decay=weight_decay, fused=True
        )
        loss_fn = TrainingLoss.from_params(config, data.layout, data.stats, device)

        # resumed from the checkpoint of the same data and parameters, if any
        fingerprint = _fingerprint(job.dataset_path, pi_weight, seeds, job.params)
        members = len(seeds)
        state = _State(
            epoch=0,
            model={},
            optimizer={},
            best={k: v.detach().clone() for k, v in model.state_dict().items()},
            best_loss=[math.inf] * members,
            best_epoch=[-1] * members,
            history=[[] for _ in seeds],
        )
        if checkpoint.is_file():
            saved = torch.load(checkpoint, map_location=device, weights_only=True)
            if saved.get("fingerprint") == fingerprint and saved["epoch"] <= config.epochs:
                state = _State(**{f.name: saved[f.name] for f in dataclasses.fields(_State)})
                model.load_state_dict(state.model)
                optimizer.load_state_dict(state.optimizer)
                log.info("resuming seeds %s from epoch %d", seeds, state.epoch)
            else:
                log.info("ignoring a checkpoint of other data or parameters: %s", checkpoint)

        with_pi = pi_weight != 0.0
        last = config.epochs if job.stop_after is None else min(job.stop_after, config.epochs)
        progress = Progress(
            config.epochs,
            job.progress or "",
            "epochs",
            initial=state.epoch,
            logger=log,
            enabled=job.progress is not None,
        )
        for epoch in range(state.epoch, last):
            factor = schedule_factor(epoch, config.restart_period, config.restart_mult)
            for group in optimizer.param_groups:
                group["lr"] = config.learning_rate * factor
                group["weight_decay"] = weight_decay * factor
            model.seed_dropout([epoch_seed(seed, epoch, "dropout") for seed in seeds])
            order = torch.as_tensor(
                np.stack([epoch_order(s, epoch, n) for s in seeds]), device=device
            )  # (E, N)

            # one epoch of steps on L = L_D + w L_B
            totals = torch.zeros(2, members, device=device)
            for start in range(0, n, batch):
                index = order[:, start : start + batch]
                x = x_train[index]
                clean = None
                with autocast(device, job.precision):
                    if with_pi and not config.pi_dropout:
                        prediction, clean = model.forward_with_clean(x)
                    else:
                        prediction = model(x)
                prediction = prediction.float()  # the losses in float32
                clean = None if clean is None else clean.float()
                loss = loss_fn(prediction, y_train[index], with_pi, clean)
                optimizer.zero_grad(set_to_none=True)
                loss.total(pi_weight).sum().backward()
                optimizer.step()
                terms = torch.stack([loss.data.detach(), loss.physics.detach()])
                totals += terms * index.shape[1]

            # the epoch's losses; each member's best epoch by its test loss
            train_mse, train_pi = (totals / n).tolist()
            test = batched_loss(model, loss_fn, x_test, y_test, config.eval_batch_size)
            test_mse, test_pi = (t.tolist() for t in test)
            if not with_pi:  # the PI term of a w=0 model, on a sample of the training set
                every = max(1, n // 4096)
                sample = (x_train[::every], y_train[::every])
                train_pi = batched_loss(model, loss_fn, *sample, config.eval_batch_size)[1]
                train_pi = train_pi.tolist()
            for k in range(members):
                row = {"epoch": epoch + 1, "lr": config.learning_rate * factor}
                row.update(
                    train_loss=train_mse[k] + pi_weight * train_pi[k],
                    train_mse=train_mse[k],
                    train_pi=train_pi[k],
                    test_loss=test_mse[k] + pi_weight * test_pi[k],
                    test_mse=test_mse[k],
                    test_pi=test_pi[k],
                )
                state.history[k].append(row)
                if row["test_loss"] < state.best_loss[k]:
                    state.best_loss[k], state.best_epoch[k] = row["test_loss"], epoch + 1
                    for name, value in model.state_dict().items():
                        state.best[name][k] = value[k].detach()
            mean = {c: float(np.mean([h[-1][c] for h in state.history])) for c in LOSS_COLUMNS}
            progress.update(postfix=f"train {mean['train_loss']:.4f}, test {mean['test_loss']:.4f}")
            log.debug(
                "w=%g seeds %s epoch %d/%d: train %.5f (mse %.5f, pi %.5f), test %.5f "
                "(mse %.5f, pi %.5f)",
                pi_weight,
                seeds,
                epoch + 1,
                config.epochs,
                *(mean[c] for c in LOSS_COLUMNS),
            )
            state.epoch = epoch + 1
            state.model, state.optimizer = model.state_dict(), optimizer.state_dict()
            with atomic_path(checkpoint) as tmp:
                torch.save({**dataclasses.asdict(state), "fingerprint": fingerprint}, tmp)
        progress.close()
        if state.epoch < config.epochs:
            return None
        model.load_state_dict(state.best)
        return {
            seed: {
                "state_dict": {k: v.cpu() for k, v in model.member(i).state_dict().items()},
                "best_epoch": state.best_epoch[i],
                "best_loss": state.best_loss[i],
                "history": state.history[i],
            }
            for i, seed in enumerate(seeds)
        }


def training_subset(n: int, max_samples: int | None) -> np.ndarray:
    """The training rows used: all, or `max_samples` evenly spaced ones (max_train_samples)."""
    if max_samples is None or n <= max_samples:
        return np.arange(n)
    return np.linspace(0, n - 1, max_samples).round().astype(np.int64)


def write_models(
    out_dir: Path,
    plots_dir: str | Path | None,
    dataset_path: Path,
    data: FeatureDataset,
    pi_weight: float,
    members: dict[int, dict],
    params: Params,
    precision: str,
    train_samples: int,
) -> dict[int, dict]:
    """out_dir/<seed>/ (model and meta) and plots_dir/seed<seed>.csv for each trained member
    (its best `state_dict`, `best_epoch`, `best_loss` and `history`); the metas by seed."""
    config = params.train
    metas = {}
    with atomic_path(out_dir) as tmp:
        for seed, member in members.items():
            meta = {
                "pi_weight": pi_weight,
                "seed": seed,
                "variant": data.layout.variant,
                "best_epoch": member["best_epoch"],
                "best_test_loss": member["best_loss"],
                "epochs": config.epochs,
                "precision": precision,
                "train_samples": train_samples,
                "test_samples": len(data.x_test),
                "dataset": repo_relative(dataset_path),  # the same in every checkout
                "train_clips": data.train_clips,
                "test_clips": data.test_clips,
                "standing": data.standing,
                "params": {"model": as_dict(params.model), "train": as_dict(config)},
            }
            model = MANN(data.layout.input_dim, data.layout.output_dim, params.model, seeds=[seed])
            model.load_state_dict(member["state_dict"])
            save_model(tmp / str(seed), model, data.layout, data.stats, meta)
            metas[seed] = meta
    if plots_dir is not None:
        with atomic_path(plots_dir) as tmp:
            tmp.mkdir()
            for seed, member in members.items():
                write_loss_csv(tmp / f"seed{seed}.csv", member["history"])
    return metas


def write_loss_csv(path: Path, history: list[dict]) -> None:
    with path.open("w", newline="") as file:
        writer = csv.DictWriter(file, fieldnames=["epoch", *LOSS_COLUMNS, "lr"])
        writer.writeheader()
        writer.writerows(history)
