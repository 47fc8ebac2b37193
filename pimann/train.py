"""Training of the (physics-informed) MANN: L = L_D + w L_B (SPEC 5, 6; Eq. overall_loss).

The seeds of one PI weight train together as vectorised ensembles (`MANN.from_seeds`), split
over `train.workers` single-threaded processes on the CPU: the members never mix (their
losses are summed, AdamW acts elementwise), and each member draws its data order, its
initial weights and its dropout masks from its own seed, so member k is the model seed k
would give alone whatever group it trains in. The dropout and order seeds are fixed per
epoch, so a run resumed from its per-epoch checkpoint continues exactly as an uninterrupted
one.

L_D is the MSE on the normalised outputs; L_B (`PhysicsInformedLoss`) is taken in physical
units on the denormalised prediction: the base twist at step i (the output window's offset
0), the joint velocities, and the configuration (base position, rpy, joints) predicted, or
the ground truth's with `train.pi_configuration: ground_truth`.

Optimiser as in the authors' code: AdamW, lr 1e-4 and weight decay 0.0025 / sqrt(batches
per epoch x Te), both annealed per epoch by cosine warm restarts (Te = 10, Tmult = 2). The
epoch with the lowest test loss is kept, per member.
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
import pickle
import shutil
import warnings
from pathlib import Path

import numpy as np
import torch

from pimann.atomic import atomic_path
from pimann.errors import PimannError, about
from pimann.features import FeatureLayout, Normalisation, read_dataset
from pimann.mann import MANN
from pimann.parallel import cpu_workers, pool_map
from pimann.params import ModelParams, Params, as_dict
from pimann.physics_loss import PhysicsInformedLoss
from pimann.progress import Progress
from pimann.robot import load_robot

log = logging.getLogger(__name__)

MODEL_FILE = "model.pt"
META_FILE = "meta.json"
CHECKPOINT_FILE = "checkpoint.pt"
STAT_NAMES = ("x_mean", "x_std", "y_mean", "y_std")
MODEL_KEYS = ("state_dict", "input_dim", "output_dim", "model_params", "layout", "stats")
LOSS_COLUMNS = ("train_loss", "train_mse", "train_pi", "test_loss", "test_mse", "test_pi")


def pick_device(setting: str = "auto") -> torch.device:
    """`auto`: CUDA when present, else CPU."""
    if setting == "cuda" and not torch.cuda.is_available():
        raise PimannError(None, "train.device is cuda but no CUDA device is available")
    if setting == "auto":
        setting = "cuda" if torch.cuda.is_available() else "cpu"
    return torch.device(setting)


def schedule_factor(epoch: int, period: int, mult: int) -> float:
    """Cosine warm restarts: 0.5 (1 + cos(pi t / T)) at epoch t of the current cycle of T."""
    if period < 1 or mult < 1:
        raise PimannError(None, "train.restart_period and restart_mult must be >= 1")
    t, length = epoch, period
    while t >= length:
        t -= length
        length *= mult
    return 0.5 * (1.0 + math.cos(math.pi * t / length))


def epoch_order(seed: int, epoch: int, n: int) -> np.ndarray:
    """The member's sample order in one epoch: a function of (seed, epoch) only."""
    return np.random.default_rng([seed, epoch]).permutation(n)


def seed_groups(seeds: list[int], workers: int) -> list[list[int]]:
    """The seeds split into `workers` contiguous groups of near-equal size, one per process."""
    return [list(map(int, group)) for group in np.array_split(np.array(seeds), workers)]


def _dropout_seed(seed: int, epoch: int) -> int:
    """A member's dropout seed in one epoch (so resuming needs no saved RNG state)."""
    return int(np.random.SeedSequence([seed, epoch, 0x5EED]).generate_state(1)[0])


class InputNoise:
    """train.input_noise: Gaussian noise on the inputs a rollout feeds back from its own
    predictions (FeatureLayout.fed_back_columns), so the network learns to lead a state that
    has drifted off the data back to it. Each member draws from its own seed and epoch."""

    def __init__(self, std: float, columns: np.ndarray, seeds: list[int], device: torch.device):
        self.std, self.seeds, self.device = std, seeds, device
        self.columns = torch.as_tensor(columns, dtype=torch.float32, device=device)
        self.generators: list[torch.Generator] = []

    def start_epoch(self, epoch: int) -> None:
        self.generators = [
            torch.Generator(self.device).manual_seed(_dropout_seed(seed, epoch) ^ 0x401)
            for seed in self.seeds
        ]

    def __call__(self, x: torch.Tensor) -> torch.Tensor:
        """x (E, B, in) with noise on the fed-back columns; x itself where std is 0."""
        if self.std == 0.0:
            return x
        noise = torch.stack(
            [
                torch.randn(x.shape[1:], generator=g, device=self.device, dtype=x.dtype)
                for g in self.generators
            ]
        )
        return x + self.std * noise * self.columns


# per `train.pi_gradient`: the predictions L_B's gradient does not move
_HELD = {
    "both": (),
    "joints": ("base_linear_velocity", "base_angular_velocity"),
    "base": ("base_position", "base_rpy", "joints", "joint_velocities"),
}


class TrainingLoss(torch.nn.Module):
    """Per-member L_D (normalised MSE) and L_B (physical units) of an ensemble's prediction."""

    def __init__(
        self,
        layout: FeatureLayout,
        stats: Normalisation,
        pi_configuration: str,
        device: torch.device,
        pi_support: str = "lower_sole",
        pi_gradient: str = "both",
    ):
        super().__init__()
        self.layout, self.pi_configuration = layout, pi_configuration
        self.pi_support, self.pi_gradient = pi_support, pi_gradient
        self.register_buffer("y_mean", torch.as_tensor(stats.y_mean, dtype=torch.float32))
        self.register_buffer("y_std", torch.as_tensor(stats.y_std, dtype=torch.float32))
        self.physics = PhysicsInformedLoss(load_robot("retarget"), torch.float32, device)
        self.to(device)

    def pi_terms(self, y: torch.Tensor) -> dict[str, torch.Tensor]:
        """Denormalised quantities of y (..., out) that L_B needs, by argument name."""
        physical = y * self.y_std + self.y_mean
        s = self.layout.y_slices
        now = self.layout.current_output

        def at_now(block: str) -> torch.Tensor:
            return physical[..., s[block]].unflatten(-1, (-1, 3))[..., now, :]

        return {
            "base_position": physical[..., s["base_position"]],
            "base_rpy": physical[..., s["base_rpy"]],
            "joints": physical[..., s["joints"]],
            "base_linear_velocity": at_now("base_linear_future"),
            "base_angular_velocity": at_now("base_angular_future"),
            "joint_velocities": physical[..., s["joint_velocities"]],
        }

    def forward(
        self,
        prediction: torch.Tensor,
        target: torch.Tensor,
        with_pi: bool = True,
        contacts: torch.Tensor | None = None,
        pi_prediction: torch.Tensor | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """(mse (E,), pi (E,)) averaged over the batch; pi is 0 when `with_pi` is False.

        `contacts` (E, B, 2): the data's feet in contact, needed with pi_support data_contacts.
        `pi_prediction`: the prediction L_B is taken on, when not `prediction` (train.pi_dropout
        false: the same inputs without dropout).
        """
        mse = (prediction - target).square().mean(dim=(-2, -1))
        if not with_pi:
            return mse, torch.zeros_like(mse)
        terms = self.pi_terms(prediction if pi_prediction is None else pi_prediction)
        if self.pi_support == "data_contacts":
            if contacts is None:
                raise ValueError("pi_support data_contacts needs the samples' contacts")
            terms["support"] = contacts
        if self.pi_configuration == "ground_truth":
            truth = self.pi_terms(target)
            for name in ("base_position", "base_rpy", "joints"):
                terms[name] = truth[name]
        for name in _HELD[self.pi_gradient]:
            terms[name] = terms[name].detach()
        return mse, self.physics(**terms).mean(-1)


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


def _fingerprint(dataset_path: Path, pi_weight: float, seeds: list[int], params: Params) -> str:
    """What a checkpoint must match to be resumed (the epoch count may grow)."""
    train = dataclasses.replace(params.train, epochs=0, eval_batch_size=0, device="auto")
    digest = hashlib.sha256(dataset_path.read_bytes()).hexdigest()
    blob = json.dumps(
        [digest, pi_weight, seeds, as_dict(params.model), as_dict(train)], sort_keys=True
    )
    return hashlib.sha256(blob.encode()).hexdigest()


def _evaluate(
    model: MANN,
    loss: TrainingLoss,
    x: torch.Tensor,
    y: torch.Tensor,
    contacts: torch.Tensor | None,
    batch: int,
    with_pi: bool,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Test-set (mse, pi) per member, averaged over samples, dropout off."""
    model.eval()
    totals = torch.zeros(2, model.ensemble, device=x.device)
    with torch.no_grad():
        for start in range(0, len(x), batch):
            xb = x[start : start + batch].expand(model.ensemble, -1, -1)
            yb = y[start : start + batch].expand(model.ensemble, -1, -1)
            cb = None
            if contacts is not None:
                cb = contacts[start : start + batch].expand(model.ensemble, -1, -1)
            mse, pi = loss(model(xb), yb, with_pi, cb)
            totals += torch.stack([mse, pi]) * xb.shape[1]
    model.train()
    return totals[0] / len(x), totals[1] / len(x)


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

    Resumes from `checkpoint_dir` (default: out_dir's sibling `.checkpoints/<name>`) when a
    checkpoint of the same data and parameters is there (it is removed once the models are
    written). `stop_after` stops after that many epochs in total without writing the models (a
    stand-in for an interruption). Returns each seed's meta data.
    """
    with _deterministic():
        return _train(
            Path(dataset_path), Path(out_dir), pi_weight, list(seeds), params, device,
            checkpoint_dir, plots_dir, stop_after,
        )  # fmt: skip


def _train(
    dataset_path: Path,
    out_dir: Path,
    pi_weight: float,
    seeds: list[int],
    params: Params,
    device: torch.device | str | None,
    checkpoint_dir: str | Path | None,
    plots_dir: str | Path | None,
    stop_after: int | None,
) -> dict[int, dict]:
    """train_models' body: the seeds split into `train.workers` groups, then the outputs."""
    if not seeds or len(set(seeds)) != len(seeds):
        raise PimannError(None, f"train.seeds must be distinct and non-empty, not {seeds}")
    config = params.train
    device = pick_device(config.device) if device is None else torch.device(device)
    checkpoint_dir = Path(checkpoint_dir or out_dir.parent / ".checkpoints" / out_dir.name)
    data = read_dataset(dataset_path)  # read here too: bad data fails before any worker starts
    if config.pi_support == "data_contacts" and pi_weight != 0.0 and data.train_contacts is None:
        raise PimannError(
            dataset_path, "has no contact flags, which train.pi_support data_contacts needs"
        )
    workers = 1 if device.type == "cuda" else cpu_workers(min(config.workers, len(seeds)))
    groups = seed_groups(seeds, workers)
    threads = max(1, torch.get_num_threads() // workers)
    # one progress for the stage: the first group's (the groups keep pace with each other)
    progress = f"train {out_dir.name} seeds {groups[0]}"
    jobs = [
        _GroupJob(dataset_path, group, pi_weight, params, str(device), checkpoint_dir,
                  stop_after, threads if workers > 1 else None, progress if k == 0 else None)
        for k, group in enumerate(groups)
    ]  # fmt: skip
    n = len(data.x_train)
    if config.max_train_samples is not None:
        n = min(n, config.max_train_samples)
    log.info(
        "%s (w=%g, %s data, %d of %d training samples): seeds %s in %d process(es)",
        out_dir.name, pi_weight, data.layout.variant, n, len(data.x_train), groups, workers,
    )  # fmt: skip
    results = pool_map(_train_group, jobs, workers, None)
    if any(result is None for result in results):
        return {}  # stopped early (stop_after)
    members = {seed: member for result in results for seed, member in result.items()}

    metas = {}
    with atomic_path(out_dir) as tmp:
        for seed in seeds:
            member = members[seed]
            meta = {
                "pi_weight": pi_weight, "seed": seed, "variant": data.layout.variant,
                "best_epoch": member["best_epoch"], "best_test_loss": member["best_loss"],
                "epochs": config.epochs, "train_samples": n, "test_samples": len(data.x_test),
                "dataset": str(dataset_path), "train_clips": data.train_clips,
                "test_clips": data.test_clips, "standing": data.standing,
                "params": {"model": as_dict(params.model), "train": as_dict(config)},
            }  # fmt: skip
            model = MANN(data.layout.input_dim, data.layout.output_dim, params.model, seeds=[seed])
            model.load_state_dict(member["state_dict"])
            save_model(tmp / str(seed), model, data.layout, data.stats, meta)
            metas[seed] = meta
    if plots_dir is not None:
        with atomic_path(plots_dir) as tmp:
            tmp.mkdir()
            for seed in seeds:
                write_loss_csv(tmp / f"seed{seed}.csv", members[seed]["history"])
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
    threads: int | None  # torch threads of a worker process; None: leave as is
    progress: str | None  # the label of the group that reports the stage's progress


def _train_group(job: _GroupJob) -> dict[int, dict] | None:
    """Train the ensemble of `job.seeds`; per seed its best weights, epoch, loss and history.

    None when stopped by `stop_after` before the last epoch (the checkpoint is kept).
    """
    if job.threads is not None:  # a spawned worker
        torch.set_num_threads(job.threads)
    with _deterministic():
        return _train_ensemble(job)


def _train_ensemble(job: _GroupJob) -> dict[int, dict] | None:
    """_train_group's body (see there)."""
    config, seeds, pi_weight = job.params.train, job.seeds, job.pi_weight
    device = torch.device(job.device)
    if device.type == "cuda":
        os.environ.setdefault("CUBLAS_WORKSPACE_CONFIG", ":4096:8")
    checkpoint = job.checkpoint_dir / ("seeds-" + "-".join(map(str, seeds))) / CHECKPOINT_FILE

    data = read_dataset(job.dataset_path)
    if config.max_train_samples is not None and len(data.x_train) > config.max_train_samples:
        keep = np.linspace(0, len(data.x_train) - 1, config.max_train_samples).round()
        keep = keep.astype(np.int64)
        data.x_train, data.y_train = data.x_train[keep], data.y_train[keep]
        if data.train_contacts is not None:
            data.train_contacts = data.train_contacts[keep]
        log.debug("training on %d evenly spaced of the training samples", len(keep))
    x_train, y_train, x_test, y_test = (
        torch.as_tensor(a, dtype=torch.float32, device=device)
        for a in (data.x_train, data.y_train, data.x_test, data.y_test)
    )
    c_train = c_test = None  # the data's contacts, loaded only where L_B uses them
    if config.pi_support == "data_contacts":
        c_train, c_test = (
            None if c is None else torch.as_tensor(c, dtype=torch.bool, device=device)
            for c in (data.train_contacts, data.test_contacts)
        )
    n, batch = len(x_train), config.batch_size
    batches = math.ceil(n / batch)
    weight_decay = config.weight_decay / math.sqrt(batches * config.restart_period)
    model = MANN.from_seeds(data.layout.input_dim, data.layout.output_dim, job.params.model, seeds)
    model.to(device).train()
    # fused: one kernel over every parameter, 3.6x faster than the default per-tensor loop on
    # the CPU (4.2 vs 15.1 ms a step for a 5-member ensemble), the same update
    optimizer = torch.optim.AdamW(
        model.parameters(), lr=config.learning_rate, weight_decay=weight_decay, fused=True
    )
    loss_fn = TrainingLoss(
        data.layout, data.stats, config.pi_configuration, device, config.pi_support,
        config.pi_gradient,
    )  # fmt: skip
    fingerprint = _fingerprint(job.dataset_path, pi_weight, seeds, job.params)
    members = len(seeds)
    state = _State(
        0, {}, {}, {k: v.detach().clone() for k, v in model.state_dict().items()},
        [math.inf] * members, [-1] * members, [[] for _ in seeds],
    )  # fmt: skip
    if checkpoint.is_file():
        saved = torch.load(checkpoint, map_location=device, weights_only=True)
        if saved.get("fingerprint") == fingerprint and saved["epoch"] <= config.epochs:
            state = _State(**{f.name: saved[f.name] for f in dataclasses.fields(_State)})
            model.load_state_dict(state.model)
            optimizer.load_state_dict(state.optimizer)
            log.info("resuming seeds %s from epoch %d", seeds, state.epoch)
        else:
            log.info("ignoring a checkpoint of other data or parameters: %s", checkpoint)

    with_pi_train = pi_weight != 0.0
    noise = InputNoise(config.input_noise, data.layout.fed_back_columns(), seeds, device)
    last = config.epochs if job.stop_after is None else min(job.stop_after, config.epochs)
    progress = Progress(
        config.epochs, job.progress or "", "epochs", initial=state.epoch, logger=log,
        enabled=job.progress is not None,
    )  # fmt: skip
    for epoch in range(state.epoch, last):
        factor = schedule_factor(epoch, config.restart_period, config.restart_mult)
        for group in optimizer.param_groups:
            group["lr"] = config.learning_rate * factor
            group["weight_decay"] = weight_decay * factor
        model.seed_dropout([_dropout_seed(seed, epoch) for seed in seeds])
        noise.start_epoch(epoch)
        order = torch.as_tensor(
            np.stack([epoch_order(s, epoch, n) for s in seeds]), device=device
        )  # (E, N)
        totals = torch.zeros(2, members, device=device)
        for start in range(0, n, batch):
            index = order[:, start : start + batch]
            contacts = None if c_train is None else c_train[index]
            x = noise(x_train[index])
            clean = None
            if with_pi_train and not config.pi_dropout:
                prediction, clean = model.forward_with_clean(x)
            else:
                prediction = model(x)
            mse, pi = loss_fn(prediction, y_train[index], with_pi_train, contacts, clean)
            optimizer.zero_grad(set_to_none=True)
            (mse + pi_weight * pi).sum().backward()
            optimizer.step()
            totals += torch.stack([mse.detach(), pi.detach()]) * index.shape[1]
        train_mse, train_pi = (totals / n).tolist()
        test = _evaluate(model, loss_fn, x_test, y_test, c_test, config.eval_batch_size, True)
        test_mse, test_pi = (t.tolist() for t in test)
        if not with_pi_train:  # the PI term of a w=0 model, on a sample of the training set
            every = max(1, n // 4096)
            sample = (x_train[::every], y_train[::every])
            sample += (None if c_train is None else c_train[::every],)
            train_pi = _evaluate(model, loss_fn, *sample, config.eval_batch_size, True)[1].tolist()
        for k in range(members):
            row = {"epoch": epoch + 1, "lr": config.learning_rate * factor}
            row.update(
                train_loss=train_mse[k] + pi_weight * train_pi[k], train_mse=train_mse[k],
                train_pi=train_pi[k], test_loss=test_mse[k] + pi_weight * test_pi[k],
                test_mse=test_mse[k], test_pi=test_pi[k],
            )  # fmt: skip
            state.history[k].append(row)
            if row["test_loss"] < state.best_loss[k]:
                state.best_loss[k], state.best_epoch[k] = row["test_loss"], epoch + 1
                for name, value in model.state_dict().items():
                    state.best[name][k] = value[k].detach()
        mean = {c: float(np.mean([h[-1][c] for h in state.history])) for c in LOSS_COLUMNS}
        progress.update(postfix=f"train {mean['train_loss']:.4f}, test {mean['test_loss']:.4f}")
        log.debug(
            "w=%g seeds %s epoch %d/%d: train %.5f (mse %.5f, pi %.5f), test %.5f (mse %.5f, "
            "pi %.5f)", pi_weight, seeds, epoch + 1, config.epochs,
            *(mean[c] for c in LOSS_COLUMNS),
        )  # fmt: skip
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


def write_loss_csv(path: Path, history: list[dict]) -> None:
    with path.open("w", newline="") as file:
        writer = csv.DictWriter(file, fieldnames=["epoch", *LOSS_COLUMNS, "lr"])
        writer.writeheader()
        writer.writerows(history)


def save_model(
    directory: Path, model: MANN, layout: FeatureLayout, stats: Normalisation, meta: dict
) -> None:
    """A single model's folder: model.pt (weights, sizes, layout, statistics) and meta.json."""
    if model.ensemble != 1:
        raise ValueError("save one member at a time (MANN.member)")
    directory.mkdir(parents=True, exist_ok=True)
    model_params = meta["params"]["model"]
    blob = {
        "state_dict": {k: v.detach().cpu() for k, v in model.state_dict().items()},
        "input_dim": model.input_dim,
        "output_dim": model.output_dim,
        "model_params": model_params,
        "layout": layout.to_json(),
        "stats": {
            name: torch.as_tensor(getattr(stats, name), dtype=torch.float64) for name in STAT_NAMES
        },
    }
    torch.save(blob, directory / MODEL_FILE)
    (directory / META_FILE).write_text(json.dumps(meta, indent=2) + "\n")


def _read_checkpoint(path: Path, device: torch.device | str) -> dict:
    """model.pt's dictionary; a file torch cannot read (empty, cut short, text, another
    pickle) or another dictionary named."""
    try:
        with warnings.catch_warnings():  # torch warns about a pickle before it refuses it
            warnings.simplefilter("ignore")
            blob = torch.load(path, map_location=device, weights_only=True)
    except OSError as error:
        raise PimannError(path, f"cannot read the model ({error.strerror})") from None
    except EOFError:
        raise PimannError(path, "not a PyTorch checkpoint: empty or cut short") from None
    except (RuntimeError, KeyError, ValueError, pickle.UnpicklingError) as error:
        reason = str(error).split(". ")[0]  # torch's own messages run to paragraphs
        raise PimannError(
            path, f"not a PyTorch checkpoint ({type(error).__name__}: {reason})"
        ) from None
    if not isinstance(blob, dict):
        raise PimannError(path, f"holds a {type(blob).__name__}, not a trained model")
    missing = [key for key in MODEL_KEYS if key not in blob]
    if missing:
        raise PimannError(path, f"not a trained model (lacks {missing})")
    return blob


def _read_meta(path: Path) -> dict:
    """meta.json: a JSON object with the model's integer seed."""
    try:
        meta = json.loads(path.read_text())
    except OSError as error:
        raise PimannError(path, f"cannot read the model's metadata ({error.strerror})") from None
    except ValueError as error:  # not JSON, or not text
        raise PimannError(path, f"not JSON ({error})") from None
    if not isinstance(meta, dict) or type(meta.get("seed")) is not int:
        raise PimannError(path, "not a model's metadata (no integer 'seed')")
    return meta


def _check_tensor(path: Path, name: str, value: object, shape: tuple[int, ...]) -> None:
    """`value` is a finite tensor of `shape`; else named."""
    if not isinstance(value, torch.Tensor) or tuple(value.shape) != shape:
        found = tuple(value.shape) if isinstance(value, torch.Tensor) else type(value).__name__
        raise PimannError(path, f"{name} is {found}, the model needs a tensor of shape {shape}")
    if not torch.isfinite(value).all():
        raise PimannError(path, f"{name} holds NaN or infinite values")


def load_model(
    directory: str | Path, device: torch.device | str = "cpu"
) -> tuple[MANN, FeatureLayout, Normalisation, dict]:
    """(model in eval mode, layout, normalisation, meta) of a folder written by training.

    A folder of anything else (a file cut short, another network, NaN weights) is named.
    """
    directory = Path(directory)
    path = directory / MODEL_FILE
    if not path.is_file():
        raise PimannError(path, "no trained model here")
    blob = _read_checkpoint(path, device)
    meta = _read_meta(directory / META_FILE)
    with about(path, "layout"):
        layout = FeatureLayout.from_json(blob["layout"])
    dims = (blob["input_dim"], blob["output_dim"])
    if dims != (layout.input_dim, layout.output_dim):
        raise PimannError(
            path, f"input_dim, output_dim {dims} do not fit the layout's "
            f"{(layout.input_dim, layout.output_dim)}"
        )  # fmt: skip
    try:
        model_params = ModelParams(**blob["model_params"])
        model = MANN(*dims, model_params, ensemble=1, seeds=[meta["seed"]])
    except (TypeError, ValueError, RuntimeError) as error:
        raise PimannError(path, f"model_params: {error}") from None
    weights, expected = blob["state_dict"], model.state_dict()
    if not isinstance(weights, dict):
        raise PimannError(path, f"state_dict is a {type(weights).__name__}, not a dictionary")
    missing, unexpected = expected.keys() - weights.keys(), weights.keys() - expected.keys()
    if missing or unexpected:
        parts = [f"lacks {sorted(missing)}"] * bool(missing)
        parts += [f"has unexpected {sorted(unexpected)}"] * bool(unexpected)
        raise PimannError(path, f"state_dict does not fit model_params: {', '.join(parts)}")
    for name, tensor in expected.items():
        _check_tensor(path, f"state_dict[{name!r}]", weights[name], tuple(tensor.shape))
    model.load_state_dict(weights)
    model.to(device).eval()
    stats = blob["stats"] if isinstance(blob["stats"], dict) else {}
    for name, size in zip(STAT_NAMES, (dims[0], dims[0], dims[1], dims[1]), strict=True):
        _check_tensor(path, f"stats[{name!r}]", stats.get(name), (size,))
    normalisation = Normalisation(*(stats[n].cpu().numpy() for n in STAT_NAMES))
    if (normalisation.x_std <= 0).any() or (normalisation.y_std <= 0).any():
        raise PimannError(path, "stats x_std or y_std hold values <= 0")
    return model, layout, normalisation, meta
