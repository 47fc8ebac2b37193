"""The ADHERENT baseline's features (Viceconte et al. 2022, RA-L; the network of BLF MANN.cpp):
its layout, its samples from retargeted clips and its dataset file.

Per frame c of a clip (authors' features_extractor.py, GlobalFrameFeatures): the ground-projected
base position p_c (root_link x, y), the ground base direction (the base x axis projected on the
floor, unit; its angle theta_c), the facing direction f_c = unit(ground base direction + ground
chest direction) (angle phi_c), the base velocity v_c = (p_c - p_{c-1}) / dt (first difference
ending at c, as pimann.learn.features), joints s_c and sdot_c = (s_c - s_{c-1}) / dt.

The window of frame c (LocalWindowFeatures): at each offset o of `features.windows[window]
.input_s` (frames), p_{c+o} - p_c, f_{c+o} and v_{c+o}, each written in the facing frame at c
(origin p_c, x along f_c), 2-D, interleaved (x, y) per sample as BLF MANN.cpp fills its input.

    x_i = [positions, directions, velocities of the window of frame i - 1 (12 samples each),
           s_{i-1}, sdot_{i-1}]                                 (BLF MANN.cpp input order)
    y_i = [positions, directions, velocities of the window of frame i at the offsets > 0,
           s_i, sdot_i, (vx, vy, yaw rate)]                     (BLF MANN.cpp output order)

The twist is the base motion from i - 1 to i: (p_i - p_{i-1}) / dt in the ground base frame at
i - 1 and (theta_i - theta_{i-1}) / dt (LocalFrameFeatures). The window sits on the frame of the
state it comes with (x_i's on s_{i-1}'s frame, y_i's on s_i's): BLF's rollout
(MANNAutoregressive::setInput) builds the next input's past half around the state just
generated and takes its future half from y_i, so x_{i+1} is rebuilt from y_i exactly
(pimann.generate.adherent_rollout). The authors' python extractor takes the window one frame
after the state (y_i's of frame i + 1); that off-by-one is not kept. y_i's window (frame i) is
not x_i's (frame i - 1): no output column copies an input column.

The split (by source clip), the time-reversed training clips, the contact flags, the standing
pose and the z-score statistics are pimann.learn.features' own; the file is
pimann.learn.dataset's format with this layout (`read_adherent_dataset` reads it back).
"""

from __future__ import annotations

import dataclasses
import json
import logging
from collections.abc import Sequence
from pathlib import Path

import h5py
import numpy as np
import torch
from scipy.spatial.transform import Rotation

from pimann.core.errors import PimannError, about
from pimann.core.params import FeaturesParams
from pimann.core.robot import CHEST_FRAME, LEFT_SOLE, N_JOINTS, RIGHT_SOLE, Robot
from pimann.core.trajectory import Trajectory
from pimann.learn.dataset import FeatureDataset, _array, _names
from pimann.learn.feature_layout import Normalisation
from pimann.learn.features import (
    settled_contacts,
    split_sources,
    with_time_reversed,
)
from pimann.learn.kinematics_torch import TorchKinematics
from pimann.learn.standing import data_standing

log = logging.getLogger(__name__)

KIND = "adherent"
BASE_BLOCKS = ("base_positions", "facing_directions", "base_velocities")
TWIST = ("vx", "vy", "yaw_rate")


@dataclasses.dataclass(frozen=True)
class AdherentLayout:
    """Where each quantity sits in ADHERENT's x and y; `offsets` in frames at `rate_hz`."""

    offsets: tuple[int, ...]
    rate_hz: float
    n_joints: int = N_JOINTS
    kind: str = KIND

    @property
    def variant(self) -> str:  # what a model's meta and the rollout record call it
        return KIND

    @property
    def future_offsets(self) -> tuple[int, ...]:
        return tuple(o for o in self.offsets if o > 0)

    @property
    def past_offsets(self) -> tuple[int, ...]:
        return tuple(o for o in self.offsets if o <= 0)

    @staticmethod
    def _slices(blocks: list[tuple[str, int]]) -> dict[str, slice]:
        ends = np.cumsum([width for _, width in blocks])
        return {name: slice(int(e - w), int(e)) for (name, w), e in zip(blocks, ends, strict=True)}

    @property
    def x_slices(self) -> dict[str, slice]:
        n = 2 * len(self.offsets)
        return self._slices(
            [
                *((b, n) for b in BASE_BLOCKS),
                ("joints", self.n_joints),
                ("joint_velocities", self.n_joints),
            ]
        )

    @property
    def y_slices(self) -> dict[str, slice]:
        n = 2 * len(self.future_offsets)
        return self._slices(
            [
                *((f"{b}_future", n) for b in BASE_BLOCKS),
                ("joints", self.n_joints),
                ("joint_velocities", self.n_joints),
                ("base_twist", 3),
            ]
        )

    @property
    def input_dim(self) -> int:
        return next(reversed(self.x_slices.values())).stop

    @property
    def output_dim(self) -> int:
        return next(reversed(self.y_slices.values())).stop

    def names(self, which: str) -> list[str]:
        """One name per column of x (`which="x"`) or y, e.g. `base_positions[-50].x`."""
        offsets = self.offsets if which == "x" else self.future_offsets
        slices = self.x_slices if which == "x" else self.y_slices
        names: list[str] = []
        for block, part in slices.items():
            if block.startswith(BASE_BLOCKS):
                names += [f"{block}[{o}].{a}" for o in offsets for a in "xy"]
            elif block == "base_twist":
                names += [f"base_twist.{a}" for a in TWIST]
            else:
                names += [f"{block}.{k}" for k in range(part.stop - part.start)]
        return names

    def to_json(self) -> str:
        return json.dumps(dataclasses.asdict(self))

    @classmethod
    def from_json(cls, text: str) -> AdherentLayout:
        """The layout `to_json` wrote; anything else raises PimannError."""
        try:
            raw = json.loads(text)
            if not isinstance(raw, dict) or raw.get("kind") != KIND:
                raise TypeError("not an ADHERENT layout (kind != 'adherent')")
            raw["offsets"] = tuple(raw["offsets"])
            layout = cls(**raw)
        except KeyError as error:
            raise PimannError(None, f"the ADHERENT layout lacks {error}") from None
        except (TypeError, ValueError) as error:
            raise PimannError(None, f"not an ADHERENT layout ({error})") from None
        fine = (
            all(type(o) is int for o in layout.offsets)
            and list(layout.offsets) == sorted(set(layout.offsets))
            and 0 in layout.offsets
            and layout.future_offsets
            and type(layout.rate_hz) in (int, float)
            and layout.rate_hz > 0
        )
        if not fine:
            raise PimannError(None, f"the ADHERENT layout is malformed: {text}")
        return layout


def adherent_layout(params: FeaturesParams, rate_hz: float) -> AdherentLayout:
    """The layout of `features.windows[features.window]`'s input offsets at `rate_hz`."""
    if params.window not in params.windows:
        raise PimannError(
            None, f"features.window {params.window!r} is not one of {sorted(params.windows)}"
        )
    offsets = tuple(int(round(s * rate_hz)) for s in params.windows[params.window].input_s)
    return AdherentLayout(offsets, float(rate_hz))


class BodyFrames:
    """Both soles and the chest in the base frame, for joints (N, 26), vectorised (the torso
    chain of pimann.learn.kinematics_torch, float64)."""

    FRAMES = (LEFT_SOLE, RIGHT_SOLE, CHEST_FRAME)  # columns

    def __init__(self, robot: Robot):
        self.kinematics = TorchKinematics(robot, torch.float64, "cpu", frames=self.FRAMES)

    def __call__(self, joints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(positions (N, 3, 3), rotations (N, 3, 3, 3)): frame in the base frame."""
        with torch.no_grad():
            chain = self.kinematics.chains(torch.as_tensor(np.asarray(joints, dtype=float)))
        return chain.frame_positions.numpy(), chain.frame_rotations.numpy()


def unit(vectors: np.ndarray) -> np.ndarray:
    return vectors / np.linalg.norm(vectors, axis=-1, keepdims=True)


def facing_direction(base_rotation: np.ndarray, chest_in_base: np.ndarray) -> np.ndarray:
    """(..., 2) unit(ground base direction + ground chest direction) (features_extractor.py;
    BLF MANNAutoregressive::setInput: root and chest x axes): base_rotation world <- base,
    chest_in_base base <- chest."""
    base_x = unit(base_rotation[..., :2, 0])
    chest_x = unit((base_rotation @ chest_in_base)[..., :2, 0])
    return unit(base_x + chest_x)


def planar_rotation(angle: np.ndarray) -> np.ndarray:
    """(..., 2, 2) rotation by `angle`."""
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


@dataclasses.dataclass
class FrameFeatures:
    """Per frame of a clip (module docstring); velocities are NaN at frame 0."""

    position: np.ndarray  # (T, 2) ground-projected base position
    base_angle: np.ndarray  # (T,) ground base direction, unwrapped
    facing: np.ndarray  # (T, 2) unit facing direction
    velocity: np.ndarray  # (T, 2) first differences of `position`
    joints: np.ndarray  # (T, nj)
    joint_velocities: np.ndarray  # (T, nj)


def frame_features(trajectory: Trajectory, frames: BodyFrames) -> FrameFeatures:
    """The per-frame quantities of a clip (authors' GlobalFrameFeatures, first differences)."""
    dt = 1.0 / trajectory.rate_hz
    rotation = Rotation.from_quat(trajectory.base_quaternion_xyzw).as_matrix()
    joints = np.asarray(trajectory.joint_positions, dtype=float)
    _, frame_rotations = frames(joints)
    position = np.asarray(trajectory.base_position, dtype=float)[:, :2].copy()
    base_x = rotation[:, :2, 0]
    velocity = np.full(position.shape, np.nan)
    joint_velocities = np.full(joints.shape, np.nan)
    velocity[1:] = np.diff(position, axis=0) / dt
    joint_velocities[1:] = np.diff(joints, axis=0) / dt
    return FrameFeatures(
        position=position,
        base_angle=np.unwrap(np.arctan2(base_x[:, 1], base_x[:, 0])),
        facing=facing_direction(rotation, frame_rotations[:, 2]),
        velocity=velocity,
        joints=joints,
        joint_velocities=joint_velocities,
    )


def window(frame: FrameFeatures, centres: np.ndarray, offsets: Sequence[int]) -> np.ndarray:
    """(N, 3, K, 2) positions, facing directions and velocities at centres + offsets, in the
    facing frame at each centre (features_extractor.py LocalWindowFeatures)."""
    at = centres[:, None] + np.asarray(offsets)[None, :]  # (N, K)
    facing = frame.facing[centres]
    to_local = planar_rotation(np.arctan2(facing[:, 1], facing[:, 0])).transpose(0, 2, 1)
    parts = (
        frame.position[at] - frame.position[centres][:, None],
        frame.facing[at],
        frame.velocity[at],
    )
    return np.stack([np.einsum("nij,nkj->nki", to_local, part) for part in parts], axis=1)


def clip_samples(
    trajectory: Trajectory, layout: AdherentLayout, frames: BodyFrames
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(X (N, in), Y (N, out), steps (N,)) of one clip, physical units (module docstring)."""
    n = len(trajectory)
    none = np.empty((0, layout.input_dim)), np.empty((0, layout.output_dim)), np.empty(0, int)
    # x_i's window sits on frame i - 1 and needs velocities (index >= 1) from i - 1 + min(o);
    # sdot_{i-1} needs i - 1 >= 1; y_i's window on frame i reaches i + max(o)
    first = max(2, 2 - min(layout.offsets))
    last = n - 1 - max(layout.offsets)
    if n < 3 or last < first:
        return none
    steps = np.arange(first, last + 1)
    frame = frame_features(trajectory, frames)
    dt = 1.0 / trajectory.rate_hz
    past = window(frame, steps - 1, layout.offsets)  # (N, 3, 12, 2)
    future = window(frame, steps, layout.future_offsets)  # (N, 3, 6, 2)
    to_base = planar_rotation(frame.base_angle[steps - 1]).transpose(0, 2, 1)
    linear = np.einsum("nij,nj->ni", to_base, frame.velocity[steps])
    yaw_rate = (frame.base_angle[steps] - frame.base_angle[steps - 1]) / dt
    x = np.concatenate(
        [past.reshape(len(steps), -1), frame.joints[steps - 1], frame.joint_velocities[steps - 1]],
        axis=1,
    )
    y = np.concatenate(
        [
            future.reshape(len(steps), -1),
            frame.joints[steps],
            frame.joint_velocities[steps],
            linear,
            yaw_rate[:, None],
        ],
        axis=1,
    )
    return x, y, steps


def build_adherent_dataset(
    clips: Sequence[tuple[str, Trajectory]], params: FeaturesParams, robot: Robot
) -> FeatureDataset:
    """ADHERENT's samples of every clip, split by source clip and normalised with the training
    statistics, as pimann.learn.features.build_dataset does for the MANN's."""
    if not clips:
        raise PimannError(params.input, "no clips to build features from")
    rates = {float(t.rate_hz) for _, t in clips}
    if len(rates) != 1:
        raise PimannError(params.input, f"clips have different rates {sorted(rates)} Hz")
    layout = adherent_layout(params, rates.pop())
    frames = BodyFrames(robot)
    test_sources = split_sources([t for _, t in clips], params.test_fraction, params.split_seed)
    clips = with_time_reversed(clips, params.time_reversed, test_sources)
    with_contacts = all(t.contacts is not None for _, t in clips)
    margin = round(params.contact_margin_s * layout.rate_hz)
    parts: dict[bool, list[tuple[np.ndarray, ...]]] = {False: [], True: []}
    for k, (_, trajectory) in enumerate(clips):
        x, y, steps = clip_samples(trajectory, layout, frames)
        origin = np.stack([np.full(len(steps), k), steps], axis=1)
        contacts = np.zeros((len(steps), 2), bool)
        if with_contacts:
            contacts = settled_contacts(trajectory.contacts, margin)[steps]
        parts[trajectory.source in test_sources].append((x, y, origin, contacts))

    def stack(side: bool) -> tuple[np.ndarray, ...]:
        items = parts[side] or [
            (
                np.empty((0, layout.input_dim)),
                np.empty((0, layout.output_dim)),
                np.empty((0, 2)),
                np.empty((0, 2)),
            )
        ]
        x, y, origin, contacts = (np.concatenate(a) for a in zip(*items, strict=True))
        return x, y, origin.astype(np.int64), contacts.astype(bool) if with_contacts else None

    x_train, y_train, train_origin, train_contacts = stack(False)
    x_test, y_test, test_origin, test_contacts = stack(True)
    if len(x_train) == 0 or len(x_test) == 0:
        raise PimannError(
            params.input, f"empty split: {len(x_train)} train, {len(x_test)} test samples"
        )
    stats = Normalisation.fit(x_train, y_train)
    standing = data_standing(t for _, t in clips if t.source not in test_sources)
    return FeatureDataset(
        x_train=stats.normalise_x(x_train).astype(np.float32),
        y_train=stats.normalise_y(y_train).astype(np.float32),
        x_test=stats.normalise_x(x_test).astype(np.float32),
        y_test=stats.normalise_y(y_test).astype(np.float32),
        stats=stats,
        layout=layout,  # type: ignore[arg-type]  # write_dataset reads the same members
        clips=[name for name, _ in clips],
        sources=[t.source for _, t in clips],
        train_origin=train_origin,
        test_origin=test_origin,
        train_contacts=train_contacts,
        test_contacts=test_contacts,
        standing=standing.to_json(),
    )


def read_adherent_dataset(path: str | Path) -> FeatureDataset:
    """The file pimann.learn.dataset.write_dataset wrote with an ADHERENT layout; any other
    (another layout, cut short, NaN) named."""
    path = Path(path)
    try:
        file = h5py.File(path, "r")
    except OSError as error:
        raise PimannError(path, f"cannot open the feature dataset ({error})") from None
    try:
        with file:
            if "layout" not in file.attrs:
                raise PimannError(path, "not a feature dataset (lacks attribute layout)")
            with about(path, "attribute layout"):
                layout = AdherentLayout.from_json(file.attrs["layout"])
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
                split[side] = x, y, origin
            standing = json.loads(file.attrs["standing"]) if "standing" in file.attrs else None
            clips, sources = _names(file, path, "clips"), _names(file, path, "sources")
    except (OSError, KeyError) as error:
        raise PimannError(path, f"unreadable feature dataset ({error})") from None
    return FeatureDataset(
        x_train=split["train"][0],
        y_train=split["train"][1],
        x_test=split["test"][0],
        y_test=split["test"][1],
        stats=stats,
        layout=layout,  # type: ignore[arg-type]
        clips=clips,
        sources=sources,
        train_origin=split["train"][2],
        test_origin=split["test"][2],
        standing=standing,
    )
