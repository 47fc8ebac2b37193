"""Value checks of params.yaml, run when it loads (pimann.core.params.load_params).

The loader checks names and types; these check values, so that `batch_size: 0`, a negative
`epochs`, `test_fraction: 1.5` or a scenario name with a typo fail at once, naming the key and
what it allows, instead of hours later (or never, silently). Two kinds:

- ranges: `RANGES` maps a dotted key pattern (`*` matches one key or list index) to a bound;
  every number must also be finite (the loader rejects NaN and infinities itself);
- cross-references: names that must exist elsewhere in the file (`check_references`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from fnmatch import fnmatchcase
from pathlib import Path
from typing import Any

from pimann.core.errors import PimannError


@dataclasses.dataclass(frozen=True)
class Bound:
    """low < value (or <=, `closed_low`) and value < high (or <=); None: unbounded."""

    low: float | None = None
    high: float | None = None
    closed_low: bool = True
    closed_high: bool = True

    def holds(self, value: float) -> bool:
        above = self.low is None or (value >= self.low if self.closed_low else value > self.low)
        below = self.high is None or (value <= self.high if self.closed_high else value < self.high)
        return above and below

    def __str__(self) -> str:
        low = "" if self.low is None else f"{'[' if self.closed_low else '('}{self.low:g}"
        high = "" if self.high is None else f"{self.high:g}{']' if self.closed_high else ')'}"
        if self.low is not None and self.high is not None:
            return f"in {low}, {high}"
        if self.low is not None:
            return f"{'>=' if self.closed_low else '>'} {self.low:g}"
        return f"{'<=' if self.closed_high else '<'} {self.high:g}"


POSITIVE = Bound(0.0, closed_low=False)
NON_NEGATIVE = Bound(0.0)
AT_LEAST_ONE = Bound(1.0)
FRACTION = Bound(0.0, 1.0)
OPEN_FRACTION = Bound(0.0, 1.0, closed_low=False, closed_high=False)

RANGES: dict[str, Bound] = {
    "data.sources.*.rate_hz": POSITIVE,
    "data.sources.*.clip_s": POSITIVE,
    "data.sources.*.max_speed": POSITIVE,
    "data.sources.*.max_takes": NON_NEGATIVE,
    "data.skeletons.*.unit_to_m": POSITIVE,
    "retarget.rate_hz": POSITIVE,
    "retarget.*_gain": POSITIVE,
    "retarget.*_weight": NON_NEGATIVE,
    "retarget.gain_time_step": POSITIVE,
    "retarget.posture_cost": NON_NEGATIVE,
    "retarget.iterations_per_frame": AT_LEAST_ONE,
    "retarget.swing_clearance": NON_NEGATIVE,
    "retarget.lift_height": NON_NEGATIVE,
    "retarget.min_*": NON_NEGATIVE,
    "retarget.contact_*": POSITIVE,
    "retarget.release_*": POSITIVE,
    "retarget.workers": AT_LEAST_ONE,
    "features.windows.*.*.*": Bound(-10.0, 10.0),  # s around the current step
    "features.test_fraction": OPEN_FRACTION,
    "features.contact_margin_s": NON_NEGATIVE,
    "model.n_experts": AT_LEAST_ONE,
    "model.*_hidden": AT_LEAST_ONE,
    "model.*_layers": AT_LEAST_ONE,
    "model.dropout": Bound(0.0, 1.0, closed_high=False),
    "train.pi_weights.*": NON_NEGATIVE,
    "train.input_noise": NON_NEGATIVE,
    "train.rollout_states": FRACTION,
    "train.rollout_steps": AT_LEAST_ONE,
    "train.seeds.*": NON_NEGATIVE,
    "train.epochs": AT_LEAST_ONE,
    "train.batch_size": AT_LEAST_ONE,
    "train.learning_rate": POSITIVE,
    "train.weight_decay": NON_NEGATIVE,
    "train.restart_period": AT_LEAST_ONE,
    "train.restart_mult": AT_LEAST_ONE,
    "train.max_train_samples": AT_LEAST_ONE,
    "train.eval_batch_size": AT_LEAST_ONE,
    "train.workers": AT_LEAST_ONE,
    "train.threads": AT_LEAST_ONE,
    "rollout.k0": NON_NEGATIVE,
    "rollout.k1": NON_NEGATIVE,
    "rollout.goal_factor": POSITIVE,
    "rollout.goal_radius": POSITIVE,
    "rollout.command_blend_tau": NON_NEGATIVE,
    "rollout.stop_blend_s": NON_NEGATIVE,
    "rollout.stop_timeout_s": NON_NEGATIVE,
    "rollout.benchmark_train_clips": NON_NEGATIVE,
    "rollout.scenarios.*.*.duration": POSITIVE,
    "evaluate.contact_*_height": POSITIVE,
    "evaluate.contact_switch_time": NON_NEGATIVE,
    "evaluate.skating_*": POSITIVE,
    "evaluate.walk_distance": POSITIVE,
    "simulate.timestep": POSITIVE,
    "simulate.*_rate_hz": POSITIVE,
    "simulate.kp_*": POSITIVE,
    "simulate.kv_ratio": NON_NEGATIVE,
    "simulate.armature": NON_NEGATIVE,
    "simulate.friction": POSITIVE,
    "simulate.*_scale": POSITIVE,
    "simulate.min_*": NON_NEGATIVE,
    "simulate.swing_height": POSITIVE,
    "simulate.com_height": POSITIVE,
    "simulate.*_hold_s": NON_NEGATIVE,
    "simulate.zmp_margin": NON_NEGATIVE,
    "simulate.plan_dt": POSITIVE,
    "simulate.plan_*_weight": NON_NEGATIVE,
    "simulate.k_*": NON_NEGATIVE,
    "simulate.zmp_filter_hz": POSITIVE,
    "simulate.*_gain": NON_NEGATIVE,
    "simulate.posture_cost": NON_NEGATIVE,
    "simulate.fall_height": POSITIVE,
    "simulate.video_every_n": AT_LEAST_ONE,
    "simulate.video_width": Bound(16.0),
    "simulate.video_height": Bound(16.0),
    "simulate.runs.*.seed": NON_NEGATIVE,
    "simulate.mpc.horizon_s": POSITIVE,
    "simulate.mpc.dt": POSITIVE,
    "simulate.mpc.friction": POSITIVE,
    "simulate.mpc.corner_*": POSITIVE,
    "simulate.mpc.com_z_*": POSITIVE,
    "simulate.mpc.freeze_s": NON_NEGATIVE,
    "simulate.mpc.*_weight": NON_NEGATIVE,
    "simulate.mpc.*_weight.*": NON_NEGATIVE,
    "simulate.mpc.max_iterations": AT_LEAST_ONE,
    "simulate.pushes.duration_s": POSITIVE,
    "simulate.pushes.max_force": POSITIVE,
    "simulate.pushes.tolerance": POSITIVE,
    "simulate.pushes.recovery_s": POSITIVE,
    "simulate.pushes.rollouts.*.seed": NON_NEGATIVE,
    "figures.drift_reduction": Bound(0.0, 1.0, closed_low=False),
    "figures.width_in": POSITIVE,
    "figures.font_pt": POSITIVE,
    "figures.dpi": Bound(50.0),
}


def _leaves(value: Any, path: tuple[str, ...] = ()) -> Iterator[tuple[tuple[str, ...], Any]]:
    """(key path, value) of every number in a params tree (dataclasses, dicts, lists)."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        for field in dataclasses.fields(value):
            yield from _leaves(getattr(value, field.name), (*path, field.name))
    elif isinstance(value, dict):
        for key, item in value.items():
            yield from _leaves(item, (*path, str(key)))
    elif isinstance(value, list):
        for index, item in enumerate(value):
            yield from _leaves(item, (*path, str(index)))
    elif isinstance(value, int | float) and not isinstance(value, bool):
        yield path, value


def _matches(pattern: str, path: tuple[str, ...]) -> bool:
    """`*` matches one whole key, or completes one with a prefix or suffix (`kp_*`)."""
    parts = pattern.split(".")
    return len(parts) == len(path) and all(
        fnmatchcase(key, part) for part, key in zip(parts, path, strict=True)
    )


def check_ranges(params: Any, source: Path) -> None:
    for path, value in _leaves(params):
        for pattern, bound in RANGES.items():
            if _matches(pattern, path) and not bound.holds(float(value)):
                key = ".".join(path)
                raise PimannError(source, f"{key} must be {bound}, not {value!r}")


def _unknown(source: Path, key: str, value: Any, known: list) -> PimannError:
    return PimannError(source, f"{key}: unknown {value!r}; known: {', '.join(map(str, known))}")


def model_names(params: Any) -> list[str]:
    """The training outputs' folder names: w<weight> per PI weight, and the baseline."""
    return [f"w{weight:g}" for weight in params.train.pi_weights] + ["baseline"]


def check_references(params: Any, source: Path) -> None:
    """Names used in one place that must exist in another."""
    for name, item in params.data.sources.items():
        if item.skeleton != "auto" and item.skeleton not in params.data.skeletons:
            raise _unknown(
                source, f"data.sources.{name}.skeleton", item.skeleton,
                ["auto", *sorted(params.data.skeletons)],
            )  # fmt: skip
    if params.features.window not in params.features.windows:
        raise _unknown(source, "features.window", params.features.window,
                       sorted(params.features.windows))  # fmt: skip
    for key, values in (("train.seeds", params.train.seeds),
                        ("train.pi_weights", params.train.pi_weights)):  # fmt: skip
        if not values or len(set(values)) != len(values):
            raise PimannError(source, f"{key} must be a non-empty list without repeats")
    scenarios = sorted(params.rollout.scenarios)
    for k, name in enumerate(params.rollout.scenario_names):
        if name not in params.rollout.scenarios:
            raise _unknown(source, f"rollout.scenario_names[{k}]", name, scenarios)
    rolled_out = params.rollout.scenario_names
    if params.figures.scenario not in rolled_out:
        raise _unknown(source, "figures.scenario", params.figures.scenario, rolled_out)
    weights = params.train.pi_weights
    for key in ("pi_weight", "large_weight"):
        if getattr(params.figures, key) not in weights:
            raise _unknown(source, f"figures.{key}", getattr(params.figures, key), weights)
    for key in ("box_weights", "foot_height_weights"):
        for k, weight in enumerate(getattr(params.figures, key)):
            if weight not in weights:
                raise _unknown(source, f"figures.{key}[{k}]", weight, weights)
    mpc = params.simulate.mpc
    if mpc.com_z_min > mpc.com_z_max:
        raise PimannError(source, "simulate.mpc.com_z_min must not exceed simulate.mpc.com_z_max")
    for key in ("box_x", "box_y"):
        box = getattr(mpc, key)
        if len(box) != 2 or box[0] > 0.0 or box[1] < 0.0:
            problem = f"simulate.mpc.{key} must be [low <= 0, high >= 0], not {box}"
            raise PimannError(source, problem)
    for key in ("com_weight", "force_rate_weight"):
        if len(getattr(mpc, key)) != 3:
            raise PimannError(source, f"simulate.mpc.{key} must have 3 entries (x, y, z)")
    if mpc.horizon_s < 2 * mpc.dt:
        raise PimannError(source, "simulate.mpc.horizon_s must span at least 2 knots of dt")
    for k, run in enumerate(params.simulate.pushes.rollouts):
        key = f"simulate.pushes.rollouts[{k}]"
        if run.model not in model_names(params):
            raise _unknown(source, f"{key}.model", run.model, model_names(params))
        if run.seed not in params.train.seeds:
            raise _unknown(source, f"{key}.seed", run.seed, params.train.seeds)
        if run.scenario not in rolled_out:
            raise _unknown(source, f"{key}.scenario", run.scenario, rolled_out)
    for k, run in enumerate(params.simulate.runs):
        key = f"simulate.runs[{k}]"
        if run.model not in model_names(params):
            raise _unknown(source, f"{key}.model", run.model, model_names(params))
        if run.seed not in params.train.seeds:
            raise _unknown(source, f"{key}.seed", run.seed, params.train.seeds)
        if run.scenario not in rolled_out:
            raise _unknown(source, f"{key}.scenario", run.scenario, rolled_out)
    evaluate = params.evaluate
    if evaluate.contact_off_height < evaluate.contact_on_height:
        raise PimannError(
            source, "evaluate.contact_off_height must be >= evaluate.contact_on_height "
            f"({evaluate.contact_off_height:g} < {evaluate.contact_on_height:g})",
        )  # fmt: skip


def check_params(params: Any, source: Path) -> None:
    """Every range and cross-reference; the first failure is a PimannError naming the key."""
    check_ranges(params, source)
    check_references(params, source)
