"""The slow-start diagnostic (diagnostics.slow_start) on clips with a known start and on tiny
real models: the data coverage in closed form, the probe's swaps doing what they say."""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest
import torch
from builders import RATE, SMALL_MODEL, STANDING_JOINTS

from diagnostics.slow_start import (
    Row,
    clip_starts,
    first_input_response,
    first_seconds,
    main,
    mann_blocks,
    outcomes,
    rest_coverage,
    run_probe,
    source_start_summary,
    source_starts,
    start_row,
)
from pimann.core.params import load_params
from pimann.core.robot import load_robot
from pimann.core.trajectory import Trajectory, write_collection
from pimann.learn.adherent import build_adherent_dataset
from pimann.learn.adherent_train import train_adherent
from pimann.learn.dataset import write_dataset
from pimann.learn.features import build_dataset
from pimann.learn.mann import MANN
from pimann.learn.model_files import load_model, save_model

PARAMS = load_params()


def starting_clip(rest_s: float, speed: float, source: str, frames: int = 300, mirrored=False):
    """Standing still for `rest_s`, then walking straight ahead at `speed` (legs swinging,
    contacts alternating)."""
    t = np.arange(frames) / RATE
    moving = np.clip(t - rest_s, 0.0, None)
    position = np.zeros((frames, 3))
    position[:, 0], position[:, 2] = speed * moving, 0.77
    gait = np.where(t > rest_s, np.sin(2 * np.pi * 1.0 * moving), 0.0)
    contacts = np.stack([gait > -0.3, gait < 0.3], axis=1)
    return Trajectory(
        time=t,
        base_position=position,
        base_quaternion_xyzw=np.tile([0.0, 0.0, 0.0, 1.0], (frames, 1)),
        joint_positions=STANDING_JOINTS + 0.2 * gait[:, None],
        source=source,
        rate_hz=RATE,
        contacts=contacts,
        attrs={"mirrored": mirrored},
    )


def collection(speeds: dict[str, tuple[float, float]]) -> list[tuple[str, Trajectory]]:
    clips = []
    for name, (rest_s, speed) in speeds.items():
        for mirrored in (False, True):
            clip = starting_clip(rest_s, speed, name, mirrored=mirrored)
            clips.append((name + "_mirror" * mirrored, clip))
    return clips


STARTS = {f"rest{k}": (1.4, 0.4) for k in range(4)} | {f"moving{k}": (0.0, 0.5) for k in range(4)}


def test_clip_starts_find_the_starts_from_rest_and_their_speed(tmp_path):
    path = tmp_path / "walking.h5"
    write_collection(path, collection(STARTS))
    table = clip_starts(path, PARAMS).set_index("clip")
    assert len(table) >= 4 and not any(name.endswith("_mirror") for name in table.index)
    for name, row in table.iterrows():
        rest_s, speed = STARTS[name]
        assert row["from_rest"] == (rest_s > 0)
        # 2 cm from the start: rest_s + 0.02 / speed, to a frame
        assert row["rest_s"] == pytest.approx(rest_s + 0.02 / speed, abs=1.0 / RATE + 1e-9)
        assert row["speed_0_1s"] == pytest.approx(speed, abs=0.02)
        assert row["speed_1_2s"] == pytest.approx(speed, abs=1e-9)
        assert row["set_off_sampled"] == (rest_s >= 1.0)


def test_start_row_of_a_pelvis_standing_then_walking():
    """A start row from bare positions, as the mocap survey takes it: 1.4 s at rest, then
    0.4 m/s; a clip shorter than two seconds and the rest window is too short to tell."""
    t = np.arange(300) / RATE
    position = np.zeros((300, 3))
    position[:, 0] = 0.4 * np.clip(t - 1.4, 0.0, None)
    row = start_row(position, RATE)
    assert row["from_rest"] and row["set_off_sampled"]
    assert row["speed_1_2s"] == pytest.approx(0.4, abs=1e-9)
    assert start_row(position[: int(2 * RATE)], RATE) is None


def test_source_start_summary_counts_by_source_and_selection():
    starts = pd.DataFrame(
        [
            {"source": "a", "picked": True, "from_rest": True, "set_off_sampled": True,
             "speed_1_2s": 0.5, "start_speed": 0.0},
            {"source": "a", "picked": True, "from_rest": True, "set_off_sampled": True,
             "speed_1_2s": 0.1, "start_speed": 0.02},
            {"source": "a", "picked": False, "from_rest": True, "set_off_sampled": False,
             "speed_1_2s": 0.9, "start_speed": 0.05},
            {"source": "b", "picked": False, "from_rest": False, "set_off_sampled": False,
             "speed_1_2s": 1.0, "start_speed": 1.0},
        ]
    )  # fmt: skip
    table = source_start_summary(starts).set_index(["source", "picked"])
    assert table.loc[("a", True)][
        ["clips", "from_rest", "set_off_sampled", "walk_after"]
    ].tolist() == [2, 2, 2, 1]
    assert table.loc[("a", False)][
        ["clips", "from_rest", "set_off_sampled", "walk_after"]
    ].tolist() == [1, 1, 0, 0]
    assert table.loc[("b", False)]["from_rest"] == 0


def test_source_starts_read_every_take_and_mark_the_profiles_pick():
    """Bandai Namco's forward walks in the shared data, two of them picked: every take is read
    (max_takes ignored), the pick marked, and each starts already walking."""
    source = dataclasses.replace(
        PARAMS.data.sources["bandai_namco"],
        path="data/mocap/bandai-namco/dataset/*/data/dataset-1_walk_a*.bvh",
        max_takes=2,
    )
    data = dataclasses.replace(PARAMS.data, sources={"bandai_namco": source})
    starts = source_starts(data)
    assert len(starts) == 4 and starts["picked"].sum() == 2
    assert not starts["from_rest"].any() and (starts["start_speed"] > 0.3).all()


def test_rest_coverage_counts_the_rest_samples_by_the_speed_asked():
    """Starts from rest at 0.4 m/s only: at-rest samples ask for the slow band, never the
    fast one; the gait phase at rest is counted for every one of them."""
    dataset = build_dataset(collection(STARTS), PARAMS.features, "full")
    coverage = rest_coverage(dataset)
    rest_clips = {dataset.clips[k] for k in np.unique(dataset.train_origin[:, 0])}
    # the time-reversed copies walk backward into a stop: never at rest with a future ahead
    started = [c for c in rest_clips if c.startswith("rest") and "~reversed" not in c]
    assert started  # the split left some on the training side
    assert coverage["at_rest_slow_band"] >= len(started) and coverage["at_rest_fast_band"] == 0
    assert coverage["at_rest_slow_band_clips"] == len(started)
    phases = sum(v for k, v in coverage.items() if k.startswith("at_rest_phase_"))
    assert phases == coverage["at_rest"] >= coverage["at_rest_asked_over_0.1"] > 0


@pytest.fixture(scope="module")
def tiny_models(tmp_path_factory):
    """A tiny MANN on the full features' layout (gait phase included) and a tiny ADHERENT."""
    root = tmp_path_factory.mktemp("slow_start")
    clips = collection(STARTS)
    dataset = build_dataset(clips, PARAMS.features, "full")
    torch.manual_seed(0)
    model = MANN(dataset.layout.input_dim, dataset.layout.output_dim, SMALL_MODEL, seeds=[0])
    meta = {
        "pi_weight": 10.0,
        "seed": 0,
        "variant": "full",
        "standing": dataset.standing,
        "params": {"model": dataclasses.asdict(SMALL_MODEL)},
    }
    save_model(root / "w10" / "0", model, dataset.layout, dataset.stats, meta)
    features = dataclasses.replace(PARAMS.features, time_reversed=[])
    train = dataclasses.replace(PARAMS.train, epochs=1, batch_size=64, seeds=[0])
    small = dataclasses.replace(PARAMS, model=SMALL_MODEL, train=train, features=features)
    adherent = build_adherent_dataset(clips, features, load_robot())
    write_dataset(root / "adherent.h5", adherent)
    train_adherent(root / "adherent.h5", root / "adherent", [0], small)
    return root


def test_probe_swaps_a_block_for_its_first_steps_and_starts_at_the_phase_given(tiny_models, robot):
    probe = run_probe(tiny_models / "w10" / "0", PARAMS, 0.4, 0.8, 1.0, [0.2], robot)
    rows, n = probe.rows, round(RATE * 1.0)
    assert probe.position.shape == (n + 1, len(rows), 3) and probe.heights.shape[:2] == (
        n + 1,
        len(rows),
    )
    assert len(probe.inputs) == n and np.isnan(probe.predicted_vx[0]).all()
    # the authors' unsteered protocol: the first input carries no command (zero windows), so
    # the slow and fast runs' first inputs are one; the second carries each one's command
    assert np.array_equal(probe.inputs[0][0], probe.inputs[0][1])
    assert not np.array_equal(probe.inputs[1][0], probe.inputs[1][1])
    layout_names = [r.name for r in rows]
    swapped = layout_names.index("slow + fast's future window")
    assert rows[swapped] == Row("slow + fast's future window", 0.4, 1, "future window", 10)
    _, layout, _, _ = load_model(tiny_models / "w10" / "0")
    future = mann_blocks(layout.names("x"), layout.x_slices)["future window"]
    for step in range(10):  # taken from the fast run, then its own (the slow command)
        assert np.array_equal(probe.inputs[step][swapped, future], probe.inputs[step][1, future])
    assert not np.allclose(probe.inputs[10][swapped, future], probe.inputs[10][1, future])
    # the slow run's other gait phases at the start
    phase = layout.x_slices["gait_phase"]
    at_pi = layout_names.index("slow, start phase 1.0 pi")
    assert np.allclose(probe.inputs[0][at_pi, phase], [-1.0, 0.0])
    assert np.allclose(probe.inputs[0][0, phase], [1.0, 0.0])
    # the response at the first input that differs, moved to the slow and fast commands, is
    # the two runs' own prediction there
    response = first_input_response(probe, [0.4, 0.8])
    assert (response["step"] == 2).all()
    assert response["vx_net"].to_numpy() == pytest.approx(probe.predicted_vx[2, :2], abs=1e-6)
    swept = [r for r in rows if r.name.startswith("command ")]
    assert [r.speed for r in swept] == [0.2, 0.3, 0.5, 0.6, 0.7, 1.0] and not any(
        r.donor for r in swept
    )
    table = outcomes(probe, PARAMS.evaluate.walk_distance)
    assert list(table["row"]) == layout_names and table["walks"].dtype == bool
    assert table.loc[0, "distance"] == pytest.approx(
        probe.position[-1, 0, 0] - probe.position[0, 0, 0]
    )
    lifted = np.flatnonzero(probe.heights[:, 0].max(axis=1) > 0.02)
    expected = lifted[0] / RATE if len(lifted) else np.nan
    assert table.loc[0, "first_lift_s"] == pytest.approx(expected, nan_ok=True)
    series = first_seconds(probe)
    assert len(series) == 10 and series["t"].iloc[-1] == pytest.approx(1.0)
    assert np.isfinite(series.drop(columns=["slow_phase", "fast_phase"]).to_numpy()).all()


def test_probe_runs_adherent_through_its_own_generator(tiny_models, robot):
    probe = run_probe(tiny_models / "adherent" / "0", PARAMS, 0.4, 0.8, 0.6, [0.2], robot)
    names = [r.name for r in probe.rows]
    assert "slow + fast's gait phase" not in names and "slow + fast's past window" in names
    # its own generator: the first input already carries each run's command
    assert not np.array_equal(probe.inputs[0][0], probe.inputs[0][1])
    assert (first_input_response(probe, [0.4])["step"] == 1).all()
    assert np.isnan(probe.phase).all() and np.isfinite(probe.predicted_vx[1:]).all()
    assert first_seconds(probe)["slow_phase"].isna().all()  # no gait phase, none printed


def test_a_missing_model_gets_one_line(tmp_path, capsys):
    assert main(["--no-data", "--model", str(tmp_path / "missing")]) == 2
    error = capsys.readouterr().err
    assert error.startswith("slow_start: ") and "missing" in error and error.count("\n") == 1
