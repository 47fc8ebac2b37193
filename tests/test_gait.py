"""The gait measures (pimann.evaluate.gait) on sole trajectories of a known step schedule, on
the robot slid along the floor, and on a real retargeted walk against another count."""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest
from builders import CONTACT_PARAMS, EVALUATE_PARAMS, make_trajectory

from pimann.core.contacts import contacts_from_heights, touchdowns
from pimann.core.params import MotionSegment, StandSegment
from pimann.core.rollout_files import script_json
from pimann.evaluate.gait import (
    command_following,
    command_frames,
    data_gait_columns,
    gait_level,
    last_window,
    swings,
    window_gait,
    with_data_gait,
)
from pimann.evaluate.metrics import trajectory_metrics
from pimann.generate.command_script import scenario_steps

RATE = 50.0
FRAMES = 501  # 10 s
STEP_FRAMES = 40  # a touchdown every 0.8 s: 1.25 swings a second
STEP = 0.32  # m: 0.32 m x 1.25 steps/s = 0.4 m/s
SWING_FRAMES = 21
APEX = 0.08


def scheduled_walk(glide: tuple[int, int] | None = None):
    """Soles of a walk at 0.4 m/s from standing: the left foot lifts at frame 20, the feet
    alternate every `STEP_FRAMES`, each swing rises, carries the foot, and lands; the first
    step is half a stride. `glide`: (first frame, frames) the right foot slides at 0.3 m/s on
    the floor (in a stance). Returns time, heights (T, 2), positions (T, 2, 3), base_xy."""
    time = np.arange(FRAMES) / RATE
    positions = np.zeros((FRAMES, 2, 3))
    positions[:, 0, 1], positions[:, 1, 1] = 0.1, -0.1
    x = np.zeros(2)
    s = (np.arange(SWING_FRAMES) + 1) / (SWING_FRAMES + 1)
    height = APEX * np.sin(np.pi * s)
    carried = np.clip((s - 0.25) / 0.5, 0.0, 1.0)  # forward only while high
    for k, start in enumerate(range(20, FRAMES - SWING_FRAMES, STEP_FRAMES)):
        foot = k % 2
        stride = STEP if k == 0 else 2 * STEP
        frames = slice(start, start + SWING_FRAMES)
        positions[frames, foot, 2] = height
        positions[frames, foot, 0] = x[foot] + stride * carried
        x[foot] += stride
        positions[start + SWING_FRAMES :, foot, 0] = x[foot]
    if glide is not None:
        first, count = glide
        slide = 0.3 / RATE * np.arange(1, count + 1)
        positions[first + 1 : first + count + 1, 1, 0] += slide
        positions[first + count + 1 :, 1, 0] += slide[-1]
    base_xy = np.column_stack([0.4 * time, np.zeros(FRAMES)])
    return time, positions[..., 2].copy(), positions, base_xy


def _speeds(time, positions):
    return np.linalg.norm(np.gradient(positions[..., :2], time, axis=0), axis=-1)


def _gait(time, heights, positions, base_xy, pitches=None):
    contacts = contacts_from_heights(heights, 1 / RATE, CONTACT_PARAMS)
    pitches = np.zeros_like(heights) if pitches is None else pitches
    window = last_window(time, EVALUATE_PARAMS.gait_window_s)
    speeds = _speeds(time, positions)
    args = (time, contacts, heights, positions, pitches, speeds, base_xy, window, EVALUATE_PARAMS)
    return window_gait(*args), contacts, window


def test_a_known_schedule_gives_its_cadence_step_and_apex():
    time, heights, positions, base_xy = scheduled_walk()
    gait, contacts, window = _gait(time, heights, positions, base_xy)
    assert window == (100, FRAMES) and gait["window_s"] == pytest.approx(8.0)
    # touchdowns every 40 frames: 10 in the last 400 frames
    assert gait["swings"] == 10
    assert gait["cadence"] == pytest.approx(1.25)
    assert gait["step_length"] == pytest.approx(STEP)
    assert gait["step_length"] * gait["cadence"] == pytest.approx(0.4)
    assert gait["swing_apex"] == pytest.approx(APEX)
    assert gait["glide_share"] == 0.0  # the foot moves only once above the glide height
    assert gait["standing_share"] == 0.0
    # every swing has a lift-off and a touchdown inside; the first step is half a stride
    assert len(swings(contacts)) == len(range(20, FRAMES - SWING_FRAMES, STEP_FRAMES))


def test_the_first_half_step_and_a_pause_enter_over_a_whole_trajectory():
    time, heights, positions, base_xy = scheduled_walk()
    contacts = contacts_from_heights(heights, 1 / RATE, CONTACT_PARAMS)
    speeds = _speeds(time, positions)
    pitches = np.zeros_like(heights)
    # the first 1.6 s: one full step and the half step that started from standing
    gait = window_gait(
        time, contacts, heights, positions, pitches, speeds, base_xy, (0, 81), EVALUATE_PARAMS
    )
    assert gait["swings"] == 1  # the left foot's start step; the right lands at frame 82
    assert gait["step_length"] == pytest.approx(STEP / 2)  # from standing: half a step
    still = np.zeros_like(base_xy)
    standing = window_gait(
        time, contacts, heights, positions, pitches, speeds, still, (0, 20), EVALUATE_PARAMS
    )
    assert standing["standing_share"] == 1.0 and standing["cadence"] == 0.0
    assert standing["step_length"] is None and standing["swing_apex"] is None


def test_a_foot_sliding_on_the_floor_glides_for_its_frames():
    # the right foot stands from frame 82 to 141 (its next swing: 140-160); slide it 10 frames
    time, heights, positions, base_xy = scheduled_walk(glide=(110, 10))
    gait, _, (start, stop) = _gait(time, heights, positions, base_xy)
    # central differences: the 9 inner frames move at 0.3 m/s, the two ends at 0.15 (< 0.2)
    assert gait["glide_share"] == pytest.approx(9 / (stop - start))
    assert gait["cadence"] == pytest.approx(1.25)


def test_contact_pitch_counts_the_soles_in_contact_only():
    time, heights, positions, base_xy = scheduled_walk()
    contacts = contacts_from_heights(heights, 1 / RATE, CONTACT_PARAMS)
    pitches = np.where(contacts, 0.2, 0.6)
    gait, _, _ = _gait(time, heights, positions, base_xy, pitches)
    assert gait["contact_sole_pitch"] == pytest.approx(0.2)


def test_command_frames_follow_the_generators_steps():
    script = [MotionSegment(duration=4.0, vx=0.4, vy=0.0, yaw_rate=0.0), StandSegment(6.0, True)]
    time = np.arange(FRAMES) / RATE
    command = command_frames(script, time)
    steps = scenario_steps(script, RATE)  # step k (frame k + 1) runs segment steps[k]
    expected = np.where(steps == 0, 0.4, 0.0)
    assert np.array_equal(command[1:, 0], expected)
    assert command[0, 0] == 0.4 and np.all(command[:, 1:] == 0.0)


def test_travel_is_along_the_command_in_the_robots_heading():
    time = np.arange(FRAMES) / RATE
    yaw = 0.2 * time  # the robot turns, the command does not
    velocity = 0.5 * np.column_stack([np.cos(yaw), np.sin(yaw)])  # forward in its own heading
    base_xy = np.concatenate([[[0.0, 0.0]], np.cumsum(velocity[:-1] / RATE, axis=0)])
    command = command_frames([MotionSegment(duration=10.0, vx=0.4, vy=0.0, yaw_rate=0.0)], time)
    window = last_window(time, 8.0)
    result = command_following(time, base_xy, yaw, command, window)
    assert result["command_speed"] == pytest.approx(0.4)
    assert result["speed"] == pytest.approx(0.5, rel=1e-3)
    assert result["speed_ratio"] == pytest.approx(1.25, rel=1e-3)
    assert result["heading_change"] == pytest.approx(1.6)
    assert result["heading_error_max_abs"] == pytest.approx(1.6)
    sideways = command_frames([MotionSegment(duration=10.0, vx=0.0, vy=0.4, yaw_rate=0.0)], time)
    assert command_following(time, base_xy, yaw, sideways, window)["travel"] == pytest.approx(
        0.0, abs=1e-3
    )


def test_the_robot_slid_along_the_floor_glides_without_a_step(robot):
    time = np.arange(FRAMES) / RATE
    xy = np.column_stack([0.4 * time, np.zeros(FRAMES)])
    script = [MotionSegment(duration=10.0, vx=0.4, vy=0.0, yaw_rate=0.0)]
    trajectory = make_trajectory(xy, script=script_json(script))
    metrics = trajectory_metrics(trajectory, robot, EVALUATE_PARAMS, CONTACT_PARAMS)
    assert metrics["gait_swings"] == 0 and metrics["gait_cadence"] == 0.0
    assert metrics["gait_step_length"] is None
    assert metrics["gait_glide_share"] == pytest.approx(1.0)
    assert metrics["gait_standing_share"] == 0.0
    assert metrics["gait_speed_ratio"] == pytest.approx(1.0, rel=1e-6)
    assert metrics["gait_command_forward"] is True
    assert metrics["gait_heading_change"] == pytest.approx(0.0, abs=1e-9)
    no_script = trajectory_metrics(make_trajectory(xy), robot, EVALUATE_PARAMS, CONTACT_PARAMS)
    assert no_script["gait_speed"] is None and no_script["gait_glide_share"] == 1.0
    assert no_script["gait_heading_change"] == pytest.approx(0.0, abs=1e-9)


def test_a_real_walk_steps_as_its_own_contacts_count(robot, real_walks):
    """The retargeted person's own contact flags (from the mocap, not the sole heights) land
    as often as the lowest-corner rule's swings; cadence, step and speed agree."""
    walk = real_walks["walk"]
    metrics = trajectory_metrics(walk, robot, EVALUATE_PARAMS, CONTACT_PARAMS)
    time = np.asarray(walk.time)
    start, stop = last_window(time, EVALUATE_PARAMS.gait_window_s)
    own = int(touchdowns(np.asarray(walk.contacts, dtype=bool)[start:stop]).sum())
    assert own >= 4
    assert abs(metrics["gait_swings"] - own) <= 1
    assert 1.0 < metrics["gait_cadence"] < 2.2
    assert 0.15 < metrics["gait_step_length"] < 0.8
    assert 0.04 < metrics["gait_swing_apex"] < 0.2
    assert metrics["gait_glide_share"] < 0.02
    shift = np.asarray(walk.base_position)[stop - 1, :2] - np.asarray(walk.base_position)[start, :2]
    speed = np.linalg.norm(shift) / (time[stop - 1] - time[start])
    assert metrics["gait_step_length"] * metrics["gait_cadence"] == pytest.approx(speed, rel=0.2)


WINDOWS = [
    {"speed": s, "cadence": c, "step_length": s / c}
    for s, c in ((0.3, 1.2), (0.35, 1.4), (0.45, 1.6), (0.8, 1.8))
]


def test_the_datas_level_is_the_windows_near_the_speed():
    level = gait_level(WINDOWS, 0.4, 0.1)
    assert level["cadence"] == {"n": 3, "median": 1.4, "min": 1.2, "max": 1.6}
    assert level["swing_apex"]["n"] == 0 and level["swing_apex"]["median"] is None
    assert gait_level(WINDOWS, 0.8, 0.1)["cadence"]["median"] == 1.8
    rows = [
        {"gait_command_speed": 0.4, "gait_command_forward": True},
        {"gait_command_speed": 0.4, "gait_command_forward": False},  # e.g. walking backward
        {"gait_command_speed": None, "gait_command_forward": None},  # no script
        {"gait_command_speed": 2.0, "gait_command_forward": np.True_},
    ]
    columns = data_gait_columns(rows, WINDOWS, 0.1)
    assert columns[0]["data_gait_cadence"] == 1.4 and columns[0]["data_gait_windows"] == 3
    assert math.isclose(columns[0]["data_gait_step_length"], 0.35 / 1.4)
    assert columns[1]["data_gait_cadence"] is None and columns[2]["data_gait_windows"] == 0
    assert columns[3]["data_gait_windows"] == 0 and columns[3]["data_gait_cadence"] is None


# the data's windows by speed (m/s): none within 1e-6 of a band's edge around the speeds below
BY_SPEED = [
    {"speed": s, "cadence": c, "step_length": length}
    for s, c, length in (
        (0.22, 1.0, 0.20),
        (0.32, 1.1, 0.26),
        (0.36, 1.2, 0.30),
        (0.45, 1.4, 0.34),
        (0.48, 1.5, 0.36),
        (0.8, 1.8, 0.45),
    )
]


def _near(speed: float, band: float = 0.1) -> dict[str, tuple[float, float, float]]:
    """(median, min, max) of the cadence and step length of `BY_SPEED` within `band` of speed."""
    near = [w for w in BY_SPEED if abs(w["speed"] - speed) <= band]
    return {
        name: (
            float(np.median([w[name] for w in near])),
            min(w[name] for w in near),
            max(w[name] for w in near),
        )
        for name in ("cadence", "step_length")
    }


def _at_speed(columns: dict, name: str) -> tuple:
    return tuple(columns[f"data_gait_{name}_at_speed_{s}"] for s in ("median", "low", "high"))


def test_a_rollout_slower_than_commanded_is_judged_at_the_speed_it_achieved():
    # the scheduled walk (0.32 m x 1.25 steps/s = 0.4 m/s) under a 0.5 m/s command
    time, heights, positions, base_xy = scheduled_walk()
    gait, _, window = _gait(time, heights, positions, base_xy)
    command = command_frames([MotionSegment(duration=10.0, vx=0.5, vy=0.0, yaw_rate=0.0)], time)
    following = command_following(time, base_xy, np.zeros(FRAMES), command, window)
    row = {f"gait_{k}": v for k, v in {**gait, **following}.items()}
    row["gait_command_forward"] = True
    assert row["gait_speed"] == pytest.approx(0.4) and row["gait_command_speed"] == 0.5
    (columns,) = data_gait_columns([row], BY_SPEED, 0.1)
    commanded, achieved = _near(0.5), _near(0.4)
    assert columns["data_gait_cadence"] == pytest.approx(commanded["cadence"][0])  # 1.45
    assert _at_speed(columns, "cadence") == pytest.approx(achieved["cadence"])  # 1.3 [1.1, 1.5]
    assert _at_speed(columns, "step_length") == pytest.approx(achieved["step_length"])
    assert columns["data_gait_windows_at_speed"] == 4
    # 1.25 swings/s of 0.32 m: inside [1.1, 1.5] and [0.26, 0.36]
    assert columns["gait_in_data_range"] is True
    short = {**row, "gait_step_length": 0.2}  # the same cadence, short steps: out
    fast = {**row, "gait_cadence": 1.6}
    no_step = {**row, "gait_step_length": None, "gait_cadence": 0.0}
    judged = data_gait_columns([short, fast, no_step], BY_SPEED, 0.1)
    assert [c["gait_in_data_range"] for c in judged] == [False, False, False]
    assert all(_at_speed(c, "cadence") == _at_speed(columns, "cadence") for c in judged)


def test_the_datas_range_is_not_judged_standing_backward_or_away_from_its_windows():
    row = {"gait_command_forward": True, "gait_command_speed": 0.4, "gait_cadence": 1.0}
    rows = [
        {**row, "gait_speed": 0.05, "gait_step_length": 0.05},  # barely moves
        {**row, "gait_speed": 1.2, "gait_step_length": 0.6},  # no window near 1.2 m/s
        {**row, "gait_command_forward": False, "gait_speed": 0.4, "gait_step_length": 0.4},
        {**row, "gait_speed": math.nan, "gait_step_length": 0.3},  # as pandas gives None back
    ]
    for columns in data_gait_columns(rows, BY_SPEED, 0.1):
        assert columns["gait_in_data_range"] is None
        assert columns["data_gait_cadence_at_speed_median"] is None
        assert columns["data_gait_windows_at_speed"] == 0


def test_the_robot_slid_slower_than_commanded_gets_the_datas_level_at_its_speed(robot):
    time = np.arange(FRAMES) / RATE
    xy = np.column_stack([0.3 * time, np.zeros(FRAMES)])  # 0.3 m/s under a 0.4 m/s command
    script = [MotionSegment(duration=10.0, vx=0.4, vy=0.0, yaw_rate=0.0)]
    trajectory = make_trajectory(xy, script=script_json(script))
    metrics = trajectory_metrics(trajectory, robot, EVALUATE_PARAMS, CONTACT_PARAMS)
    table = {k: [w[k] for w in BY_SPEED] for k in BY_SPEED[0]}
    frame = with_data_gait(pd.DataFrame([metrics]), {"gait": {"per_window": table}}, 0.1)
    row = frame.iloc[0]
    assert row["gait_speed"] == pytest.approx(0.3, rel=1e-6)
    assert row["data_gait_cadence"] == pytest.approx(_near(0.4)["cadence"][0])
    achieved = _near(0.3)  # the windows at 0.22, 0.32 and 0.36 m/s
    assert _at_speed(row, "cadence") == pytest.approx(achieved["cadence"])  # 1.1 [1.0, 1.2]
    assert _at_speed(row, "step_length") == pytest.approx(achieved["step_length"])
    assert row["data_gait_windows_at_speed"] == 3
    judged = row["gait_in_data_range"]
    assert pd.notna(judged) and not judged  # a glide without a step is not the data's gait


def test_the_key_numbers_and_the_page_carry_the_gait_and_the_datas_level(tmp_path):
    from builders import AGREEING, REFERENCE, SCENARIO, WEIGHTS, crafted_metrics

    from pimann.core.params import load_params
    from pimann.core.rollout_files import STEERING_LABEL
    from pimann.evaluate.evaluation import provenance, write_results
    from pimann.report.key_metrics import MAX_VALUES, key_metrics
    from pimann.report.page import build_report

    params = load_params()
    cadence = {model: 1.0 + 0.1 * k for k, model in enumerate(WEIGHTS)}
    values = {
        **AGREEING,
        "gait_cadence": cadence,
        "gait_step_length": dict.fromkeys(WEIGHTS, 0.18),
        "data_gait_cadence": dict.fromkeys(WEIGHTS, 1.39),
        "data_gait_step_length": dict.fromkeys(WEIGHTS, 0.284),
    }
    frame = crafted_metrics(values)
    # w10's unsteered seeds 0-4: not judged, in, in, out, in; every other row in
    judged = {0: None, 1: True, 2: True, 3: False, 4: True}
    frame["gait_in_data_range"] = [
        judged[row.seed] if row.model == "w10" and not row.steering else True
        for row in frame.itertuples()
    ]
    root = tmp_path / "results"
    write_results(frame, root, params, provenance(params), {}, REFERENCE)
    metrics = key_metrics(root, params)
    assert metrics[f"{SCENARIO}.w10.gait_in_data_range"] == pytest.approx(0.75)
    assert metrics[f"{SCENARIO}.w1.gait_in_data_range"] == 1.0
    summary = json.loads((root / "metrics_summary.json").read_text())["summary"]
    seeds = summary[SCENARIO][STEERING_LABEL[False]]["w10"]["metrics"]["gait_in_data_range"]
    assert seeds["n"] == 4 and seeds["mean"] == pytest.approx(0.75)
    assert len(metrics) <= MAX_VALUES
    assert metrics[f"{SCENARIO}.w10.gait_cadence"] == pytest.approx(cadence["w10"])
    assert metrics[f"{SCENARIO}.w10.gait_glide_share"] is None  # not in this metrics.csv
    assert metrics["data.gait_cadence"] == pytest.approx(1.39 * 1.0)  # the median seed's
    assert metrics["data.gait_step_length"] == pytest.approx(0.284)
    page = build_report(root, tmp_path / "figures", params, metrics)
    gait = page[page.index("The gait over the last seconds") :]
    assert "data at the commanded speed</td><td>–</td><td>1.39</td><td>0.284</td>" in gait
    assert "<th>glide share</th><th>in data range</th>" in gait
    w10 = gait[gait.index("<td>w10</td>") :]
    assert w10.split("</tr>")[0].endswith("<td>0.75</td>")


def test_the_datas_windows_come_from_its_stepping_originals(real_walks, tmp_path):
    from pimann.core.params import load_params
    from pimann.core.trajectory import write_collection
    from pimann.evaluate.data_reference import data_reference
    from pimann.evaluate.gait import DATA_WINDOW_S, windows_of

    params = load_params()
    path = tmp_path / "walking.h5"
    walk, mirror = real_walks["walk"], real_walks["walk_mirrored"]
    assert mirror.attrs.get("mirrored")
    write_collection(path, [("walk", walk), ("walk_mirrored", mirror)])
    both = data_reference(path, params, workers=1)["gait"]
    write_collection(path, [("walk", walk)])
    alone = data_reference(path, params, workers=1)["gait"]
    assert both["windows"] == alone["windows"] >= 2  # the mirror is not counted again
    windows = windows_of(both)
    assert all(w["window_s"] >= DATA_WINDOW_S - 1e-9 for w in windows)
    for w in windows:  # both ends on touchdowns: step x cadence is the window's speed
        assert 1.2 < w["cadence"] < 2.2 and w["glide_share"] == 0.0
        assert w["step_length"] * w["cadence"] == pytest.approx(w["speed"], rel=0.2)
    speed = f"{round(float(np.median([w['speed'] for w in windows])), 1):.1f}"
    assert both["by_speed"][speed]["cadence"]["n"] >= 1
