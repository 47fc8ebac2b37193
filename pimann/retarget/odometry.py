"""Leg odometry: the base position that keeps the supporting foot where it was put down.

The joints come from IK on orientations alone, so the base position is free: the scaled
human pelvis would make the feet slide (the robot's steps are shorter than the person's).
Instead, while a foot is in contact it is an anchor fixed in the world, on the floor, and
the base hangs from it through the leg's forward kinematics. The anchor only changes when
it lifts off, to the other foot if that one is down (its current position becomes its
anchor, so the base does not jump). With no foot down the base follows the scaled pelvis.

Height is set apart: the base hangs so that the lowest sole corner of either foot touches
the floor. The robot's flat feet and shorter legs can bring the landing foot lower than
the stance foot for a few frames; then the stance foot rises a little rather than the
landing foot going through the floor (walking has no flight phase, so one foot is down).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from pimann.robot import LEFT_SOLE, RIGHT_SOLE, Robot

# Sole corners (sole frame, m) of the retargeting's foot (SPEC 1).
SOLE_CORNERS = np.array([[x, y, 0.0] for x in (0.118, -0.118) for y in (0.05, -0.05)])


def sole_offsets(robot: Robot, configurations: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(T, 2, 3) left and right sole positions minus the base position (world axes), and
    (T,) the lowest sole corner's height relative to the base."""
    model, data = robot.model, robot.model.createData()
    frames = [robot.frame_id(LEFT_SOLE), robot.frame_id(RIGHT_SOLE)]
    offsets = np.empty((len(configurations), 2, 3))
    lowest = np.full(len(configurations), np.inf)
    for t, q in enumerate(configurations):
        pin.forwardKinematics(model, data, q)
        for k, frame in enumerate(frames):
            placement = pin.updateFramePlacement(model, data, frame)
            offsets[t, k] = placement.translation - q[:3]
            corners_z = SOLE_CORNERS @ placement.rotation[2] + offsets[t, k, 2]
            lowest[t] = min(lowest[t], corners_z.min())
    return offsets, lowest


def odometry_base_positions(
    offsets: np.ndarray, contacts: np.ndarray, fallback: np.ndarray, lowest: np.ndarray
) -> np.ndarray:
    """(T, 3) base positions from sole offsets (T, 2, 3), contacts (T, 2), a fallback base
    trajectory (T, 3) whose displacement is used while no foot is in contact, and the
    lowest corner's height under the base (T,)."""
    n = len(offsets)
    base = np.empty((n, 3))
    anchor_foot = -1
    anchor = np.zeros(3)
    for t in range(n):
        if anchor_foot < 0 or not contacts[t, anchor_foot]:
            down = np.flatnonzero(contacts[t])
            new_foot = int(down[0]) if len(down) else -1
            if new_foot >= 0:
                # where that foot was a frame ago (it is down, so it stays)
                anchor = (
                    base[t - 1] + offsets[t - 1, new_foot]
                    if t
                    else fallback[0] + offsets[0, new_foot]
                )
            anchor_foot = new_foot
        if anchor_foot >= 0:
            base[t] = anchor - offsets[t, anchor_foot]
        else:
            base[t] = base[t - 1] + fallback[t] - fallback[t - 1] if t else fallback[t]
    base[:, 2] = -lowest
    return base
