"""The gait-by-speed diagnostic (diagnostics.gait_by_speed): the data's level at the speed a
rollout achieved and the inside flags on crafted windows, the trend's slopes in closed form,
and a stepping gait whose stride follows the command, rolled out and printed."""

from __future__ import annotations

import json

import numpy as np
import pytest
from builders import IDENTITY, LAYOUT, GaitModel

import diagnostics.gait_by_speed as gait_by_speed
from diagnostics.gait_by_speed import gait_of, gait_table, judged, main, roll_out, trend
from pimann.core.params import load_params

PARAMS = load_params()
BAND = 0.1


def window(speed: float, cadence: float, step: float) -> dict:
    return {"speed": speed, "cadence": cadence, "step_length": step, "window_s": 2.0}


def gait(speed: float, cadence: float, step: float | None, forward: bool = True) -> dict:
    return {
        "gait_speed": speed,
        "gait_cadence": cadence,
        "gait_step_length": step,
        "gait_swing_apex": 0.1,
        "gait_glide_share": 0.2,
        "gait_command_forward": forward,
    }


# three windows near 0.5 m/s (within the band), one near 0.9 and one at 0.62 just outside
WINDOWS = [
    window(0.45, 1.4, 0.25),
    window(0.50, 1.6, 0.30),
    window(0.55, 1.5, 0.35),
    window(0.62, 9.0, 9.0),
    window(0.90, 1.9, 0.45),
]


def test_judged_takes_the_data_level_at_the_achieved_speed_and_flags_each_measure():
    row = judged(gait(0.5, 1.45, 0.36), WINDOWS, BAND)
    assert row["windows"] == 3  # 0.62 is 0.12 away, 0.9 far
    assert (row["data_cadence"], row["data_cadence_low"], row["data_cadence_high"]) == (
        1.5,
        1.4,
        1.6,
    )
    assert (row["data_step_length"], row["data_step_length_low"]) == (0.30, 0.25)
    assert row["data_step_length_high"] == 0.35
    assert row["cadence_inside"] is True and row["step_length_inside"] is False
    assert row["inside"] is False  # both must lie inside
    # the bounds count as inside; at 0.9 m/s the one window there is the level
    assert judged(gait(0.5, 1.6, 0.25), WINDOWS, BAND)["inside"] is True
    fast = judged(gait(0.9, 1.9, 0.30), WINDOWS, BAND)
    assert fast["windows"] == 1 and fast["data_step_length"] == 0.45
    assert fast["cadence_inside"] is True and fast["step_length_inside"] is False
    # no step counted: outside; standing or not commanded forward: no level, no verdict
    assert judged(gait(0.5, 1.5, None), WINDOWS, BAND)["step_length_inside"] is False
    for still in (gait(0.02, 0.0, None), gait(0.5, 1.5, 0.3, forward=False)):
        row = judged(still, WINDOWS, BAND)
        assert row["windows"] == 0 and row["inside"] is None and row["data_step_length"] is None
        assert row["cadence_inside"] is None and row["step_length_inside"] is None
    # nothing near the speed: a level of none
    assert judged(gait(1.5, 1.9, 0.5), WINDOWS, BAND)["inside"] is None


def test_trend_compares_the_slopes_over_the_walking_rollouts():
    """Steps of 0.3 x speed against data windows of 0.5 x speed: slopes 0.3 and 0.5, steps
    at 60% of the data's; the standing rollout is left out of the slope."""
    windows = [window(v, 1.8, 0.5 * v) for v in np.arange(0.2, 1.21, 0.05)]
    speeds = [0.3, 0.5, 0.8, 1.0]
    gaits = [gait(0.01, 0.0, None)] + [gait(v, 1.8, 0.3 * v) for v in (0.4, 0.6, 0.8)]
    table = gait_table("w10/0", speeds, gaits, windows, BAND)
    assert list(table["command"]) == speeds and (table["model"] == "w10/0").all()
    out = trend(table, windows, BAND)
    assert out["walking"] == 3 and (out["speed_low"], out["speed_high"]) == (0.4, 0.8)
    assert out["step_slope"] == pytest.approx(0.3)
    assert out["data_step_slope"] == pytest.approx(0.5)
    assert out["step_over_data"] == pytest.approx(0.6, abs=0.03)
    # inside: step 0.3 v against the data's [0.5 (v - 0.1), 0.5 (v + 0.1)]: nowhere
    assert out["step_inside_at"] == "-" and out["inside_at"] == "-"
    inside = trend(gait_table("m", [0.4], [gait(0.4, 1.8, 0.2)], windows, BAND), windows, BAND)
    assert inside["inside_at"] == "0.4" and np.isnan(inside["step_slope"])  # one speed


@pytest.fixture
def stepping(monkeypatch, robot):
    """Any --model is a stepping gait (tests/builders.GaitModel): 2 swings a second, each foot
    swinging by the commanded velocity x a half period, so its step is half its speed."""
    model = GaitModel(robot)
    monkeypatch.setattr(gait_by_speed, "_is_adherent", lambda _: False)
    monkeypatch.setattr(gait_by_speed, "load_model", lambda _: (model, LAYOUT, IDENTITY, {}))


def test_a_stride_that_follows_the_command_lengthens_the_step(stepping, robot, tmp_path):
    speeds = [0.2, 0.4, 0.8]
    trajectories = roll_out(tmp_path / "gait", PARAMS, speeds, 10.0, robot)
    assert [len(t.time) for t in trajectories] == [501] * 3
    gaits = [gait_of(t, PARAMS, robot) for t in trajectories]
    cadence = np.array([g["gait_cadence"] for g in gaits])
    step = np.array([g["gait_step_length"] for g in gaits])
    speed = np.array([g["gait_speed"] for g in gaits])
    assert cadence == pytest.approx(2.0)  # 16 swings over the last 8 s
    assert step * cadence == pytest.approx(speed, rel=0.05)  # a steady gait
    assert np.all(np.diff(step) > 0.05) and np.all(speed > 0.5 * np.array(speeds))
    table = gait_table("gait", speeds, gaits, [window(v, 2.0, 0.5 * v) for v in speed], BAND)
    assert trend(table, [], BAND)["step_slope"] == pytest.approx(0.5, abs=0.03)


def write_summary(folder, windows: list[dict]):
    """A metrics_summary.json whose data_reference records these gait windows."""
    table = {key: [w[key] for w in windows] for key in windows[0]}
    record = {"speed_band": BAND, "per_window": table}
    path = folder / "metrics_summary.json"
    path.write_text(json.dumps({"data_reference": {"gait": record}}))
    return path


def _rows(text: str, header: str) -> list[list[str]]:
    """The rows of the table printed under the line starting with `header`."""
    lines = text.splitlines()
    start = next(k for k, line in enumerate(lines) if line.startswith(header)) + 2
    rows = []
    for line in lines[start:]:
        if not line.strip():
            break
        rows.append(line.split())
    return rows


def test_the_printed_table_judges_each_rollout_at_its_achieved_speed(stepping, tmp_path, capsys):
    """Crafted data: under 0.5 m/s windows of cadence 1.8-2.2, at or over it 1.0-1.4, each
    window's step half its speed; the stepping gait (2 swings a second, step half its speed)
    lies inside at its slow command and outside in cadence at its fast one, judged at the speed
    it achieved, not the command (0.8 m/s: it achieves about 0.65)."""
    grid = np.round(np.arange(0.0, 1.51, 0.05), 2)
    windows = [window(v, c, 0.5 * v) for v in grid for c in ((1.8, 2.2) if v < 0.5 else (1.0, 1.4))]
    summary = write_summary(tmp_path, windows)
    args = ["--model", str(tmp_path / "gait"), "--speeds", "0.4", "0.8", "--seconds", "10"]
    assert main([*args, "--summary", str(summary)]) == 0
    out = capsys.readouterr().out
    data = _rows(out, "the data's forward walking")
    assert [float(r[0]) for r in data] == [0.4, 0.8]
    assert [int(r[1]) for r in data] == [2 * 5, 2 * 5]  # 0.3 .. 0.5 and 0.7 .. 0.9
    rows = _rows(out, f"{tmp_path / 'gait'}:")
    assert len(rows) == 2 and all(len(r) == 16 for r in rows)
    for row, (low_speed, high_speed) in zip(rows, ((0.3, 0.45), (0.58, 0.7)), strict=True):
        speed, cadence, step = (float(v) for v in row[1:4])
        assert low_speed < speed < high_speed and cadence == 2.0
        near = grid[np.abs(grid - speed) <= BAND + 1e-9]
        assert int(row[14]) == 2 * len(near)
        data_step, step_low, step_high = (float(v) for v in row[10:13])
        assert data_step == pytest.approx(0.5 * np.median(near), abs=1e-3)
        assert (step_low, step_high) == pytest.approx((0.5 * near.min(), 0.5 * near.max()), 1e-3)
        assert row[13] == "True"  # the step is half the speed: inside
    slow, fast = rows
    assert slow[6:10] == ["2.0", "1.8", "2.2", "True"] and slow[15] == "True"
    assert fast[6:10] == ["1.2", "1.0", "1.4", "False"] and fast[15] == "False"
    (trends,) = _rows(out, "step length against speed")
    assert trends[-3:] == ["0.4", "0.8", "0.4"]  # step inside at 0.4 0.8; both at 0.4


def test_a_missing_model_gets_one_line(tmp_path, capsys):
    summary = write_summary(tmp_path, WINDOWS)
    args = ["--model", str(tmp_path / "missing"), "--speeds", "0.4", "--summary", str(summary)]
    assert main(args) == 2
    error = capsys.readouterr().err
    assert error.startswith("gait_by_speed: ") and "missing" in error and error.count("\n") == 1
