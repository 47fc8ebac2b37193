"""Command scripts as the generator reads them (pimann.generate.command_script)."""

from __future__ import annotations

import numpy as np
import pytest
from pydantic import ValidationError

from pimann.core.errors import PimannError
from pimann.core.params import MotionSegment, StandSegment
from pimann.generate.command_script import Command, ScriptSteps, scenario_steps

RATE = 50.0


def test_each_step_takes_the_segment_its_midpoint_falls_in():
    script = [
        MotionSegment(1.0, 0.8, 0.0, 0.0),
        StandSegment(0.5, True),
        MotionSegment(0.26, 0.0, 0.2, 0.1),
    ]
    steps = scenario_steps(script, RATE)
    assert len(steps) == round(1.76 * RATE) == 88
    # step k spans [k dt, (k+1) dt): the first 50 in segment 0, the next 25 in 1, 13 in 2
    assert np.array_equal(np.bincount(steps), [50, 25, 13])
    assert np.all(np.diff(steps) >= 0)  # segments in order, each once
    midpoints = (np.arange(88) + 0.5) / RATE
    ends = np.cumsum([1.0, 0.5, 0.26])
    assert np.array_equal(steps, [int(np.argmax(t < ends)) for t in midpoints])


def test_an_empty_script_is_refused():
    with pytest.raises(PimannError, match="segments"):
        scenario_steps([], RATE)


@pytest.mark.parametrize(
    "make", [lambda: MotionSegment(0.0, 0.1, 0, 0), lambda: StandSegment(-1.0, True)]
)
def test_a_non_positive_duration_is_refused_where_the_segment_is_made(make):
    with pytest.raises(ValidationError, match="greater than 0"):
        make()


def test_a_zero_motion_command_is_a_stand():
    assert Command.of(MotionSegment(1.0, 0.0, 0.0, 0.0)).stand
    assert Command.of(StandSegment(1.0, True)).stand
    turning = Command.of(MotionSegment(1.0, 0.0, 0.0, 0.3))
    assert not turning.stand and turning.yaw_rate == 0.3
    moving = Command.of(MotionSegment(1.0, -0.6, 0.2, 0.0))
    assert np.array_equal(moving.velocity, [-0.6, 0.2]) and not moving.stand


def test_rows_of_different_lengths_stand_past_their_end():
    short = [MotionSegment(0.2, 0.8, 0.0, 0.0)]  # 10 steps
    long = [StandSegment(0.1, True), MotionSegment(0.3, 0.0, 0.2, 0.3)]  # 5 + 15 steps
    s = ScriptSteps([short, long], RATE)
    assert list(s.lengths) == [10, 20] and s.velocity.shape == (21, 2, 2)
    # row 0: moving on steps 1..10, then standing and inactive; step 0 is the start state
    assert np.allclose(s.velocity[1:11, 0], [0.8, 0.0]) and not s.stand[1:11, 0].any()
    assert s.stand[11:, 0].all() and not s.active[11:, 0].any() and s.active[:11, 0].all()
    assert np.allclose(s.velocity[11:, 0], 0.0)
    # row 1: stands 5 steps, then side-steps turning
    assert s.stand[1:6, 1].all() and not s.stand[6:21, 1].any()
    assert np.allclose(s.velocity[6:21, 1], [0.0, 0.2]) and np.allclose(s.yaw_rate[6:21, 1], 0.3)
    # a command starts where its segment's first step is
    assert np.flatnonzero(s.changed[:, 0]).tolist() == [1]
    assert np.flatnonzero(s.changed[:, 1]).tolist() == [1, 6]
    assert s.active[:, 1].all()
