"""The features stage's dataset file: normalised train/test arrays, their statistics, layout
and where every sample came from (`FeatureDataset`), written to and read from HDF5.

Apart from pimann.learn.features so that reading a dataset (training, the diagnostics) does
not run through building one.
"""

from __future__ import annotations

import dataclasses
import json
import logging
from pathlib import Path

import h5py
import numpy as np

from pimann.core.atomic import atomic_path
from pimann.core.errors import PimannError, about, require_finite
from pimann.learn.feature_layout import FeatureLayout, Normalisation

log = logging.getLogger(__name__)


@dataclasses.dataclass
class FeatureDataset:
    """Normalised train/test arrays, their statistics and where every sample came from."""

    x_train: np.ndarray
    y_train: np.ndarray
    x_test: np.ndarray
    y_test: np.ndarray
    stats: Normalisation
    layout: FeatureLayout
    clips: list[str]  # group names, indexed by the first column of `*_origin`
    sources: list[str]  # each clip's source (a clip and its mirror share one)
    train_origin: np.ndarray  # (N, 2) clip index, step
    test_origin: np.ndarray
    # (N, 2) bool: left and right foot in contact at the sample's step (the data's own contact
    # detection), for the diagnostics (diagnostics.teacher_forcing); None when a clip has none
    train_contacts: np.ndarray | None = None
    test_contacts: np.ndarray | None = None
    # the training clips' standing pose (pimann.learn.standing), JSON; None: not recorded
    standing: dict | None = None

    @property
    def train_clips(self) -> list[str]:
        return [self.clips[k] for k in np.unique(self.train_origin[:, 0])]

    @property
    def test_clips(self) -> list[str]:
        return [self.clips[k] for k in np.unique(self.test_origin[:, 0])]


def _arrays(dataset: FeatureDataset) -> dict[str, np.ndarray]:
    """The file's datasets, by name."""
    stats = dataset.stats
    arrays = {
        "X_train": dataset.x_train,
        "Y_train": dataset.y_train,
        "X_test": dataset.x_test,
        "Y_test": dataset.y_test,
        "X_mean": stats.x_mean,
        "X_std": stats.x_std,
        "Y_mean": stats.y_mean,
        "Y_std": stats.y_std,
        "train_origin": dataset.train_origin,
        "test_origin": dataset.test_origin,
    }
    if dataset.train_contacts is not None and dataset.test_contacts is not None:
        arrays["train_contacts"] = dataset.train_contacts
        arrays["test_contacts"] = dataset.test_contacts
    return arrays


def write_dataset(path: str | Path, dataset: FeatureDataset) -> None:
    """One HDF5 file: X/Y train/test, the statistics, the layout and the clip lists."""
    with atomic_path(path) as tmp, h5py.File(tmp, "w") as file:
        for name, values in _arrays(dataset).items():
            file.create_dataset(name, data=values)
        file.attrs["layout"] = dataset.layout.to_json()
        file.attrs["x_names"] = dataset.layout.names("x")
        file.attrs["y_names"] = dataset.layout.names("y")
        for name, part in dataset.layout.x_slices.items():
            file.attrs[f"x_slice.{name}"] = (part.start, part.stop)
        for name, part in dataset.layout.y_slices.items():
            file.attrs[f"y_slice.{name}"] = (part.start, part.stop)
        file.attrs["clips"] = dataset.clips
        file.attrs["sources"] = dataset.sources
        file.attrs["train_clips"] = dataset.train_clips
        file.attrs["test_clips"] = dataset.test_clips
        if dataset.standing is not None:
            file.attrs["standing"] = json.dumps(dataset.standing)


def _array(file: h5py.File, path: Path, name: str, shape: tuple[int | None, ...]) -> np.ndarray:
    """Dataset `name`: numbers of `shape` (None: any length), all finite; else named."""
    if not isinstance(file.get(name), h5py.Dataset):
        raise PimannError(path, f"not a feature dataset (lacks the dataset {name!r})")
    values = np.asarray(file[name][()])
    fits = values.ndim == len(shape) and all(
        want in (None, got) for want, got in zip(shape, values.shape, strict=True)
    )
    if values.dtype.kind not in "biuf" or not fits:
        wanted = str(tuple("N" if w is None else w for w in shape)).replace("'", "")
        raise PimannError(
            path, f"{name} is {values.shape} {values.dtype}; the layout needs {wanted} numbers"
        )
    require_finite(path, name, values)
    return values


def _names(file: h5py.File, path: Path, key: str) -> list[str]:
    """The string-list attribute `key`."""
    values = np.asarray(file.attrs[key])
    if values.ndim != 1:
        raise PimannError(path, f"attribute {key!r} is not a list of names")
    return [v.decode() if isinstance(v, bytes) else str(v) for v in values]


def read_dataset(path: str | Path) -> FeatureDataset:
    """The file `write_dataset` wrote; any other (another layout, cut short, NaN) named."""
    path = Path(path)
    try:
        file = h5py.File(path, "r")
    except OSError as error:
        raise PimannError(path, f"cannot open the feature dataset ({error})") from None
    try:
        with file:
            return _read_open_dataset(file, path)
    except (OSError, KeyError) as error:  # an HDF5 file damaged inside
        raise PimannError(path, f"unreadable feature dataset ({error})") from None


def _read_open_dataset(file: h5py.File, path: Path) -> FeatureDataset:
    needed = (
        "X_train",
        "Y_train",
        "X_test",
        "Y_test",
        "X_mean",
        "X_std",
        "Y_mean",
        "Y_std",
        "train_origin",
        "test_origin",
    )
    missing = [n for n in needed if n not in file]
    missing += [f"attribute {n}" for n in ("layout", "clips", "sources") if n not in file.attrs]
    if missing:
        raise PimannError(path, f"not a feature dataset (lacks {missing})")
    with about(path, "attribute layout"):
        layout = FeatureLayout.from_json(file.attrs["layout"])
    clips, sources = _names(file, path, "clips"), _names(file, path, "sources")
    if len(sources) != len(clips):
        raise PimannError(path, f"{len(clips)} clips but {len(sources)} sources")
    n_in, n_out = layout.input_dim, layout.output_dim
    stats = Normalisation(
        _array(file, path, "X_mean", (n_in,)),
        _array(file, path, "X_std", (n_in,)),
        _array(file, path, "Y_mean", (n_out,)),
        _array(file, path, "Y_std", (n_out,)),
    )
    if (stats.x_std <= 0).any() or (stats.y_std <= 0).any():
        raise PimannError(path, "X_std or Y_std holds values <= 0")
    split = {}
    for side in ("train", "test"):
        x = _array(file, path, f"X_{side}", (None, n_in))
        y = _array(file, path, f"Y_{side}", (len(x), n_out))
        origin = _array(file, path, f"{side}_origin", (len(x), 2)).astype(np.int64)
        if len(origin) and not (0 <= origin[:, 0].min() and origin[:, 0].max() < len(clips)):
            raise PimannError(path, f"{side}_origin names clips beyond the {len(clips)} listed")
        contacts = None
        if f"{side}_contacts" in file:
            contacts = _array(file, path, f"{side}_contacts", (len(x), 2)).astype(bool)
        split[side] = x, y, origin, contacts
    try:
        standing = json.loads(file.attrs["standing"]) if "standing" in file.attrs else None
    except (TypeError, ValueError) as error:
        raise PimannError(path, f"attribute standing is not JSON ({error})") from None
    (x_train, y_train, train_origin, train_contacts) = split["train"]
    (x_test, y_test, test_origin, test_contacts) = split["test"]
    return FeatureDataset(
        x_train=x_train,
        y_train=y_train,
        x_test=x_test,
        y_test=y_test,
        stats=stats,
        layout=layout,
        clips=clips,
        sources=sources,
        train_origin=train_origin,
        test_origin=test_origin,
        train_contacts=train_contacts,
        test_contacts=test_contacts,
        standing=standing,
    )
