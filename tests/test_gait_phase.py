"""The gait phase (features.gait_phase) against its closed form on hand-made contact flags."""

from __future__ import annotations

import numpy as np
import pytest

from pimann.core.errors import PimannError
from pimann.learn.gait_phase import (
    gait_phase,
    phase_vector,
    touchdown_frames,
    unit_phase,
)

RATE = 50.0


def flags(length: int, left: list[tuple[int, int]], right: list[tuple[int, int]]) -> np.ndarray:
    """(T, 2) contact flags down over the [start, stop) frames given per foot."""
    contacts = np.zeros((length, 2), dtype=bool)
    for foot, runs in enumerate((left, right)):
        for start, stop in runs:
            contacts[start:stop, foot] = True
    return contacts


def test_alternating_touchdowns_are_half_turns_apart_and_linear_between():
    # left down at 10 and 60, right at 35 and 85: a 25-frame (0.5 s) step
    contacts = flags(100, [(10, 45), (60, 95)], [(0, 20), (35, 70), (85, 100)])
    frames, feet = touchdown_frames(contacts)
    assert frames.tolist() == [10, 35, 60, 85] and feet.tolist() == [0, 1, 0, 1]
    phase = gait_phase(contacts, RATE, step_s=0.8)
    assert phase[[10, 35, 60, 85]] == pytest.approx([0.0, np.pi, 2 * np.pi, 3 * np.pi])
    between = np.arange(10, 86)
    assert phase[between] == pytest.approx((between - 10) * np.pi / 25)
    assert np.all(phase[86:] == phase[85])  # after the last touchdown it holds
    # before the first: half a turn over step_s (0.8 s = 40 frames, clipped at frame 0)
    assert phase[0] == pytest.approx(-np.pi * 10 / 40)


def test_a_pause_holds_the_phase_and_the_same_foot_advances_a_whole_turn():
    # left down at 10, then (a 2 s pause) left again at 110; the right foot stays down
    contacts = flags(160, [(10, 60), (110, 160)], [(0, 160)])
    phase = gait_phase(contacts, RATE, step_s=0.5)  # 25 frames
    assert phase[10] == 0.0 and phase[110] == pytest.approx(2 * np.pi)
    assert np.all(phase[10:86] == 0.0)  # waits until step_s before the touchdown
    assert phase[98] == pytest.approx(2 * np.pi * (98 - 85) / 25)
    assert np.all(phase[110:] == phase[110])


def test_no_touchdown_is_phase_zero_and_bad_input_is_named():
    assert np.all(gait_phase(np.ones((30, 2), bool), RATE, 0.8) == 0.0)
    with pytest.raises(PimannError, match=r"\(T, 2\)"):
        gait_phase(np.ones((30, 3), bool), RATE, 0.8)
    with pytest.raises(PimannError, match="positive"):
        gait_phase(np.ones((30, 2), bool), RATE, 0.0)


def test_both_feet_at_one_frame_count_once_and_the_phase_never_falls():
    rng = np.random.default_rng(0)
    contacts = rng.random((400, 2)) < 0.7
    contacts[50] = False
    contacts[51] = True  # both feet land at 51
    frames, _ = touchdown_frames(contacts)
    assert np.all(np.diff(frames) > 0)
    phase = gait_phase(contacts, RATE, 0.8)
    assert np.all(np.diff(phase) >= 0)


def test_phase_vectors_are_unit_and_a_prediction_is_put_back_on_the_circle():
    phase = np.linspace(-3, 9, 50)
    vector = phase_vector(phase)
    assert np.allclose(np.linalg.norm(vector, axis=1), 1.0)
    assert np.allclose(np.arctan2(vector[:, 1], vector[:, 0]), np.angle(np.exp(1j * phase)))
    assert np.allclose(unit_phase(2.5 * vector), vector)
    assert unit_phase(np.zeros((1, 2))).tolist() == [[1.0, 0.0]]


def test_several_predicted_phases_are_each_put_back_on_their_circle():
    pairs = np.array([[3.0, 4.0, 0.0, -2.0], [0.0, 0.0, 1.0, 1.0]])
    assert np.allclose(unit_phase(pairs), [[0.6, 0.8, 0.0, -1.0], [1.0, 0.0, 2**-0.5, 2**-0.5]])
