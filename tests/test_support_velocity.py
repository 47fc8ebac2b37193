"""The velocity level's sole twists (pimann.evaluate.sliding) against placements alone: the
support sole still, the other sole moving as the joints carry it relative to the support."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from builders import random_configuration

from pimann.core.contacts import FEET
from pimann.evaluate.sliding import sole_jacobians, support_foot_velocities


def _moved(robot, q, joint_velocities, step):
    """q with the joints advanced by `step` s at `joint_velocities`, the base where it is."""
    v = np.zeros(robot.model.nv)
    v[robot.v_index] = joint_velocities
    return pin.integrate(robot.model, q, v * step)


@pytest.mark.parametrize("support", [0, 1])
def test_support_sole_still_and_the_other_relative_to_it(robot, rng, support):
    q = random_configuration(robot, rng)
    joint_velocities = rng.normal(size=len(robot.v_index))
    heights = np.array([[0.0, 0.1]]) if support == 0 else np.array([[0.1, 0.0]])
    (twists,) = support_foot_velocities(
        robot, sole_jacobians(robot, q[None]), joint_velocities[None], heights
    )
    np.testing.assert_allclose(twists[support], 0.0, atol=1e-10)

    # reference: the support sole fixed in the world where it is at q, the other sole placed
    # from it through the joints only, its twist by central differences of those placements
    held, other = FEET[support], FEET[1 - support]
    world_M_held = robot.frame_placement(q, held)
    step = 1e-6

    def placed(sign: float) -> pin.SE3:
        moved = _moved(robot, q, joint_velocities, sign * step)
        held_M_other = robot.frame_placement(moved, held).inverse() * robot.frame_placement(
            moved, other
        )
        return world_M_held * held_M_other

    after, before = placed(1.0), placed(-1.0)
    linear = (after.translation - before.translation) / (2 * step)
    angular = pin.log3(after.rotation @ before.rotation.T) / (2 * step)  # world axes
    np.testing.assert_allclose(twists[1 - support], np.r_[linear, angular], atol=1e-6)
    assert np.abs(twists[1 - support]).max() > 0.1  # the joints do move it


def test_still_joints_leave_both_soles_still_and_the_support_follows_the_heights(robot, rng):
    q = np.array([random_configuration(robot, rng) for _ in range(3)])
    still = support_foot_velocities(
        robot, sole_jacobians(robot, q), np.zeros((3, len(robot.v_index))), np.zeros((3, 2))
    )
    assert np.abs(still).max() == 0.0
    joint_velocities = rng.normal(size=(3, len(robot.v_index)))
    heights = np.array([[0.0, 0.1], [0.2, 0.05], [0.0, 0.0]])  # left, right, a tie: the left
    twists = support_foot_velocities(robot, sole_jacobians(robot, q), joint_velocities, heights)
    for k, support in enumerate([0, 1, 0]):
        np.testing.assert_allclose(twists[k, support], 0.0, atol=1e-10)
        assert np.abs(twists[k, 1 - support]).max() > 0.1
