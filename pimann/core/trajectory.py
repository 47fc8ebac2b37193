"""The robot trajectory file (ARCHITECTURE Contract 1): one HDF5 layout for every stage.

A file holds one trajectory at its root, or a collection with one group per clip. Datasets:
`time` (T,), `base_position` (T,3), `base_quaternion_xyzw` (T,4), `joint_positions` (T,26);
optional `contacts` (T,2) bool (left, right), `joint_velocities` (T,26), `com_position`
(T,3). Attributes: `joint_names`, `rate_hz`, `source`, and any extra ones (`mirrored`,
`steering`, `pi_weight`, `seed`, ...).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from pimann.core.atomic import atomic_path
from pimann.core.errors import PimannError, require_finite
from pimann.core.robot import JOINT_NAMES, N_JOINTS

OPTIONAL_DATASETS = {"contacts": 2, "joint_velocities": N_JOINTS, "com_position": 3}


@dataclasses.dataclass
class Trajectory:
    time: np.ndarray
    base_position: np.ndarray
    base_quaternion_xyzw: np.ndarray
    joint_positions: np.ndarray
    source: str
    rate_hz: float
    contacts: np.ndarray | None = None
    joint_velocities: np.ndarray | None = None
    com_position: np.ndarray | None = None
    attrs: dict[str, Any] = dataclasses.field(default_factory=dict)

    def __post_init__(self) -> None:
        n = len(self.time)
        shapes = {
            "base_position": (self.base_position, 3),
            "base_quaternion_xyzw": (self.base_quaternion_xyzw, 4),
            "joint_positions": (self.joint_positions, N_JOINTS),
        }
        for name, width in OPTIONAL_DATASETS.items():
            if getattr(self, name) is not None:
                shapes[name] = (getattr(self, name), width)
        for name, (values, width) in shapes.items():
            if np.shape(values) != (n, width):
                raise PimannError(
                    self.source, f"{name} has shape {np.shape(values)}, expected {(n, width)}"
                )
            if name != "contacts":
                require_finite(self.source, name, values)

    def __len__(self) -> int:
        return len(self.time)


def _write_group(group: h5py.Group, trajectory: Trajectory) -> None:
    group.create_dataset("time", data=np.asarray(trajectory.time, dtype=np.float64))
    group.create_dataset("base_position", data=trajectory.base_position)
    group.create_dataset("base_quaternion_xyzw", data=trajectory.base_quaternion_xyzw)
    group.create_dataset("joint_positions", data=trajectory.joint_positions)
    for name in OPTIONAL_DATASETS:
        values = getattr(trajectory, name)
        if values is not None:
            group.create_dataset(name, data=values.astype(bool) if name == "contacts" else values)
    group.attrs["joint_names"] = list(JOINT_NAMES)
    group.attrs["rate_hz"] = float(trajectory.rate_hz)
    group.attrs["source"] = trajectory.source
    for key, value in trajectory.attrs.items():
        group.attrs[key] = value


def _read_group(group: h5py.Group, path: Path) -> Trajectory:
    required = ("time", "base_position", "base_quaternion_xyzw", "joint_positions")
    for name in required:
        if name not in group:
            raise PimannError(path, f"group {group.name!r} lacks dataset {name!r}")
    names = [str(n) for n in group.attrs.get("joint_names", [])]
    joints = group["joint_positions"][()]
    joint_velocities = group["joint_velocities"][()] if "joint_velocities" in group else None
    if names != list(JOINT_NAMES):
        unknown = sorted(set(names) - set(JOINT_NAMES))
        if unknown or len(names) != N_JOINTS:
            raise PimannError(
                path, f"joint_names do not match ergoCub's 26 joints (unknown: {unknown})"
            )
        order = [names.index(n) for n in JOINT_NAMES]  # same joints, other order: map by name
        joints = joints[:, order]
        joint_velocities = None if joint_velocities is None else joint_velocities[:, order]
    extra = {
        k: (v.item() if isinstance(v, np.generic) else v)
        for k, v in group.attrs.items()
        if k not in ("joint_names", "rate_hz", "source")
    }
    return Trajectory(
        time=group["time"][()],
        base_position=group["base_position"][()],
        base_quaternion_xyzw=group["base_quaternion_xyzw"][()],
        joint_positions=joints,
        source=str(group.attrs.get("source", path.name)),
        rate_hz=float(group.attrs.get("rate_hz", np.nan)),
        contacts=group["contacts"][()].astype(bool) if "contacts" in group else None,
        joint_velocities=joint_velocities,
        com_position=group["com_position"][()] if "com_position" in group else None,
        attrs=extra,
    )


def write_trajectory(path: str | Path, trajectory: Trajectory) -> None:
    """One trajectory at the file's root, written atomically."""
    with atomic_path(path) as tmp, h5py.File(tmp, "w") as file:
        _write_group(file, trajectory)


def write_collection(path: str | Path, trajectories: Iterable[tuple[str, Trajectory]]) -> None:
    """Many trajectories, one group per clip name, written atomically."""
    with atomic_path(path) as tmp, h5py.File(tmp, "w") as file:
        for name, trajectory in trajectories:
            _write_group(file.create_group(name), trajectory)


def _open(path: Path) -> h5py.File:
    try:
        return h5py.File(path, "r")
    except FileNotFoundError:
        raise PimannError(path, "file not found") from None
    except OSError as error:
        raise PimannError(path, f"not a readable HDF5 file ({error})") from None


def read_trajectory(path: str | Path, group: str | None = None) -> Trajectory:
    """The trajectory at the root (or in `group`) of a trajectory file."""
    path = Path(path)
    with _open(path) as file:
        if group is not None:
            if group not in file:
                raise PimannError(path, f"no group {group!r}")
            return _read_group(file[group], path)
        if "time" not in file:
            raise PimannError(path, "holds no trajectory at its root (a collection? name a group)")
        return _read_group(file, path)


def iter_collection(path: str | Path) -> Iterator[tuple[str, Trajectory]]:
    """(clip name, trajectory) for each group of a collection file, in name order."""
    path = Path(path)
    with _open(path) as file:
        for name in sorted(file):
            if isinstance(file[name], h5py.Group):
                yield name, _read_group(file[name], path)
