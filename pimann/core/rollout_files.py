"""Where the study's rollouts live and how their files are named, read and grouped.

One file per run, simple to list and to rerun:

    results/rollouts/<model>/<seed>/<scenario>-<steering|nosteering>.h5
    results/rollouts/<model>/models.json      the trained models' meta (pi_weight, variant, ...)

`<model>` is the training output's folder name (`w10`, `baseline`, `adherent`); `baseline` is
the full model with a yaw-only (ground-projected) base and no physics term, `adherent` the
ADHERENT baseline (its own features, outputs and rollout; train.adherent). `<scenario>` is a named
scenario of `rollout.scenario_names` or, with `rollout.benchmark_clips`, `clip_<clip name>`: the
command-following benchmark's script of one test clip (with `rollout.benchmark_train_clips`,
`train_<clip name>`: of a training clip; `scenario_split` tells them). Every rollout records the
script it ran
in its attrs["script"] (JSON, `script_json`; `read_script` reads it back). The helpers at the
end name the models of a table keyed like the layout (model, pi_weight, seed, scenario,
steering), as the evaluation's metrics.csv is.

Apart from the runner (pimann.generate.rollouts), in pimann.core: the generation, the simulation,
the evaluation and the figures read the layout from the lowest floor, without depending on the
generator or the training code.
"""

from __future__ import annotations

import dataclasses
import json
import re
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pimann.core.errors import PimannError
from pimann.core.params import MotionSegment, Params, Segment, StandSegment

if TYPE_CHECKING:
    import pandas as pd

    from pimann.core.trajectory import Trajectory

BASELINE = "baseline"
ADHERENT = "adherent"  # the ADHERENT baseline's training output (train.adherent)
MODELS_FILE = "models.json"
STEERING_LABEL = {True: "steering", False: "nosteering"}
CLIP_PREFIX = "clip_"  # the benchmark scripts' scenario names: clip_<clip name>
TRAIN_PREFIX = "train_"  # ... of a training clip: train_<clip name>
HELD_OUT, TRAINING = "held_out", "training"  # the benchmark's splits (`scenario_split`)
SCRIPT_ATTR = "script"  # a rollout's attrs: the script it ran, as JSON
# a contact-consistent variant of a rollout (docs/consistent.md) is the scenario
# <scenario>+<variant> (post | loop) beside the raw <scenario>; `find_rollouts` lists the raw
# ones unless asked, so every reader that knew only raw rollouts still reads only those
RAW = "raw"
VARIANT_SEPARATOR = "+"


@dataclasses.dataclass(frozen=True, order=True)
class RolloutKey:
    model: str
    seed: int
    scenario: str
    steering: bool


def rollout_path(root: str | Path, key: RolloutKey) -> Path:
    return (
        Path(root) / key.model / str(key.seed) / f"{key.scenario}-{STEERING_LABEL[key.steering]}.h5"
    )


def parse_rollout_path(root: str | Path, path: str | Path) -> RolloutKey:
    """The inverse of `rollout_path`; a file elsewhere is a PimannError."""
    parts = Path(path).relative_to(root).parts
    stem = Path(parts[-1]).stem if len(parts) == 3 else ""
    scenario, _, label = stem.rpartition("-")
    steering = {v: k for k, v in STEERING_LABEL.items()}.get(label)
    if steering is None or not scenario or not parts[1].isdigit():
        raise PimannError(path, "not <model>/<seed>/<scenario>-<steering|nosteering>.h5")
    return RolloutKey(parts[0], int(parts[1]), scenario, steering)


def find_rollouts(root: str | Path, variants: bool = False) -> list[tuple[RolloutKey, Path]]:
    """Every raw rollout under `root`; with `variants`, the contact-consistent ones too."""
    root = Path(root)
    found = sorted((parse_rollout_path(root, p), p) for p in root.glob("*/*/*.h5"))
    if not variants:
        found = [(key, path) for key, path in found if split_variant(key.scenario)[1] == RAW]
    if not found:
        raise PimannError(root, "holds no rollout (<model>/<seed>/<scenario>-<steering>.h5)")
    return found


def split_variant(scenario: str) -> tuple[str, str]:
    """(scenario, variant) of a file's scenario name: ("forward", "post") of "forward+post",
    ("forward", RAW) of "forward"."""
    base, separator, variant = scenario.rpartition(VARIANT_SEPARATOR)
    return (base, variant) if separator and base else (scenario, RAW)


def variant_scenario(scenario: str, variant: str) -> str:
    """The scenario name of a rollout's variant (the inverse of `split_variant`)."""
    return scenario if variant == RAW else f"{scenario}{VARIANT_SEPARATOR}{variant}"


def scenario_names(rollout_params: Any) -> list[str]:
    """The scenarios the rollout stage generates: `rollout.scenario_names` (else every one)."""
    names = getattr(rollout_params, "scenario_names", None)
    if names is not None:
        return list(names)
    scenarios = getattr(rollout_params, "scenarios", None)
    if scenarios is None:
        raise PimannError("params.yaml", "rollout.scenarios is missing")
    if isinstance(scenarios, dict):
        return list(scenarios)
    return [s if isinstance(s, str) else s.name for s in scenarios]


def script_json(script: Sequence[Segment]) -> str:
    """A command script as JSON: [{duration, vx, vy, yaw_rate} | {duration, stand: true}]."""
    return json.dumps([dataclasses.asdict(segment) for segment in script])


def script_of_json(text: str, source: Any = None) -> list[Segment]:
    """The inverse of `script_json`."""
    try:
        items = json.loads(text)
        script: list[Segment] = [
            StandSegment(float(d["duration"]), True)
            if d.get("stand")
            else MotionSegment(
                float(d["duration"]), float(d["vx"]), float(d["vy"]), float(d["yaw_rate"])
            )
            for d in items
        ]
    except (ValueError, TypeError, KeyError, AttributeError) as error:
        raise PimannError(source, f"not a command script ({error!r})") from None
    if not script:
        raise PimannError(source, "the command script has no segments")
    return script


def read_script(trajectory: Trajectory, params: Params | None = None) -> list[Segment]:
    """The script a rollout ran (its attrs); for a file written before the attribute, the
    named scenario's of `params` (a PimannError where there is none)."""
    text = trajectory.attrs.get(SCRIPT_ATTR)
    if text is not None:
        return script_of_json(str(text), trajectory.source)
    scenario = trajectory.attrs.get("scenario")
    if params is not None and scenario in params.rollout.scenarios:
        return list(params.rollout.scenarios[scenario])
    raise PimannError(trajectory.source, "records no command script (attrs['script'])")


def is_clip(scenario: str) -> bool:
    """A benchmark script of a clip (test or training), not a named scenario."""
    return scenario.startswith((CLIP_PREFIX, TRAIN_PREFIX))


def scenario_split(scenario: str) -> str:
    """TRAINING for a training clip's script, else HELD_OUT: the test clips' and the named
    scenarios' commands, which no training clip gave."""
    return TRAINING if scenario.startswith(TRAIN_PREFIX) else HELD_OUT


def _file_stem(clip: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]", "_", clip)


def clip_scenario(clip: str) -> str:
    """The scenario name (a file stem) of a test clip's benchmark script: clip_<clip name>."""
    return CLIP_PREFIX + _file_stem(clip)


def train_scenario(clip: str) -> str:
    """The scenario name of a training clip's benchmark script: train_<clip name>."""
    return TRAIN_PREFIX + _file_stem(clip)


def rollout_columns(
    root: str | Path, rollouts: Sequence[tuple[RolloutKey, Path]]
) -> list[dict[str, Any]]:
    """The key columns of each rollout (model, variant, pi_weight, seed, scenario, steering,
    rollout), with the seed's record from the rollout stage's models.json."""
    root = Path(root)
    seeds: dict[str, dict[str, Any]] = {}
    columns = []
    for key, path in rollouts:
        record_path = root / key.model / MODELS_FILE
        if key.model not in seeds:
            try:
                seeds[key.model] = json.loads(record_path.read_text())["seeds"]
            except FileNotFoundError:
                raise PimannError(
                    record_path, "missing: the rollout stage records the models here"
                ) from None
            except (KeyError, TypeError, ValueError) as error:
                raise PimannError(record_path, f"not a rollout record ({error!r})") from None
        seed = seeds[key.model].get(str(key.seed))
        if seed is None:
            raise PimannError(record_path, f"no record of seed {key.seed}")
        columns.append(
            {
                "model": key.model,
                "variant": seed["variant"],
                "pi_weight": seed["pi_weight"],
                "seed": key.seed,
                "scenario": key.scenario,
                "steering": key.steering,
                "rollout": str(Path(path).relative_to(root)),
            }
        )
    return columns


def select_rows(frame: pd.DataFrame, scenario: str, steering: bool, **where: Any) -> pd.DataFrame:
    """The rows of one scenario and steering condition (and `column=value` of `where`)."""
    mask = (frame["scenario"] == scenario) & (frame["steering"] == steering)
    for column, value in where.items():
        mask &= frame[column] == value
    return frame[mask]


def paper_baseline(frame: pd.DataFrame) -> str:
    """The model that stands for the paper's baseline in a table keyed like the layout:
    ADHERENT where it was rolled out, else the yaw-only variant."""
    return ADHERENT if (frame["model"] == ADHERENT).any() else BASELINE


def pi_models(frame: pd.DataFrame) -> dict[float, str]:
    """{pi_weight: model name} of the PI models (every model but the two baselines)."""
    rows = frame[~frame["model"].isin([BASELINE, ADHERENT])].drop_duplicates("model")
    return {float(w): str(m) for w, m in sorted(zip(rows["pi_weight"], rows["model"], strict=True))}


def weight_label(weight: float) -> str:
    return f"{weight:g}"
