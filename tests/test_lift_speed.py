"""The lift-speed diagnostic (diagnostics.lift_speed) on a robot lifted at a known speed."""

from __future__ import annotations

import numpy as np
import pytest
from builders import RATE, make_trajectory

from diagnostics.lift_speed import counted_frames, describe, lift_speeds
from pimann.generate.contact_consistent import LegSolver


@pytest.mark.parametrize("speed", [0.3, 0.9])
def test_a_robot_lifted_at_a_known_speed_lifts_both_feet_at_it(robot, params, speed):
    """Standing 0.5 s, then the whole robot rises at `speed`: both feet leave the floor at
    `speed`, and the rule counts them down for its switch time after they pass the off height:
    the two lift-offs read `speed` there (central differences, past the kink)."""
    frames = 60
    rise = speed * np.clip(np.arange(frames) / RATE - 0.5, 0.0, None)
    trajectory = make_trajectory(np.zeros((frames, 2)), z=rise)
    solver = LegSolver(robot, params.rollout.consistent)
    speeds = lift_speeds(trajectory, solver, params.contacts, rollout=True)
    assert counted_frames(params.contacts, 1.0 / RATE) == 2
    np.testing.assert_allclose(speeds, [speed, speed], atol=1e-6)
    assert describe(speeds).startswith("2 lift-offs") and describe(speeds[:0]) == "no lift-off"


def test_a_stance_cut_by_the_end_is_no_lift_off(robot, params):
    trajectory = make_trajectory(np.zeros((40, 2)))
    solver = LegSolver(robot, params.rollout.consistent)
    assert len(lift_speeds(trajectory, solver, params.contacts, rollout=True)) == 0
