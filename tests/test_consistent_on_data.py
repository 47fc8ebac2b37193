"""diagnostics.consistent_on_data: the post-process on retargeted clips, raw against held,
measured as the data reference measures the data."""

from __future__ import annotations

import numpy as np
import pytest
from builders import HEADING, walking_clip

from diagnostics.consistent_on_data import ABOVE, clip_row, drifted, summary
from pimann.core.params import load_params
from pimann.evaluate.data_reference import MIN_FORWARD_FRAMES, clip_reference

POSITION = "support_rmse_linear_position_total"


@pytest.fixture(scope="module")
def params():
    return load_params()


def test_a_drift_moves_the_base_to_the_left_of_its_heading_then_stops():
    clip = walking_clip(0.4, 300, "walk")  # heading HEADING, 6 s
    moved = drifted(clip, 0.05, 4.0)
    offset = moved.base_position - clip.base_position
    left = np.array([-np.sin(HEADING), np.cos(HEADING), 0.0])
    expected = 0.05 * np.minimum(clip.time, 4.0)
    np.testing.assert_allclose(offset, expected[:, None] * left, atol=1e-12)
    np.testing.assert_array_equal(moved.joint_positions, clip.joint_positions)


def _row(raw: float, held: float, forward: int, name: str = "c") -> dict:
    def m(value):
        return {
            "forward_frames": forward,
            "position": value,
            "authors": 2 * value,
            "position_clip": value,
            "authors_clip": 2 * value,
            "touchdowns": 4,
        }

    return {
        "clip": name,
        "raw": m(raw),
        "held": m(held),
        "joints_rms": 0.02,
        "joints_max": 0.3,
        "residual": 0.0,
    }


def test_the_medians_count_the_data_references_clips_and_the_clips_above_their_raw_level():
    rows = [
        _row(10.0, 9.0, MIN_FORWARD_FRAMES),
        _row(20.0, 1.2 * 20.0, MIN_FORWARD_FRAMES + 10),  # above ABOVE x its raw level
        _row(100.0, 50.0, MIN_FORWARD_FRAMES - 1),  # too little forward walking for the reference
    ]
    s = summary(rows)
    assert ABOVE < 1.2
    assert s["position"]["clips"] == 2 and s["position"]["raw"] == pytest.approx(15.0)
    assert s["position"]["held"] == pytest.approx(16.5)
    assert s["position"]["above"] == 1 and s["position"]["largest_ratio"] == pytest.approx(1.2)
    assert s["position_clip"]["clips"] == 3 and s["position_clip"]["raw"] == pytest.approx(20.0)


def test_a_real_walk_held_slides_as_its_data_and_a_drift_is_removed(robot, params, real_walks):
    """A retargeted forward walk: its raw level is the data reference's; held, within 1.2x of
    it; drifting sideways at 0.05 m/s for 4 s, its feet glide and the hold removes most of it."""
    walk = real_walks["walk"]
    plain = clip_row("walk", walk, robot, params)
    reference = clip_reference(walk, params.evaluate, params.contacts)
    assert plain["raw"]["position"] == pytest.approx(reference[POSITION])
    assert plain["raw"]["forward_frames"] >= MIN_FORWARD_FRAMES
    raw, held = plain["raw"], plain["held"]
    for key in ("position", "position_clip"):
        assert held[key] < 1.2 * raw[key], (key, raw[key], held[key])
    assert held["touchdowns"] == raw["touchdowns"]
    assert plain["joints_rms"] < 0.05 and plain["residual"] < 0.01

    drift = clip_row("walk", walk, robot, params, drift=0.05, drift_s=4.0)
    assert drift["raw"]["position_clip"] > 1.15 * raw["position_clip"]  # the feet glide
    for key in ("position", "position_clip"):
        assert drift["held"][key] < 0.85 * drift["raw"][key], (key, drift["raw"], drift["held"])
        assert drift["held"][key] < 1.2 * raw[key]
