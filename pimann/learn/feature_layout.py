"""Where each quantity sits in a sample's input x and output y (Sec. III-A), the windows in frames,
and the z-score statistics that normalise both: what training, generation and the model files
share about the features (pimann.learn.features builds them)."""

from __future__ import annotations

import dataclasses
import json

import numpy as np

from pimann.core.errors import PimannError
from pimann.core.params import FeaturesParams
from pimann.core.robot import N_JOINTS

VARIANTS = ("full", "ground_projected")
# the base pose p, psi in x and y: `world` as the paper (inertial position and unwrapped yaw),
# `gravity` keeps only what gravity and the floor define (height, roll, pitch; x, y, yaw = 0)
POSE_INPUTS = ("world", "gravity")
MIN_STD = 1e-8  # a constant feature (e.g. roll of the ground-projected base) keeps std 1


@dataclasses.dataclass(frozen=True)
class FeatureLayout:
    """Where each quantity sits in x and y; the windows' offsets are in frames at `rate_hz`.

    Window blocks are (samples, 3) row-major: sample k's x, y, z are columns 3k..3k+2.
    """

    input_offsets: tuple[int, ...]
    output_offsets: tuple[int, ...]
    rate_hz: float
    variant: str
    n_joints: int = N_JOINTS
    pose_input: str = "world"  # a key of POSE_INPUTS
    # (cos, sin) of the gait phase after the pose (pimann.learn.gait_phase), its longest step
    # in seconds; None: no phase (the paper)
    gait_phase_step_s: float | None = None

    @property
    def gait_phase(self) -> bool:
        return self.gait_phase_step_s is not None

    @property
    def gait_phase_names(self) -> list[str]:
        """The phase block's columns: the stride's (cos, sin)."""
        if not self.gait_phase:
            return []
        return ["gait_phase.cos", "gait_phase.sin"]

    def pose(self, position: np.ndarray, rpy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The base pose as the network sees it (input and output): `pose_input` applied."""
        if self.pose_input == "world":
            return position, rpy
        position, rpy = np.array(position, dtype=float), np.array(rpy, dtype=float)
        position[..., :2] = 0.0
        rpy[..., 2] = 0.0
        return position, rpy

    def _blocks(self, window: str, n: int) -> list[tuple[str, int]]:
        return [
            (f"base_linear_{window}", 3 * n),
            (f"base_angular_{window}", 3 * n),
            ("joints", self.n_joints),
            ("joint_velocities", self.n_joints),
            ("base_position", 3),
            ("base_rpy", 3),
        ] + ([("gait_phase", len(self.gait_phase_names))] if self.gait_phase else [])

    @staticmethod
    def _slices(blocks: list[tuple[str, int]]) -> dict[str, slice]:
        ends = np.cumsum([width for _, width in blocks])
        return {name: slice(int(e - w), int(e)) for (name, w), e in zip(blocks, ends, strict=True)}

    @property
    def x_slices(self) -> dict[str, slice]:
        """input: base_linear_window, base_angular_window, joints, ... (state at i-1)."""
        return self._slices(self._blocks("window", len(self.input_offsets)))

    @property
    def y_slices(self) -> dict[str, slice]:
        """output: base_linear_future, base_angular_future, joints, ... (state at i)."""
        return self._slices(self._blocks("future", len(self.output_offsets)))

    def past_input_offsets(self) -> list[int]:
        """The input window's samples up to now (offsets <= 0): a rollout fills them from its
        own earlier predictions, the later ones from the command."""
        return [offset for offset in self.input_offsets if offset <= 0]

    @property
    def input_dim(self) -> int:
        return next(reversed(self.x_slices.values())).stop

    @property
    def output_dim(self) -> int:
        return next(reversed(self.y_slices.values())).stop

    @property
    def current_output(self) -> int:
        """Index of offset 0 in the output window: the base velocity at step i itself."""
        if 0 not in self.output_offsets:
            raise PimannError(None, "the output window has no sample at offset 0")
        return self.output_offsets.index(0)

    def names(self, which: str) -> list[str]:
        """One name per column of x (`which="x"`) or y, e.g. `base_linear_window[-50].x`."""
        offsets = self.input_offsets if which == "x" else self.output_offsets
        slices = self.x_slices if which == "x" else self.y_slices
        names = []
        for block, part in slices.items():
            if block.startswith("base_") and block.endswith(("window", "future")):
                names += [f"{block}[{o}].{a}" for o in offsets for a in "xyz"]
            elif block == "base_rpy":
                names += [f"base_rpy.{a}" for a in ("roll", "pitch", "yaw")]
            elif block == "gait_phase":
                names += self.gait_phase_names
            else:
                names += [f"{block}.{k}" for k in range(part.stop - part.start)]
        return names

    def to_json(self) -> str:
        """The layout as JSON; without the gait phase as before it existed."""
        fields = dataclasses.asdict(self)
        if fields["gait_phase_step_s"] is None:
            del fields["gait_phase_step_s"]
        return json.dumps(fields)

    @classmethod
    def from_json(cls, text: str) -> FeatureLayout:
        """The layout `to_json` wrote; anything else raises PimannError (the caller names
        the file)."""
        try:
            raw = json.loads(text)
            if not isinstance(raw, dict):
                raise TypeError(f"a JSON {type(raw).__name__}, not an object")
            raw["input_offsets"] = tuple(raw["input_offsets"])
            raw["output_offsets"] = tuple(raw["output_offsets"])
            layout = cls(**raw)
        except KeyError as error:
            raise PimannError(None, f"the feature layout lacks {error}") from None
        except (TypeError, ValueError) as error:
            raise PimannError(None, f"not a feature layout ({error})") from None
        offsets = layout.input_offsets + layout.output_offsets
        rate = layout.rate_hz
        checks = {
            "offsets that are not integers": all(type(o) is int for o in offsets),
            f"rate_hz {rate!r}": type(rate) in (int, float) and rate > 0,
            f"variant {layout.variant!r}": layout.variant in VARIANTS,
            f"pose_input {layout.pose_input!r}": layout.pose_input in POSE_INPUTS,
            f"n_joints {layout.n_joints!r}": type(layout.n_joints) is int and layout.n_joints > 0,
            f"gait_phase_step_s {layout.gait_phase_step_s!r}": layout.gait_phase_step_s is None
            or (type(layout.gait_phase_step_s) in (int, float) and layout.gait_phase_step_s > 0),
        }
        bad = [what for what, fine in checks.items() if not fine]
        if bad:
            raise PimannError(None, f"the feature layout has {', '.join(bad)}")
        return layout


@dataclasses.dataclass(frozen=True)
class Normalisation:
    """Z-score statistics of the training samples; works on numpy arrays and torch tensors."""

    x_mean: np.ndarray
    x_std: np.ndarray
    y_mean: np.ndarray
    y_std: np.ndarray

    @classmethod
    def fit(cls, x: np.ndarray, y: np.ndarray) -> Normalisation:
        def std(values: np.ndarray) -> np.ndarray:
            s = values.std(axis=0)
            return np.where(s < MIN_STD, 1.0, s)

        return cls(x.mean(axis=0), std(x), y.mean(axis=0), std(y))

    def normalise_x(self, x):
        return (x - _like(self.x_mean, x)) / _like(self.x_std, x)

    def normalise_y(self, y):
        return (y - _like(self.y_mean, y)) / _like(self.y_std, y)

    def denormalise_x(self, x):
        return x * _like(self.x_std, x) + _like(self.x_mean, x)

    def denormalise_y(self, y):
        return y * _like(self.y_std, y) + _like(self.y_mean, y)


def _like(values: np.ndarray, reference):
    """`values` as the same kind (numpy or torch, dtype, device) as `reference`."""
    if isinstance(reference, np.ndarray):
        return values.astype(reference.dtype, copy=False)
    return reference.new_tensor(values)


def window_layout(params: FeaturesParams, rate_hz: float, variant: str) -> FeatureLayout:
    """The layout for the window named by `params.window`, offsets rounded to frames."""
    if params.pose_input not in POSE_INPUTS:
        raise PimannError(
            None, f"features.pose_input {params.pose_input!r} is not one of {list(POSE_INPUTS)}"
        )
    if params.window not in params.windows:
        raise PimannError(
            None, f"features.window {params.window!r} is not one of {sorted(params.windows)}"
        )
    if variant not in VARIANTS:
        raise PimannError(None, f"unknown feature variant {variant!r}; known: {list(VARIANTS)}")
    window = params.windows[params.window]

    def frames(seconds: list[float]) -> tuple[int, ...]:
        return tuple(int(round(s * rate_hz)) for s in seconds)

    return FeatureLayout(
        frames(window.input_s),
        frames(window.output_s),
        rate_hz,
        variant,
        pose_input=params.pose_input,
        gait_phase_step_s=params.gait_phase_step_s if params.gait_phase else None,
    )
