"""Typed params.yaml: one frozen dataclass per stage section.

Unknown keys (a typo) and missing keys are rejected with the dotted key's name, so a
mistyped ablation never silently runs with a default. The `profile` picks a set of
overrides from `profiles` (dotted keys), which scale data and epochs and nothing else.
"""

from __future__ import annotations

import dataclasses
import types
import typing
from pathlib import Path
from typing import Any, Literal

import yaml

from pimann.errors import PimannError
from pimann.paths import REPO_ROOT

DEFAULT_PARAMS = REPO_ROOT / "params.yaml"


@dataclasses.dataclass(frozen=True)
class SkeletonParams:
    """How one BVH skeleton maps onto the 13 XSens segments."""

    segments: dict[str, str]  # XSens segment -> BVH joint
    axes: dict[str, list[str]]  # XSens segment -> its x, y, z axes in BVH joint-local axes
    foot_pitch_deg: float  # extra pitch that makes the BVH foot flat
    unit_to_m: float  # BVH length unit in metres


@dataclasses.dataclass(frozen=True)
class DataParams:
    mocap_root: str  # relative to the shared folder unless absolute
    skeleton: str
    skeletons: dict[str, SkeletonParams]
    contents: list[str]
    styles: list[str] | None  # None: every style
    max_clips: int | None  # None: every clip that matches
    mirror: bool


@dataclasses.dataclass(frozen=True)
class RetargetParams:
    rate_hz: float
    pelvis_gain: float
    segment_gain: float
    segment_weight: float
    posture_cost: float
    iterations_per_frame: int
    solver: str
    flat_feet: bool
    head_from_t8: bool
    min_leg_roll_spread: float
    min_shoulder_roll: float
    min_foot_spacing: float
    contact_height: float
    contact_speed: float
    workers: int


@dataclasses.dataclass(frozen=True)
class FeaturesParams:
    """features: windows, split, normalisation (issue 3)."""


@dataclasses.dataclass(frozen=True)
class ModelParams:
    """model: MANN architecture (issue 3)."""


@dataclasses.dataclass(frozen=True)
class TrainParams:
    """train: optimiser, epochs, PI weights, seeds (issue 3)."""


@dataclasses.dataclass(frozen=True)
class RolloutParams:
    """rollout: autoregressive generation and steering (issue 4)."""


@dataclasses.dataclass(frozen=True)
class EvaluateParams:
    """evaluate: metrics (issue 4)."""


@dataclasses.dataclass(frozen=True)
class SimulateParams:
    """simulate: MuJoCo, DCM adjustment, whole-body QP (issue 5)."""


@dataclasses.dataclass(frozen=True)
class FiguresParams:
    """figures (issue 4)."""


@dataclasses.dataclass(frozen=True)
class Params:
    profile: Literal["paper", "quick"]
    profiles: dict[str, dict[str, Any]]
    data: DataParams
    retarget: RetargetParams
    features: FeaturesParams
    model: ModelParams
    train: TrainParams
    rollout: RolloutParams
    evaluate: EvaluateParams
    simulate: SimulateParams
    figures: FiguresParams


def _build(kind: Any, value: Any, key: str, source: Path) -> Any:
    """Check `value` against the annotation `kind`, recursing into dataclasses and containers."""
    origin = typing.get_origin(kind)
    if dataclasses.is_dataclass(kind):
        if not isinstance(value, dict):
            raise PimannError(source, f"{key or 'params'} must be a mapping")
        hints = typing.get_type_hints(kind)
        names = [f.name for f in dataclasses.fields(kind)]
        unknown = sorted(set(value) - set(names))
        if unknown:
            raise PimannError(source, f"unknown key {_join(key, unknown[0])!r}")
        missing = [n for n in names if n not in value]
        if missing:
            raise PimannError(source, f"missing key {_join(key, missing[0])!r}")
        return kind(**{n: _build(hints[n], value[n], _join(key, n), source) for n in names})
    if origin in (types.UnionType, typing.Union):
        options = typing.get_args(kind)
        if value is None and type(None) in options:
            return None
        errors = []
        for option in (o for o in options if o is not type(None)):
            try:
                return _build(option, value, key, source)
            except PimannError as error:
                errors.append(error.problem)
        raise PimannError(source, errors[0] if errors else f"{key} has the wrong type")
    if origin is Literal:
        if value not in typing.get_args(kind):
            raise PimannError(
                source, f"{key} must be one of {list(typing.get_args(kind))}, not {value!r}"
            )
        return value
    if origin is list:
        if not isinstance(value, list):
            raise PimannError(source, f"{key} must be a list")
        (item,) = typing.get_args(kind)
        return [_build(item, v, f"{key}[{i}]", source) for i, v in enumerate(value)]
    if origin is dict:
        if not isinstance(value, dict):
            raise PimannError(source, f"{key} must be a mapping")
        _, item = typing.get_args(kind)
        return {k: _build(item, v, _join(key, str(k)), source) for k, v in value.items()}
    if kind is Any:
        return value
    if kind is float and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if not isinstance(value, kind) or (kind is int and isinstance(value, bool)):
        raise PimannError(source, f"{key} must be {kind.__name__}, not {value!r}")
    return value


def _join(prefix: str, name: str) -> str:
    return f"{prefix}.{name}" if prefix else name


def _apply_overrides(raw: dict, overrides: dict[str, Any], source: Path) -> None:
    for dotted, value in overrides.items():
        node = raw
        *parents, leaf = dotted.split(".")
        for part in parents:
            if not isinstance(node.get(part), dict):
                raise PimannError(source, f"profile override {dotted!r} names no key")
            node = node[part]
        if leaf not in node:
            raise PimannError(source, f"profile override {dotted!r} names no key")
        node[leaf] = value


def load_params(path: str | Path = DEFAULT_PARAMS) -> Params:
    """Read params.yaml, apply the chosen profile's overrides, validate every key."""
    path = Path(path)
    try:
        raw = yaml.safe_load(path.read_text())
    except FileNotFoundError:
        raise PimannError(path, "params file not found") from None
    except yaml.YAMLError as error:
        raise PimannError(path, f"not valid YAML: {error}".replace("\n", " ")) from None
    if not isinstance(raw, dict):
        raise PimannError(path, "params must be a mapping of sections")
    profile = raw.get("profile")
    profiles = raw.get("profiles") or {}
    if profile not in profiles:
        raise PimannError(path, f"profile {profile!r} is not one of profiles {sorted(profiles)}")
    _apply_overrides(raw, profiles[profile], path)
    params = _build(Params, raw, "", path)
    if params.data.skeleton not in params.data.skeletons:
        raise PimannError(
            path,
            f"unknown skeleton {params.data.skeleton!r} in data.skeleton; "
            f"known: {sorted(params.data.skeletons)}",
        )
    return params


def as_dict(params: Any) -> dict:
    """Plain dict of a params section, for recording provenance beside outputs."""
    return dataclasses.asdict(params)
