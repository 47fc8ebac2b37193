"""Training of the ADHERENT baseline (no physics term: L = L_D, the MSE on normalised outputs) and
reading its model folders.

The network is pimann.learn.mann.MANN (the same gate and experts, `model.*` params) on ADHERENT's
inputs and outputs (pimann.learn.adherent). The loop is pimann.learn.train's at w = 0, without its
MANN-layout parts (L_B, own-rollout states, input noise): the seeds train together as one
vectorised ensemble; each member draws its initial weights, its sample order and its dropout
masks from its own seed (pimann.learn.epochs), so the same seed gives the same model in any group;
AdamW with lr and the scaled weight decay annealed per epoch by cosine warm restarts; the epoch
with the lowest test MSE is kept, per member. The model folders are pimann.learn.model_files'
(model.pt, meta.json) with the ADHERENT layout; `load_adherent_model` reads them.
"""

from __future__ import annotations

import csv
import logging
import math
from pathlib import Path

import numpy as np
import torch

from pimann.core.atomic import atomic_path
from pimann.core.errors import PimannError, about
from pimann.core.params import ModelParams, Params, as_dict
from pimann.core.paths import repo_relative
from pimann.core.progress import Progress
from pimann.learn.adherent import AdherentLayout, read_adherent_dataset
from pimann.learn.epochs import epoch_order, epoch_seed, schedule_factor
from pimann.learn.feature_layout import Normalisation
from pimann.learn.mann import MANN
from pimann.learn.model_files import (
    META_FILE,
    MODEL_FILE,
    STAT_NAMES,
    _check_tensor,
    _read_checkpoint,
    _read_meta,
    save_model,
)

log = logging.getLogger(__name__)

# the loss CSV's columns, as pimann.learn.train writes them (the PI ones 0 here)
LOSS_COLUMNS = ("train_loss", "train_mse", "train_pi", "test_loss", "test_mse", "test_pi")


def write_loss_csv(path: Path, history: list[dict]) -> None:
    with path.open("w", newline="") as file:
        writer = csv.DictWriter(file, fieldnames=["epoch", *LOSS_COLUMNS, "lr"])
        writer.writeheader()
        writer.writerows(history)


def _test_mse(model: MANN, x: torch.Tensor, y: torch.Tensor, batch: int) -> torch.Tensor:
    """(E,) each member's MSE over the test samples, dropout off (the mode restored after)."""
    training = model.training
    model.eval()
    total = torch.zeros(model.ensemble)
    with torch.no_grad():
        for start in range(0, len(x), batch):
            xb = x[start : start + batch].expand(model.ensemble, -1, -1)
            error = model(xb) - y[start : start + batch]
            total += error.square().mean(-1).sum(-1)
    model.train(training)
    return total / max(1, len(x))


def train_adherent(
    dataset_path: str | Path,
    out_dir: str | Path,
    seeds: list[int],
    params: Params,
    plots_dir: str | Path | None = None,
) -> dict[int, dict]:
    """Train one ADHERENT model per seed on `dataset_path`; write out_dir/<seed>/ and the loss
    CSVs (plots_dir/seed<seed>.csv, pimann.learn.train's columns, the PI ones 0). Returns each
    seed's meta."""
    if not seeds or len(set(seeds)) != len(seeds):
        raise PimannError(None, f"train.seeds must be distinct and non-empty, not {seeds}")
    dataset_path, out_dir, config = Path(dataset_path), Path(out_dir), params.train
    data = read_adherent_dataset(dataset_path)
    layout: AdherentLayout = data.layout  # type: ignore[assignment]
    keep = np.arange(len(data.x_train))
    if config.max_train_samples is not None and len(keep) > config.max_train_samples:
        keep = np.linspace(0, len(keep) - 1, config.max_train_samples).round().astype(np.int64)
    x_train, y_train, x_test, y_test = (
        torch.as_tensor(a, dtype=torch.float32)
        for a in (data.x_train[keep], data.y_train[keep], data.x_test, data.y_test)
    )
    n, batch = len(x_train), config.batch_size
    batches = math.ceil(n / batch)
    weight_decay = config.weight_decay / math.sqrt(batches * config.restart_period)
    model = MANN.from_seeds(layout.input_dim, layout.output_dim, params.model, list(seeds))
    model.train()
    optimizer = torch.optim.AdamW(
        model.parameters(), lr=config.learning_rate, weight_decay=weight_decay, fused=True
    )
    members = len(seeds)
    best = {k: v.detach().clone() for k, v in model.state_dict().items()}
    best_loss, best_epoch = [math.inf] * members, [-1] * members
    history: list[list[dict]] = [[] for _ in seeds]
    log.info(
        "adherent: seeds %s, %d of %d training samples, %d test, %d epochs",
        seeds,
        n,
        len(data.x_train),
        len(x_test),
        config.epochs,
    )
    progress = Progress(config.epochs, f"train adherent seeds {list(seeds)}", "epochs", logger=log)
    for epoch in range(config.epochs):
        factor = schedule_factor(epoch, config.restart_period, config.restart_mult)
        for group in optimizer.param_groups:
            group["lr"] = config.learning_rate * factor
            group["weight_decay"] = weight_decay * factor
        model.seed_dropout([epoch_seed(seed, epoch, "dropout") for seed in seeds])
        order = torch.as_tensor(np.stack([epoch_order(s, epoch, n) for s in seeds]))  # (E, N)
        totals = torch.zeros(members)
        for start in range(0, n, batch):
            index = order[:, start : start + batch]
            mse = (model(x_train[index]) - y_train[index]).square().mean(dim=(-2, -1))  # (E,)
            optimizer.zero_grad(set_to_none=True)
            mse.sum().backward()
            optimizer.step()
            totals += mse.detach() * index.shape[1]
        train_mse = (totals / n).tolist()
        test_mse = _test_mse(model, x_test, y_test, config.eval_batch_size).tolist()
        for k in range(members):
            row = dict.fromkeys(LOSS_COLUMNS, 0.0)
            row.update(
                epoch=epoch + 1,
                lr=config.learning_rate * factor,
                train_loss=train_mse[k],
                train_mse=train_mse[k],
                test_loss=test_mse[k],
                test_mse=test_mse[k],
            )
            history[k].append(row)
            if test_mse[k] < best_loss[k]:
                best_loss[k], best_epoch[k] = test_mse[k], epoch + 1
                for name, value in model.state_dict().items():
                    best[name][k] = value[k].detach()
        progress.update(postfix=f"train {np.mean(train_mse):.4f}, test {np.mean(test_mse):.4f}")
    progress.close()
    model.load_state_dict(best)
    metas = {}
    with atomic_path(out_dir) as tmp:
        for k, seed in enumerate(seeds):
            meta = {
                "pi_weight": 0.0,
                "seed": int(seed),
                "variant": layout.variant,
                "best_epoch": best_epoch[k],
                "best_test_loss": best_loss[k],
                "epochs": config.epochs,
                "precision": "float32",
                "train_samples": n,
                "test_samples": len(x_test),
                "dataset": repo_relative(dataset_path),  # the same in every checkout
                "train_clips": data.train_clips,
                "test_clips": data.test_clips,
                "standing": data.standing,
                "params": {"model": as_dict(params.model), "train": as_dict(config)},
            }
            save_model(tmp / str(seed), model.member(k), layout, data.stats, meta)  # type: ignore[arg-type]
            metas[int(seed)] = meta
    if plots_dir is not None:
        with atomic_path(plots_dir) as tmp:
            tmp.mkdir()
            for k, seed in enumerate(seeds):
                write_loss_csv(tmp / f"seed{seed}.csv", history[k])
    return metas


def load_adherent_model(
    directory: str | Path,
) -> tuple[MANN, AdherentLayout, Normalisation, dict]:
    """(model in eval mode, layout, normalisation, meta) of a folder `train_adherent` wrote;
    a folder of anything else is named (pimann.learn.model_files' checks)."""
    directory = Path(directory)
    path = directory / MODEL_FILE
    if not path.is_file():
        raise PimannError(path, "no trained model here")
    blob = _read_checkpoint(path, "cpu")
    meta = _read_meta(directory / META_FILE)
    with about(path, "layout"):
        layout = AdherentLayout.from_json(blob["layout"])
    dims = (blob["input_dim"], blob["output_dim"])
    if dims != (layout.input_dim, layout.output_dim):
        raise PimannError(path, f"input_dim, output_dim {dims} do not fit the ADHERENT layout")
    try:
        model = MANN(*dims, ModelParams(**blob["model_params"]), seeds=[meta["seed"]])
        model.load_state_dict(blob["state_dict"])
    except (TypeError, ValueError, RuntimeError) as error:
        raise PimannError(path, f"not an ADHERENT model ({error})") from None
    for name, tensor in model.state_dict().items():
        _check_tensor(path, f"state_dict[{name!r}]", tensor, tuple(tensor.shape))
    stats = blob["stats"] if isinstance(blob["stats"], dict) else {}
    for name, size in zip(STAT_NAMES, (dims[0], dims[0], dims[1], dims[1]), strict=True):
        _check_tensor(path, f"stats[{name!r}]", stats.get(name), (size,))
    normalisation = Normalisation(*(stats[n].cpu().numpy() for n in STAT_NAMES))
    return model.eval(), layout, normalisation, meta
