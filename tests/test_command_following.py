"""Command following: scripts from clips, per-segment measures, summary, figure.

Synthetic trajectories are the standing ergoCub (real FK) moved rigidly as a command says
(`make_trajectory` of the data report's tests); the stepping check rolls the analytic gait
"network" of the generator's tests out through the real generator.
"""

from __future__ import annotations

import dataclasses
import math

import matplotlib
import numpy as np
import pandas as pd
import pytest
from builders import (
    CONTACT_PARAMS,
    EVALUATE_PARAMS,
    RATE,
    GaitModel,
    crafted_rows,  # noqa: F401
    make_trajectory,
    roll,
)
from matplotlib.backends.backend_agg import FigureCanvasAgg

from pimann.core.contacts import touchdowns
from pimann.core.params import MotionSegment, StandSegment, load_params
from pimann.evaluate import command_following_measures as cf
from pimann.evaluate.command_following_benchmark import summary_table
from pimann.evaluate.command_following_figure import fig_command_following
from pimann.evaluate.figure_style import style
from pimann.generate.command_script import clip_commands, segment_class

DT = 1.0 / RATE


def follow(script, heading=0.0, wobble=0.0, sway=0.0, speed_scale=1.0) -> tuple:
    """(xy (T, 2), yaw (T,)) of a base that does what `script` commands, step by step as the
    generator's frames run (frame 0 at rest), times `speed_scale`; `wobble` (m/s) and `sway`
    (m/s) add a 2 Hz forward and a 1 Hz lateral oscillation to walking, as a gait does."""
    ends = np.cumsum([s.duration for s in script])
    steps = round(ends[-1] * RATE)
    segment = np.minimum(np.searchsorted(ends, (np.arange(steps) + 0.5) * DT), len(script) - 1)
    commands = np.array(
        [
            [0.0, 0.0, 0.0] if isinstance(s, StandSegment) else [s.vx, s.vy, s.yaw_rate]
            for s in script
        ]
    )[segment]
    t = np.arange(steps) * DT
    moving = np.hypot(commands[:, 0], commands[:, 1]) > 0
    vx = speed_scale * commands[:, 0] + moving * wobble * np.sin(4 * np.pi * t)
    vy = speed_scale * commands[:, 1] + moving * sway * np.sin(2 * np.pi * t)
    yaw = heading + np.concatenate([[0.0], np.cumsum(commands[:, 2] * DT)])
    mid = (yaw[:-1] + yaw[1:]) / 2
    world = np.column_stack(
        [np.cos(mid) * vx - np.sin(mid) * vy, np.sin(mid) * vx + np.cos(mid) * vy]
    )
    xy = np.concatenate([[[0.0, 0.0]], np.cumsum(world * DT, axis=0)])
    return xy, yaw


SCRIPT = [
    StandSegment(3.0, True),
    MotionSegment(4.0, 0.8, 0.0, 0.0),
    MotionSegment(3.0, -0.6, 0.0, 0.0),
]


def assert_segments(found, expected, duration_tol=0.1, speed_tol=0.03, yaw_tol=0.03):
    assert [type(s) for s in found] == [type(s) for s in expected], found
    for got, want in zip(found, expected, strict=True):
        assert got.duration == pytest.approx(want.duration, abs=duration_tol), (got, want)
        if isinstance(want, MotionSegment):
            assert got.vx == pytest.approx(want.vx, abs=speed_tol), (got, want)
            assert got.vy == pytest.approx(want.vy, abs=speed_tol), (got, want)
            assert got.yaw_rate == pytest.approx(want.yaw_rate, abs=yaw_tol), (got, want)
    assert sum(s.duration for s in found) == pytest.approx(sum(s.duration for s in expected))


# ----------------------------------------------------------------------------- clip scripts


def test_clip_commands_recover_stand_forward_backward():
    trajectory = make_trajectory(*follow(SCRIPT, heading=0.7))
    found = clip_commands(trajectory)
    assert_segments(found, SCRIPT, duration_tol=0.03, speed_tol=0.005, yaw_tol=1e-6)
    assert [segment_class(s) for s in found] == ["standing", "forward", "backward"]


def test_clip_commands_of_a_swaying_gait_with_turns_and_side_steps():
    """A walk's wobble and sway (a stride-long window cancels them) cut no extra segment."""
    script = [
        StandSegment(2.0, True),
        MotionSegment(4.0, 0.9, 0.0, 0.0),
        MotionSegment(4.0, 0.9, 0.0, 0.3),
        MotionSegment(3.0, 0.0, 0.3, 0.0),
        MotionSegment(2.0, -0.5, 0.0, 0.0),
        MotionSegment(2.0, 0.0, 0.0, 0.5),
        StandSegment(2.0, True),
    ]
    trajectory = make_trajectory(*follow(script, heading=-1.0, wobble=0.1, sway=0.3))
    found = clip_commands(trajectory)
    assert_segments(found, script, duration_tol=0.1, speed_tol=0.03, yaw_tol=0.03)
    classes = [segment_class(s) for s in found]
    assert classes == [
        "standing",
        "forward",
        "turning",
        "side",
        "backward",
        "turning_in_place",
        "standing",
    ]


def test_clip_commands_keep_a_steady_walk_whole_and_feed_the_generator():
    script = [MotionSegment(6.0, 0.5, 0.1, 0.0)]
    found = clip_commands(make_trajectory(*follow(script, wobble=0.1, sway=0.2)))
    assert_segments(found, script, speed_tol=0.01)
    # the frames a rollout of the found script has are the clip's
    assert cf.segment_frames(found, RATE)[-1][1] == 300


def test_a_clip_follows_its_own_commands(robot):
    """The data's own score: a swaying clip measured against the script cut from it."""
    clip = make_trajectory(*follow(SCRIPT, heading=2.0, wobble=0.1, sway=0.3))
    script = clip_commands(clip)
    rows = cf.follow_measures(clip, script, robot, EVALUATE_PARAMS, CONTACT_PARAMS)
    assert [r["class"] for r in rows] == ["standing", "forward", "backward"]
    for row in rows[1:]:
        assert row["speed_ratio"] == pytest.approx(1.0, abs=0.05)
        assert row["heading_error_max_deg"] < 0.1


# ----------------------------------------------------------------------------- measures


@pytest.fixture(scope="module")
def exact_rows(robot):
    script = [*SCRIPT, MotionSegment(10.0, 0.6, 0.0, 0.3), StandSegment(5.0, True)]
    trajectory = make_trajectory(*follow(script, heading=0.3))
    return script, cf.follow_measures(trajectory, script, robot, EVALUATE_PARAMS, CONTACT_PARAMS)


def test_follow_measures_of_an_exact_follower(exact_rows):
    script, rows = exact_rows
    assert [r["class"] for r in rows] == ["standing", "forward", "backward", "turning", "standing"]
    for row, segment in zip(rows, script, strict=True):
        assert row["duration_s"] == pytest.approx(segment.duration)
        assert row["heading_error_max_deg"] == pytest.approx(0.0, abs=1e-6)
        # the rigid robot never lifts a foot, and its feet glide at the base's speed
        assert row["touchdowns_left"] == row["touchdowns_right"] == 0
        for drift in ("roll_drift_deg", "pitch_drift_deg", "foot_pitch_drift_deg"):
            assert row[drift] == pytest.approx(0.0, abs=1e-6)
    for row in rows[1:4]:
        assert row["speed_ratio"] == pytest.approx(1.0, abs=1e-6)
        assert row["alternates"] is False  # moving without a single step
        assert math.isnan(row["base_travel_m"])
    turning = rows[3]
    assert turning["settle_s"] == pytest.approx(2.0)  # 10 s command: the last 8 s count
    assert turning["yaw_rate_ratio"] == pytest.approx(1.0, abs=1e-6)
    assert (turning["vx"], turning["vy"]) == pytest.approx((0.6, 0.0), abs=1e-6)
    # sliding, position level: both feet down and gliding with the base
    assert rows[1]["sliding_linear_position"] > 0.8 * 500 / math.sqrt(3) * 0.9
    # velocity level: its base holds the lower foot, and the still joints carry the other
    # with it: a rigid glide or turn does not slide there
    for row in rows:
        assert row["sliding_linear"] == pytest.approx(0.0, abs=1e-9)
        assert row["sliding_angular"] == pytest.approx(0.0, abs=1e-9)
    for stand in (rows[0], rows[4]):
        assert stand["alternates"] is True
        assert stand["base_travel_m"] == pytest.approx(0.0, abs=1e-9)
        assert stand["base_travel_limit_m"] == pytest.approx(
            0.05 * (stand["duration_s"] - stand["settle_s"]) / 5.0
        )
        assert stand["foot_speed_max"] == pytest.approx(0.0, abs=1e-6)
    assert rows[4]["sliding_linear_position"] == pytest.approx(0.0, abs=1e-6)
    # the central differences at the stand's last frame see half the next step
    assert rows[0]["sliding_linear_position"] == pytest.approx(
        500 * 0.4 / math.sqrt(3) / 150, rel=1e-3
    )


def test_follow_measures_of_a_robot_that_stands_still(robot):
    script = [MotionSegment(10.0, 0.8, 0.0, 0.0)]
    still = make_trajectory(np.zeros((501, 2)), yaw=0.4)
    (row,) = cf.follow_measures(still, script, robot, EVALUATE_PARAMS, CONTACT_PARAMS)
    assert row["speed_ratio"] == pytest.approx(0.0, abs=1e-9)
    assert row["heading_error_max_deg"] == pytest.approx(0.0, abs=1e-9)
    assert row["alternates"] is False
    summary = cf.summarise_following(
        pd.DataFrame([{**row, "model": "m", "steering": False, "seed": 0}])
    )
    assert bool(summary.loc[0, "speed_pass"]) is False
    assert bool(summary.loc[0, "heading_pass"]) is True
    assert bool(summary.loc[0, "passes"]) is False


def test_follow_measures_of_a_slow_drifting_follower(robot):
    """70% of the commanded speed and a 0.05 rad/s unwanted turn: ratio 0.7, heading off."""
    script = [MotionSegment(10.0, 0.8, 0.0, 0.0)]
    xy, yaw = follow([MotionSegment(10.0, 0.8, 0.0, 0.05)], speed_scale=0.7)
    (row,) = cf.follow_measures(
        make_trajectory(xy, yaw=yaw), script, robot, EVALUATE_PARAMS, CONTACT_PARAMS
    )
    assert row["speed_ratio"] == pytest.approx(0.7, abs=1e-6)
    assert (row["vx"], row["vy"]) == pytest.approx((0.56, 0.0), abs=1e-6)  # heading frame
    assert row["yaw_rate"] == pytest.approx(0.05, abs=1e-9)
    assert row["heading_error_final_deg"] == pytest.approx(math.degrees(0.5), rel=1e-6)
    assert row["heading_error_max_deg"] == pytest.approx(math.degrees(0.5), rel=1e-6)


def test_follow_measures_reject_a_rollout_of_another_script(robot):
    from pimann.core.errors import PimannError

    with pytest.raises(PimannError, match="frames"):
        cf.follow_measures(
            make_trajectory(np.zeros((100, 2))), SCRIPT, robot, EVALUATE_PARAMS, CONTACT_PARAMS
        )


def test_drift_is_last_window_minus_first():
    values = np.concatenate([np.zeros(100), np.linspace(0, 1, 300), np.ones(100)])
    assert cf._window_drift(values, 100) == pytest.approx(math.degrees(1.0))
    assert math.isnan(cf._window_drift(np.full(10, np.nan), 3))


def test_touchdowns_and_alternation_on_synthetic_contacts():
    phase = np.arange(200) % 50  # 1 s gait: left down 0-29, right down 25-49 and 0-4
    contacts = np.column_stack([phase < 30, (phase >= 25) | (phase < 5)])
    counts = touchdowns(contacts)
    assert counts.tolist() == [3, 4]  # the left starts down; the right touches down each cycle
    assert cf.feet_alternate(counts, moving=True)
    assert not cf.feet_alternate([4, 1], moving=True)  # one foot steps, the other drags
    assert not cf.feet_alternate([0, 1], moving=True)  # a motion needs steps with both
    assert cf.feet_alternate([0, 0], moving=False)
    # shorter than two strides, one foot's touchdown may be all a walking gait shows (the
    # synthetic gait above: 1 s strides, its 0.8 s windows)
    assert cf.feet_alternate([0, 1], True, 2 * cf.STRIDE_S - 0.01)
    assert not cf.feet_alternate([0, 1], True, 2 * cf.STRIDE_S)
    assert not cf.feet_alternate([0, 0], True, 1.0)  # but it steps
    assert not cf.feet_alternate([2, 0], True, 1.0)
    shares = [touchdowns(contacts[k : k + 40]) for k in range(0, 160, 5)]
    assert all(cf.feet_alternate(c, True, 0.8) for c in shares)
    assert not all(min(c) >= 1 for c in shares)  # the stricter rule fails the gait itself
    assert touchdowns(np.ones((10, 2), bool)).tolist() == [0, 0]


def test_a_stepping_gait_alternates_and_stands(robot):
    """The generator's analytic gait: forward at 0.5 m/s then a stand, unsteered."""
    params = dataclasses.replace(load_params(), evaluate=EVALUATE_PARAMS)
    script = [StandSegment(1.0, True), MotionSegment(4.0, 0.5, 0.0, 0.0), StandSegment(3.0, True)]
    trajectory = roll(GaitModel(robot), script, params, False, robot).trajectory
    rows = cf.follow_measures(trajectory, script, robot, params.evaluate, params.contacts)
    walk = rows[1]
    assert walk["alternates"] is True
    assert min(walk["touchdowns_left"], walk["touchdowns_right"]) >= 3
    assert 0.6 < walk["speed_ratio"] < 1.4
    assert walk["heading_error_max_deg"] < 1.0
    for stand in (rows[0], rows[2]):
        assert stand["base_travel_m"] < stand["base_travel_limit_m"]
        assert stand["touchdowns_left"] + stand["touchdowns_right"] <= 1


# ----------------------------------------------------------------------------- summary


def test_summary_medians_and_criteria():
    summary = cf.summarise_following(crafted_rows())
    assert len(summary) == 2 * 2 * 3
    assert list(summary["class"].unique()) == ["forward", "turning_in_place", "standing"]
    key = summary.set_index(["model", "steering", "class"])
    good = key.loc[("w10", True, "forward")]
    assert (good["seeds"], good["segments"]) == (3, 6)
    assert good["speed_ratio"] == pytest.approx(0.79 / 0.8)
    assert good["heading_error_final_deg"] == pytest.approx(3.0)  # absolute values
    assert good["alternation_share"] == 1.0
    assert bool(good["passes"]) and pd.isna(good["stand_pass"])
    bad = key.loc[("baseline", False, "forward")]
    # seeds' means 0.41, 0.46, 0.51: the median seed's
    assert bad["achieved_speed"] == pytest.approx(0.46)
    assert bad["sliding_linear"] == pytest.approx(11.0)
    assert bad["sliding_linear_position"] == pytest.approx(7.0)
    line = next(r for r in summary_table(summary) if r.startswith("| baseline | nosteering | fo"))
    assert "| 11.0 / 7.0 (– / –) |" in line  # both levels; no data rows: no data levels
    assert bad["alternation_share"] == 0.0  # two seeds of three never alternate
    assert bad["pitch_drift_deg"] == pytest.approx(7.0)
    for criterion in ("speed_pass", "heading_pass", "alternation_pass", "drift_pass", "passes"):
        assert not bool(bad[criterion]), criterion
    turn = key.loc[("baseline", False, "turning_in_place")]
    assert bool(turn["speed_pass"]) and bool(turn["passes"])  # by the yaw rate: 0.9
    assert key.loc[("w10", True, "standing"), "base_travel_ratio"] == pytest.approx(0.5)
    assert bool(key.loc[("w10", True, "standing"), "stand_pass"])
    assert not bool(key.loc[("w10", False, "standing"), "stand_pass"])
    assert pd.isna(key.loc[("w10", False, "standing"), "speed_pass"])


def test_summary_needs_the_key_columns():
    from pimann.core.errors import PimannError

    with pytest.raises(PimannError, match="seed"):
        cf.summarise_following(crafted_rows().drop(columns="seed"))


def test_figure_of_commanded_and_achieved_speed(tmp_path):
    figures = load_params().figures
    summary = cf.summarise_following(crafted_rows())
    with matplotlib.rc_context(style(figures)):
        fig = fig_command_following(summary, figures)
        fig.savefig(tmp_path / "following.png")
    assert fig.get_size_inches()[0] == pytest.approx(figures.width_in)
    axes = fig.axes
    assert [ax.get_title() for ax in axes] == ["no steering", "steering"]
    assert [t.get_text() for t in axes[-1].get_xticklabels()] == ["forward"]
    legend = fig.legends[0]
    assert [t.get_text() for t in legend.get_texts()][:2] == ["baseline", "$w$=10"]
    # the legend sits above every panel, clear of the data, inside the figure
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    renderer = canvas.get_renderer()
    box = legend.get_window_extent(renderer)
    assert all(box.y0 >= ax.get_window_extent(renderer).y1 for ax in axes)
    assert box.x0 >= 0 and box.x1 <= fig.bbox.x1
    assert (tmp_path / "following.png").stat().st_size > 1000
    only_stand = summary[summary["class"] == "standing"]
    assert fig_command_following(only_stand, figures) is None
