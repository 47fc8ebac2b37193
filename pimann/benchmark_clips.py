"""The command-following benchmark's scripts: each test clip of the features stage's split
(by source clip, mirrors included) as the commands of its own base motion.

The rollout stage rolls them out beside the named scenarios (`rollout.benchmark_clips`); the
evaluation measures each rollout against its script and the clip's own level. Apart from the
runner, so that the evaluation reads the test clips without depending on the generator.
"""

from __future__ import annotations

from pathlib import Path

from pimann.clip_commands import clip_commands
from pimann.errors import PimannError
from pimann.features import split_sources
from pimann.params import Params
from pimann.paths import REPO_ROOT
from pimann.rollout_layout import Segment, clip_scenario
from pimann.trajectory import Trajectory, iter_collection


def held_out_clips(collection: str | Path, params: Params) -> list[tuple[str, Trajectory]]:
    """(name, trajectory) of the clips of a retargeted collection on the test side of the
    features stage's split (by source clip, mirrors included), in name order."""
    sources = [t.source for _, t in iter_collection(collection)]  # a pass for the names only
    if len(set(sources)) < 2:
        raise PimannError(collection, "needs at least 2 source clips for the test split")
    test = split_sources(sources, params.features.test_fraction, params.features.split_seed)
    return [(name, t) for name, t in iter_collection(collection) if t.source in test]


def benchmark_scripts(params: Params) -> dict[str, list[Segment]]:
    """{clip_<clip name>: script} of the command-following benchmark: each test clip of the
    features stage's split (collection `features.input`) as the commands of its own base
    motion (pimann.clip_commands.clip_commands)."""
    scripts: dict[str, list[Segment]] = {}
    for name, trajectory in held_out_clips(REPO_ROOT / params.features.input, params):
        scenario = clip_scenario(name)
        if scenario in scripts:
            raise PimannError(params.features.input, f"two test clips are named {scenario!r}")
        scripts[scenario] = clip_commands(trajectory)
    return scripts
