"""The rollouts' layout (pimann.core.rollout_files) and runner (pimann.generate.rollouts):
paths, the table's model names, and that both sit apart from the evaluation (the layout also apart
from
the generator)."""

from __future__ import annotations

import ast
import dataclasses
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from builders import benchmark_collection, tiny_models, walking_clip

from pimann.core.errors import PimannError
from pimann.core.params import MotionSegment, ProtocolParams, StandSegment, load_params
from pimann.core.paths import REPO_ROOT
from pimann.core.rollout_files import (
    BASELINE,
    HELD_OUT,
    TRAINING,
    RolloutKey,
    clip_scenario,
    find_rollouts,
    parse_rollout_path,
    pi_models,
    read_script,
    rollout_columns,
    rollout_path,
    script_json,
    script_of_json,
    select_rows,
    weight_label,
)
from pimann.generate.benchmark_clips import benchmark_clips, benchmark_scripts
from pimann.generate.command_script import clip_commands
from pimann.generate.rollouts import models_record, rollout_scripts
from pimann.learn.model_files import model_seeds

PROTOCOL = ProtocolParams(
    script=[MotionSegment(0.6, 0.4, 0.0, 0.0)],
    unsteered={"command_blend_tau": 0.0, "start_history": "zero"},
    steered={"k1": 2.0, "goal_factor": 2.5, "command_blend_tau": None},
)

EVALUATION = (
    "pimann.evaluate.evaluation",
    "pimann.evaluate.claims",
    "pimann.evaluate.data_reference",
)


def test_rollout_paths_round_trip(tmp_path):
    key = RolloutKey("w10", 3, "turn-left", True)
    path = rollout_path(tmp_path, key)
    assert path == tmp_path / "w10" / "3" / "turn-left-steering.h5"
    assert parse_rollout_path(tmp_path, path) == key
    with pytest.raises(PimannError, match="not <model>"):
        parse_rollout_path(tmp_path, tmp_path / "w10" / "3" / "forward-maybe.h5")
    with pytest.raises(PimannError, match="holds no rollout"):
        find_rollouts(tmp_path)
    path.parent.mkdir(parents=True)
    path.touch()
    assert find_rollouts(tmp_path) == [(key, path)]


def test_table_models_and_rows():
    frame = pd.DataFrame(
        {
            "model": [BASELINE, "w10", "w1", "w10"],
            "pi_weight": [0.0, 10.0, 1.0, 10.0],
            "scenario": ["forward"] * 4,
            "steering": [False, False, False, True],
            "seed": [0] * 4,
        }
    )
    assert pi_models(frame) == {1.0: "w1", 10.0: "w10"}
    assert weight_label(10.0) == "10" and weight_label(0.5) == "0.5"
    assert list(select_rows(frame, "forward", False, model="w10").index) == [1]


def test_benchmark_scripts_of_the_test_clips_and_a_few_training_clips(tmp_path):
    params = load_params()
    collection = benchmark_collection(tmp_path / "walking.h5")
    params = dataclasses.replace(
        params,
        features=dataclasses.replace(params.features, input=str(collection), split_seed=0),
        rollout=dataclasses.replace(params.rollout, benchmark_train_clips=2),
    )
    scripts = benchmark_scripts(params)
    # a file stem: the space replaced; then the training clips by class (forward, standing)
    assert list(scripts) == ["clip_c", "clip_c_mirror", "train_d", "train_a", "train_b"]
    assert scripts["train_a"] == clip_commands(walking_clip(0.5, 300, "a"))
    assert [c.split for c in benchmark_clips(collection, params)] == [HELD_OUT] * 2 + [TRAINING] * 3
    # no training clip longer than the longest script run anyway (here the test clip's 2 s)
    brief = dataclasses.replace(
        params,
        rollout=dataclasses.replace(
            params.rollout,
            scenarios={"step": [MotionSegment(1.0, 0.5, 0.0, 0.0)]},
            scenario_names=["step"],
        ),
    )
    assert list(benchmark_scripts(brief)) == ["clip_c", "clip_c_mirror", "train_d", "train_b"]
    expected = clip_commands(walking_clip(0.4, 100, "c"))
    assert scripts["clip_c"] == scripts["clip_c_mirror"] == expected
    assert isinstance(expected[0], MotionSegment) and expected[0].vx == pytest.approx(0.4, abs=0.01)
    assert sum(s.duration for s in expected) == pytest.approx(99 / 50)
    key = RolloutKey("w10", 0, clip_scenario("dataset-1_walk-back x"), False)
    assert parse_rollout_path(tmp_path, rollout_path(tmp_path, key)) == key

    named = rollout_scripts(params)
    assert list(named) == [*params.rollout.scenario_names, *scripts]
    one = dataclasses.replace(
        params,
        rollout=dataclasses.replace(params.rollout, benchmark_clips=False, benchmark_train_clips=1),
    )
    assert list(rollout_scripts(one)) == [*params.rollout.scenario_names, "train_d", "train_b"]
    only = dataclasses.replace(
        params, rollout=dataclasses.replace(one.rollout, benchmark_train_clips=0)
    )
    assert list(rollout_scripts(only)) == params.rollout.scenario_names


def test_scripts_round_trip_through_json():
    script = [StandSegment(1.0, True), MotionSegment(2.5, 0.8, -0.1, 0.3)]
    text = script_json(script)
    assert '"stand": true' in text and script_of_json(text) == script
    with pytest.raises(PimannError, match="not a command script"):
        script_of_json('[{"duration": 1.0}]', "x.h5")
    trajectory = walking_clip(0.0, 10, "s")
    trajectory.attrs["scenario"] = "forward"
    assert read_script(trajectory, load_params()) == load_params().rollout.scenarios["forward"]
    with pytest.raises(PimannError, match="records no command script"):
        read_script(trajectory)
    trajectory.attrs["script"] = text
    assert read_script(trajectory) == script


GENERATION = (
    "torch",
    "pimann.generate.rollout_batch",
    "pimann.generate.batch_generator",
    "pimann.learn.train",
    "pimann.learn.model_files",
    "pimann.learn.mann",
)


@pytest.mark.parametrize(
    "module, forbidden",
    [
        ("pimann.generate.rollouts", EVALUATION),
        ("pimann.core.rollout_files", EVALUATION + GENERATION),
    ],
)
def test_the_layout_imports_neither_generation_nor_evaluation(module, forbidden):
    code = f"import sys, {module}; print(sorted(m for m in sys.modules if m in {forbidden!r}))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text())
    return {
        node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom) and node.module
    } | {a.name for node in ast.walk(tree) if isinstance(node, ast.Import) for a in node.names}


def test_rollout_users_import_the_layout_not_the_evaluation():
    users = [
        *sorted((REPO_ROOT / "pimann" / "sim").glob("*.py")),
        REPO_ROOT / "pimann" / "cli.py",
        REPO_ROOT / "stages" / "rollout.py",
        REPO_ROOT / "stages" / "simulate.py",
    ]
    for path in users:
        assert not _imports(path) & set(EVALUATION), path
    assert "pimann.core.rollout_files" in _imports(REPO_ROOT / "pimann" / "sim" / "run_list.py")
    assert "pimann.generate.rollouts" in _imports(REPO_ROOT / "stages" / "rollout.py")


def test_run_rollouts_batches_give_the_files_of_generate_file(tmp_path):
    """One batch per seed (scripts x steering): each file as `pimann generate` writes it."""

    from pimann.core.trajectory import read_trajectory
    from pimann.generate.rollout_batch import generate_file
    from pimann.generate.rollouts import run_rollouts

    params = load_params()
    params = dataclasses.replace(
        params,
        rollout=dataclasses.replace(
            params.rollout,
            scenarios={
                "short": [MotionSegment(0.6, 0.5, 0.0, 0.0)],
                "stop": [
                    MotionSegment(0.4, 0.4, 0.0, 0.2),
                    StandSegment(0.6, True),
                    MotionSegment(0.3, 0.3, 0.0, 0.0),
                ],
            },
            scenario_names=["short", "stop"],
            benchmark_clips=False,
            benchmark_train_clips=0,
            protocols={"proto": PROTOCOL},
        ),
    )
    tiny_models(tmp_path / "models" / "w10", 10.0, "full", [0, 1])
    written = run_rollouts(tmp_path / "models" / "w10", tmp_path / "w10", params, workers=1)
    assert len(written) == 2 * 3 * 2 and (tmp_path / "w10" / "models.json").is_file()
    keys = [RolloutKey("w10", 1, "stop", True), RolloutKey("w10", 0, "short", False)]
    keys += [RolloutKey("w10", 0, "proto", steering) for steering in (False, True)]
    for key in keys:
        batched = read_trajectory(rollout_path(tmp_path, key))
        alone = generate_file(
            tmp_path / "models" / "w10" / str(key.seed),
            key.scenario,
            tmp_path / "alone.h5",
            key.steering,
            params,
        )
        alone = read_trajectory(tmp_path / "alone.h5")
        assert batched.attrs == alone.attrs and batched.source == alone.source
        scripts = {**params.rollout.scenarios, "proto": PROTOCOL.script}
        assert read_script(batched) == scripts[key.scenario]
        assert len(batched) == len(alone) == {"short": 31, "stop": 66, "proto": 31}[key.scenario]
        assert batched.attrs.get("protocol") == ("proto" if key.scenario == "proto" else None)
        for name in ("base_position", "joint_positions", "joint_velocities"):
            np.testing.assert_allclose(getattr(batched, name), getattr(alone, name), atol=1e-5)
        np.testing.assert_array_equal(batched.contacts, alone.contacts)


def test_a_protocol_runs_with_the_rollout_keys_it_sets(tmp_path):
    """The protocol's unsteered way overwrites the future window with the command (tau 0) and
    starts from zero velocity windows: not the plain unsteered rollout of the same script."""
    from pimann.generate.rollout_batch import generate_file

    params = load_params()
    params = dataclasses.replace(
        params,
        rollout=dataclasses.replace(
            params.rollout,
            scenarios={**params.rollout.scenarios, "plain": PROTOCOL.script},
            protocols={"proto": PROTOCOL},
        ),
    )
    tiny_models(tmp_path / "models", 10.0, "full", [0])
    unsteered = params.rollout.for_protocol("proto", False)
    assert unsteered.command_blend_tau == 0.0 and unsteered.start_history == "zero"
    assert params.rollout.for_protocol("proto", True).k1 == 2.0
    runs = {
        name: generate_file(tmp_path / "models" / "0", name, tmp_path / f"{name}.h5", False, params)
        for name in ("plain", "proto")
    }
    assert runs["proto"].attrs["protocol"] == "proto" and "protocol" not in runs["plain"].attrs
    gap = np.abs(runs["proto"].joint_positions - runs["plain"].joint_positions).max()
    assert gap > 1e-4  # the tiny model barely walks; the same keys set by hand give the same:
    by_hand = dataclasses.replace(params, rollout=dataclasses.replace(unsteered, protocols={}))
    same = generate_file(tmp_path / "models" / "0", "plain", tmp_path / "h.h5", False, by_hand)
    np.testing.assert_array_equal(same.joint_positions, runs["proto"].joint_positions)


@pytest.mark.parametrize(
    "meta, message",
    [
        ("{pi_weight", "not a model's metadata"),
        ("[1]", "not a model's metadata"),
        ('{"seed": 0, "variant": "full"}', "metadata lacks 'pi_weight'"),
    ],
)
def test_a_broken_meta_or_record_is_named(tmp_path, meta, message):
    """The rollout stage's record of the models, and evaluate's reading of it."""
    folder = tmp_path / "w10" / "0"
    folder.mkdir(parents=True)
    (folder / "meta.json").write_text(meta)
    with pytest.raises(PimannError, match=message) as raised:
        models_record(tmp_path / "w10")
    assert raised.value.path == str(folder / "meta.json")
    (tmp_path / "w10" / "models.json").write_text(meta)
    key = RolloutKey("w10", 0, "forward", True)
    with pytest.raises(PimannError, match="not a rollout record") as raised:
        rollout_columns(tmp_path, [(key, rollout_path(tmp_path, key))])
    assert raised.value.path == str(tmp_path / "w10" / "models.json")
    (tmp_path / "w10" / "best").mkdir()
    (tmp_path / "w10" / "best" / "meta.json").write_text("{}")
    with pytest.raises(PimannError, match="not a seed") as raised:
        model_seeds(tmp_path / "w10")
    assert raised.value.path == str(tmp_path / "w10" / "best")
