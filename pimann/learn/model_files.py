"""A trained model's folder: model.pt (weights, sizes, feature layout, normalisation) and
meta.json (seed, params, training record), written by training and read by every later
stage; anything else in their place (a file cut short, another network, NaN weights) is
named with the file and the problem."""

from __future__ import annotations

import json
import pickle
import warnings
from pathlib import Path

import torch
from pydantic import ValidationError

from pimann.core.errors import PimannError, about
from pimann.core.params import ModelParams, validation_problem
from pimann.learn.feature_layout import FeatureLayout, Normalisation
from pimann.learn.mann import MANN

MODEL_FILE = "model.pt"
META_FILE = "meta.json"
STAT_NAMES = ("x_mean", "x_std", "y_mean", "y_std")
MODEL_KEYS = ("state_dict", "input_dim", "output_dim", "model_params", "layout", "stats")


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
            path,
            f"input_dim, output_dim {dims} do not fit the layout's "
            f"{(layout.input_dim, layout.output_dim)}",
        )
    try:
        model_params = ModelParams(**blob["model_params"])
        model = MANN(*dims, model_params, ensemble=1, seeds=[meta["seed"]])
    except ValidationError as error:
        raise PimannError(path, f"model_params: {validation_problem(error)}") from None
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


def model_seeds(models_dir: str | Path) -> dict[int, Path]:
    """{seed: folder} of the trained models in a training output (`<seed>/meta.json`)."""
    models_dir = Path(models_dir)
    seeds: dict[int, Path] = {}
    for folder in (p.parent for p in models_dir.glob("*/meta.json")):
        try:
            seeds[int(folder.name)] = folder
        except ValueError:
            raise PimannError(folder, "not a seed: a model folder is named by its seed") from None
    if not seeds:
        raise PimannError(models_dir, "holds no trained model (<seed>/meta.json)")
    return dict(sorted(seeds.items()))
