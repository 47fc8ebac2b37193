"""The command-following benchmark's scripts: each test clip of the features stage's split
(by source clip, mirrors included) as the commands of its own base motion, and a few training
clips' alike, so that a class failing on both splits is a motion the model cannot make and one
failing on the held-out split alone a take (a style) it does not generalise to.

The rollout stage rolls them out beside the named scenarios (`rollout.benchmark_clips`,
`rollout.benchmark_train_clips`); the evaluation measures each rollout against its script and
the clip's own level. Apart from the runner, so that the evaluation reads the clips without
depending on the generator.
"""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import numpy as np

from pimann.core.errors import PimannError
from pimann.core.params import Params
from pimann.core.paths import REPO_ROOT
from pimann.core.rollout_files import (
    HELD_OUT,
    TRAINING,
    Segment,
    clip_scenario,
    scenario_names,
    train_scenario,
)
from pimann.core.trajectory import Trajectory, iter_collection
from pimann.generate.command_script import clip_commands
from pimann.learn.features import split_sources
from pimann.learn.motion_classes import CLASSES, class_counts, majority_class, spread_pick


def _test_sources(collection: str | Path, params: Params) -> set[str]:
    """The features stage's test sources, in one pass over the collection (a clip at a time)."""
    trajectories = (t for _, t in iter_collection(collection))
    features = params.features
    try:
        return split_sources(trajectories, features.test_fraction, features.split_seed)
    except PimannError as error:  # a split problem: name the collection
        if error.path is not None:
            raise
        raise PimannError(collection, error.problem) from None


def held_out_clips(collection: str | Path, params: Params) -> list[tuple[str, Trajectory]]:
    """(name, trajectory) of the clips of a retargeted collection on the test side of the
    features stage's split (by source clip, mirrors included), in name order."""
    test = _test_sources(collection, params)
    return [(name, t) for name, t in iter_collection(collection) if t.source in test]


def _duration(trajectory: Trajectory) -> float:
    return (len(trajectory) - 1) / float(trajectory.rate_hz)


def training_clips(collection: str | Path, params: Params) -> list[tuple[str, Trajectory]]:
    """`rollout.benchmark_train_clips` training clips per motion class (each clip's
    `majority_class`), in class order: a seeded shuffle (`features.split_seed`) of the
    unmirrored ones (a mirror adds a rollout and no new take), picked of different sources and
    styles while there are. Only clips no longer than the longest script the stage runs anyway
    (named scenarios, test clips): a seed's scripts advance as one batch, so these add rollouts
    to it but no steps."""
    count = params.rollout.benchmark_train_clips
    if count == 0:
        return []
    test = _test_sources(collection, params)
    scenarios = params.rollout.scenarios
    longest = max(
        [sum(s.duration for s in scenarios.get(n, [])) for n in scenario_names(params.rollout)],
        default=0.0,
    )
    classes: dict[str, str] = {}
    groups: dict[str, str] = {}
    durations: dict[str, float] = {}
    for name, t in iter_collection(collection):
        if t.source in test:
            longest = max(longest, _duration(t))
        elif not t.attrs.get("mirrored", False):
            classes[name] = majority_class(class_counts(t))
            groups[name] = str(t.attrs.get("style") or "") or t.source
            durations[name] = _duration(t)
    classes = {n: c for n, c in classes.items() if durations[n] <= longest + 1e-9}
    names = sorted(classes)
    order = [
        names[k] for k in np.random.default_rng(params.features.split_seed).permutation(len(names))
    ]
    chosen: list[str] = []
    for name in CLASSES:
        chosen += spread_pick([n for n in order if classes[n] == name], groups, count)
    clips = dict(iter_collection(collection))
    return [(name, clips[name]) for name in chosen]


class BenchmarkClip(NamedTuple):
    split: str  # HELD_OUT or TRAINING
    name: str  # the clip's name in the collection
    scenario: str  # its script's scenario name
    trajectory: Trajectory


def benchmark_clips(collection: str | Path, params: Params) -> list[BenchmarkClip]:
    """The benchmark's clips: every test clip (HELD_OUT, clip_<name>), then the training clips
    of `training_clips` (TRAINING, train_<name>)."""
    clips = [
        BenchmarkClip(HELD_OUT, n, clip_scenario(n), t)
        for n, t in held_out_clips(collection, params)
    ]
    clips += [
        BenchmarkClip(TRAINING, n, train_scenario(n), t)
        for n, t in training_clips(collection, params)
    ]
    seen: set[str] = set()
    for clip in clips:
        if clip.scenario in seen:
            raise PimannError(collection, f"two benchmark clips are named {clip.scenario!r}")
        seen.add(clip.scenario)
    return clips


def benchmark_scripts(params: Params) -> dict[str, list[Segment]]:
    """{scenario: script} of the command-following benchmark (collection `features.input`):
    each clip of `benchmark_clips` as the commands of its own base motion
    (pimann.generate.command_script.clip_commands); the test clips with
    `rollout.benchmark_clips`."""
    rollout = params.rollout
    if not rollout.benchmark_clips and rollout.benchmark_train_clips == 0:
        return {}
    clips = benchmark_clips(REPO_ROOT / params.features.input, params)
    return {
        clip.scenario: clip_commands(clip.trajectory)
        for clip in clips
        if clip.split == TRAINING or rollout.benchmark_clips
    }
