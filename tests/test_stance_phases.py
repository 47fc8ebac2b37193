"""Where in a stance the feet slide (pimann.evaluate.sliding): labels worked out by hand,
shares
of known sums, and the columns pimann.evaluate.metrics and pimann.evaluate.data_reference report."""

from __future__ import annotations

import numpy as np
import pytest
from builders import CONTACT_PARAMS, EVALUATE_PARAMS, walking_clip

from pimann.core.robot import load_robot
from pimann.evaluate.data_reference import clip_reference
from pimann.evaluate.metrics import trajectory_metrics
from pimann.evaluate.sliding import PHASES, phase_shares, stance_phases

# one foot: a stance under way at the start (frames 0-2), one seen whole (5-11), one still on
# at the end (13-14); edge 2: two frames each side
CONTACTS = np.array([1, 1, 1, 0, 0, 1, 1, 1, 1, 1, 1, 1, 0, 1, 1], dtype=bool)[:, None]
#                    mid lift    td td mid   lift   td td
LABELS = np.array([2, 3, 3, 0, 0, 1, 1, 2, 2, 2, 3, 3, 0, 1, 1])[:, None]


def test_labels_by_hand():
    assert np.array_equal(stance_phases(CONTACTS, 2), LABELS)


def test_a_short_stance_is_lift_off_where_both_windows_meet():
    contacts = np.array([0, 1, 1, 1, 0], dtype=bool)[:, None]
    assert stance_phases(contacts, 2)[:, 0].tolist() == [0, 1, 3, 3, 0]


def test_feet_are_labelled_independently():
    both = np.hstack([CONTACTS, CONTACTS[::-1]])
    labels = stance_phases(both, 2)
    assert np.array_equal(labels[:, 0], LABELS[:, 0])
    flipped = LABELS[::-1, 0].copy()  # time reversed: touchdowns become lift-offs
    flipped[flipped == 1], flipped[flipped == 3] = 9, 1
    flipped[flipped == 9] = 3
    assert np.array_equal(labels[:, 1], flipped)


def test_shares_of_an_even_spread_are_the_frame_shares():
    shares = phase_shares(np.ones_like(CONTACTS, dtype=float), CONTACTS, rate_hz=20.0)  # edge 2
    counts = {"touchdown": 4, "mid": 4, "liftoff": 4}  # of 12 contact frames
    for phase in PHASES:
        assert shares[phase] == pytest.approx(counts[phase] / 12)
        assert shares[f"{phase}_frames"] == pytest.approx(counts[phase] / 12)


def test_sliding_only_before_lift_off_is_all_lift_off():
    values = np.where(LABELS == 3, 2.5, 0.0) + np.where(LABELS == 0, 100.0, 0.0)  # swing ignored
    shares = phase_shares(values, CONTACTS, rate_hz=20.0)
    assert shares["liftoff"] == 1.0 and shares["touchdown"] == shares["mid"] == 0.0
    assert phase_shares(np.zeros(CONTACTS.shape), CONTACTS, 20.0)["mid"] is None


def test_counted_frames_keep_the_stance_phases():
    counted = np.arange(15) >= 7  # frames 7.. only: 7-9 mid, 10-11 lift-off, 13-14 touchdown
    shares = phase_shares(np.ones(CONTACTS.shape), CONTACTS, 20.0, counted)
    assert shares["mid"] == pytest.approx(3 / 7) and shares["liftoff"] == pytest.approx(2 / 7)
    assert shares["touchdown"] == pytest.approx(2 / 7)


def test_metrics_and_data_reference_report_the_shares():
    """The standing robot slid at a constant speed on both feet, down all along: no touchdown or
    lift-off in view, so all its sliding is mid-stance, in the rollouts' metrics and in the
    data's reference alike. A glide with still joints moves no foot at the velocity level: it
    has no share to split."""
    clip = walking_clip(0.5, 200, "a")
    metrics = trajectory_metrics(clip, load_robot("retarget"), EVALUATE_PARAMS, CONTACT_PARAMS)
    reference = clip_reference(clip, EVALUATE_PARAMS, CONTACT_PARAMS)
    for row in (metrics, reference):
        assert row["support_rmse_linear_position_mid_share"] == pytest.approx(1.0)
        assert row["support_rmse_linear_position_liftoff_share"] == 0.0
        assert row["support_rmse_linear_mid_share"] is None
        assert row["contact_mid_frames_share"] == 1.0


def test_a_foot_dragged_before_lift_off_shows_in_the_metrics():
    """The file's contacts: both feet down, the left one lifting at frame 150; the robot slides
    from frame 140 on. The left foot slides 10 contact frames (the last 5 its lift-off window),
    the right one 60 (mid-stance, on to the end): a lift-off share of 5 / 70."""
    robot = load_robot("retarget")
    clip = walking_clip(0.5, 200, "a", contacts=True)
    clip.contacts[150:, 0] = False
    start = clip.base_position[0].copy()
    moved = np.maximum(clip.time - clip.time[140], 0.0)[:, None]
    clip.base_position[:] = start + moved * (clip.base_position[1] - start) / clip.time[1]
    metrics = trajectory_metrics(clip, robot, EVALUATE_PARAMS, CONTACT_PARAMS)
    assert metrics["support_rmse_linear_position_liftoff_share"] == pytest.approx(5 / 70, rel=0.05)
    assert metrics["support_rmse_linear_position_touchdown_share"] == 0.0
    assert metrics["contact_liftoff_frames_share"] == pytest.approx(5 / 350)
