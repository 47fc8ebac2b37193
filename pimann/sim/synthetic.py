"""A synthetic stepping trajectory (kinematic, via the IK) for tests and benchmarks.

Built from a hand-made footstep plan so the footstep extraction can be checked against it,
and the closed loop can be run without a trained model.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from pimann.core.params import SimulateParams
from pimann.core.robot import LEFT_SOLE, RIGHT_SOLE, STANDING_JOINTS, Robot
from pimann.core.trajectory import Trajectory
from pimann.sim.footsteps import FootstepPlan, Footsteps, compose
from pimann.sim.wbc import IKTargets, WholeBodyIK, standing_pose


def standing_feet(robot: Robot, q: np.ndarray) -> np.ndarray:
    """(2, 3) x, y, yaw of the left and right soles at q."""
    out = np.empty((2, 3))
    for side, frame in enumerate((LEFT_SOLE, RIGHT_SOLE)):
        placement = robot.frame_placement(q, frame)
        out[side, :2] = placement.translation[:2]
        out[side, 2] = np.arctan2(placement.rotation[1, 0], placement.rotation[0, 0])
    return out


def stepping_plan(
    feet: np.ndarray,
    steps: int,
    step: tuple[float, float, float] | float,
    single: float = 0.7,
    double: float = 0.2,
    start: float = 0.5,
    end: float = 0.5,
    swing_height: float = 0.035,
) -> FootstepPlan:
    """`steps` alternating steps from `feet` (2, 3), each foot moving by `step` (dx, dy, dyaw).

    `step` is in the walking frame (a float: straight forward). The frame midway between the
    feet advances by half a step per step and the last step brings the feet side by side, so
    the first and last steps are half steps. The foot on the side of the motion moves first.
    """
    increment = np.array([step, 0.0, 0.0] if np.isscalar(step) else step, dtype=float) / 2
    half_width = 0.5 * np.linalg.norm(feet[0, :2] - feet[1, :2])
    path = np.array([*feet[:, :2].mean(axis=0), np.angle(np.exp(1j * feet[:, 2]).mean())])
    first = 0 if (increment[1] > 0 or increment[2] > 0) else 1
    positions = [[feet[0, :2].copy()], [feet[1, :2].copy()]]
    yaws = [[feet[0, 2]], [feet[1, 2]]]
    t_on, t_off = [[0.0], [0.0]], [[], []]
    t = start
    for k in range(steps):
        side = first if k % 2 == 0 else 1 - first
        if k < steps - 1:
            path = compose(path, increment)
        foot = compose(path, np.array([0.0, half_width if side == 0 else -half_width, 0.0]))
        t_off[side].append(t)
        t += single
        positions[side].append(foot[:2])
        yaws[side].append(foot[2])
        t_on[side].append(t)
        t += double
    duration = t - double + end
    made = tuple(
        Footsteps(
            positions=np.array(positions[s]),
            yaws=np.array(yaws[s]),
            t_on=np.array(t_on[s]),
            t_off=np.array([*t_off[s], duration]),
        )
        for s in (0, 1)
    )
    return FootstepPlan(made, duration, swing_height, 0.0, 0.0, 1.0)


def stepping_trajectory(
    robot: Robot, params: SimulateParams, plan: FootstepPlan, rate_hz: float = 50.0
) -> Trajectory:
    """A kinematic trajectory whose soles follow `plan`, CoM shifting over the stance foot."""
    q0 = standing_pose(robot, params)
    ik = WholeBodyIK(robot, dataclasses.replace(params, control_rate_hz=rate_hz), q0)
    time = np.arange(0.0, plan.duration + 1e-9, 1.0 / rate_hz)
    qs, contacts = [], []
    com_z = ik.com_position()[2]
    for t in time:
        poses = [plan.foot_pose(s, t) for s in (0, 1)]
        loaded = [plan.in_contact(s, t) for s in (0, 1)]
        support = [p[0][:2] for p, c in zip(poses, loaded, strict=True) if c]
        com_xy = np.mean(support, axis=0)
        targets = IKTargets(
            left=plan.sole_placement(0, t),
            right=plan.sole_placement(1, t),
            com=np.array([com_xy[0], 0.5 * com_xy[1], com_z]),
            chest_yaw=float(np.mean([p[1] for p in poses])),
            posture=STANDING_JOINTS,
        )
        for _ in range(3):
            q = ik.step(targets)
        qs.append(q)
        contacts.append(loaded)
    qs = np.array(qs)
    return Trajectory(
        time=time,
        base_position=qs[:, :3],
        base_quaternion_xyzw=qs[:, 3:7],
        joint_positions=qs[:, robot.q_index],
        source="synthetic-stepping",
        rate_hz=rate_hz,
        contacts=np.array(contacts),
    )
