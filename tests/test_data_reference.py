"""The data's own level of the sliding metrics (pimann.evaluate.data_reference) on synthetic clips
whose
answer is known: the standing robot slid along its heading at a known speed."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from builders import (
    EVALUATE_PARAMS,
    walking_clip,  # noqa: F401
)

from pimann.core.params import load_params
from pimann.core.trajectory import write_collection
from pimann.evaluate.data_reference import FRAMES, clip_reference, data_reference
from pimann.learn.features import split_sources


@pytest.fixture(scope="module")
def params():
    return dataclasses.replace(load_params(), evaluate=EVALUATE_PARAMS)


def test_a_sliding_clip_scores_its_speed_per_500_frames(params):
    # both feet in contact slide at 0.6 m/s: RMS over 3 components 0.6 / sqrt(3) every frame
    row = clip_reference(
        walking_clip(0.6, 300, "a", contacts=False), params.evaluate, params.contacts
    )
    assert row["forward_frames"] == 300 and row["frames"] == 300
    expected = FRAMES * 0.6 / np.sqrt(3)
    for name in ("linear_position", "linear_position_world"):
        assert row[f"support_rmse_{name}_total"] == pytest.approx(expected, rel=1e-6), name
    # the velocity level's base holds the support foot, and still joints move no foot
    for name in ("linear", "linear_world", "angular"):
        assert row[f"support_rmse_{name}_total"] == pytest.approx(0.0, abs=1e-9), name
    # the file's contacts (none) are ignored: the evaluate rule finds both feet down
    assert row["support_rmse_linear_position_total"] > 0


def test_only_forward_frames_count(params):
    standing = clip_reference(walking_clip(0.0, 300, "s"), params.evaluate, params.contacts)
    assert standing["forward_frames"] == 0 and standing["support_rmse_linear_total"] is None


def test_level_is_the_median_over_clips_with_enough_forward_walking(params, tmp_path):
    clips = {
        "a": walking_clip(0.3, 300, "a"),
        "b": walking_clip(0.6, 260, "b"),
        "c": walking_clip(0.9, 400, "c"),
        "short": walking_clip(3.0, 200, "short"),  # too little forward walking: left out
        "stand": walking_clip(0.0, 400, "stand"),
    }
    path = tmp_path / "walking.h5"
    write_collection(path, clips.items())
    reference = data_reference(path, params, workers=1)
    every = reference["all"]
    assert every["clips"] == 5 and every["used"] == 3 and every["forward_frames"] == 960
    linear = every["metrics"]["support_rmse_linear_position_total"]
    assert linear["median"] == pytest.approx(FRAMES * 0.6 / np.sqrt(3), rel=1e-6)
    assert linear["min"] == pytest.approx(FRAMES * 0.3 / np.sqrt(3), rel=1e-6)
    assert reference["joint_velocities"] == "differences"
    features = params.features
    test = split_sources(clips.values(), features.test_fraction, features.split_seed)
    assert reference["test"]["clips"] == len(test)
    used = [name for name in test if name in ("a", "b", "c")]
    assert reference["test"]["used"] == len(used)
