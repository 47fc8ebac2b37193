"""Whole-body QP IK (pink + daqp): feet poses, CoM, chest orientation, posture.

The IK integrates its own kinematic configuration (the joint references sent to the position
actuators); feedback from the simulation enters only through the CoM velocity command
(`zmp_com_feedback`), as in Romualdi 2018's offline controller. Targets are given for the end
of the control tick: feet and CoM follow them exactly (gain 1, the targets carry the
feed-forward), chest and posture with gain kp * dt.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pinocchio as pin
from pink import Configuration, solve_ik
from pink.tasks import ComTask, FrameTask, PostureTask

from pimann.core.params import SimulateParams
from pimann.core.robot import CHEST_FRAME, LEFT_SOLE, RIGHT_SOLE, STANDING_JOINTS, Robot
from pimann.core.rotations import rot_z

SOLE_HEIGHT = 0.002  # the foot boxes' bottoms lie this far above the soles (docs/controllers.md)


def sole_pose(position_xy, z: float, yaw: float) -> pin.SE3:
    """A flat sole placement: the foot boxes touch the floor when z = 0."""
    return pin.SE3(rot_z(yaw), np.array([position_xy[0], position_xy[1], z - SOLE_HEIGHT]))


@dataclasses.dataclass
class IKTargets:
    left: pin.SE3
    right: pin.SE3
    com: np.ndarray  # (3,)
    chest_yaw: float
    posture: np.ndarray  # joints (26,) in the study's order


class WholeBodyIK:
    """One pink QP per control tick on the simulation model (26 joints, free base).

    Costs: feet 100, CoM 10, chest orientation 1, posture `posture_cost` (0.1): the feet win
    any conflict, the generated joints only shape the null space.
    """

    def __init__(self, robot: Robot, params: SimulateParams, q0: np.ndarray):
        self.robot = robot
        self.params = params
        self.dt = 1.0 / params.control_rate_hz
        self.configuration = Configuration(robot.model, robot.data, np.asarray(q0, dtype=float))
        self.lower = robot.model.lowerPositionLimit[7:]
        self.upper = robot.model.upperPositionLimit[7:]
        self.feet = (FrameTask(LEFT_SOLE, 100.0, 100.0), FrameTask(RIGHT_SOLE, 100.0, 100.0))
        self.com = ComTask(10.0)
        self.chest = FrameTask(CHEST_FRAME, 0.0, 1.0)
        self.posture = PostureTask(params.posture_cost)
        self.set_gains(self.dt)

    def set_gains(self, dt: float) -> None:
        """Feet and CoM reach their next-tick targets (gain 1); chest and posture converge at kp."""
        for task in (*self.feet, self.com):
            task.gain = 1.0
        self.chest.gain = min(1.0, self.params.chest_gain * dt)
        self.posture.gain = min(1.0, self.params.posture_gain * dt)

    @property
    def q(self) -> np.ndarray:
        return self.configuration.q.copy()

    def step(self, targets: IKTargets, dt: float | None = None) -> np.ndarray:
        """Move the IK configuration one tick toward the targets; returns the new q."""
        dt = self.dt if dt is None else dt
        self.feet[0].set_target(targets.left)
        self.feet[1].set_target(targets.right)
        self.com.set_target(np.asarray(targets.com, dtype=float))
        self.chest.set_target(pin.SE3(rot_z(targets.chest_yaw), np.zeros(3)))
        posture = self.configuration.q.copy()
        posture[self.robot.q_index] = targets.posture
        self.posture.set_target(posture)
        tasks = (*self.feet, self.com, self.chest, self.posture)
        velocity = solve_ik(
            self.configuration, tasks, dt, solver=self.params.ik_solver, safety_break=False
        )
        q = pin.integrate(self.robot.model, self.configuration.q, velocity * dt)
        # the QP keeps joints inside their limits only up to round-off; clip the last 1e-6
        q[7:] = np.clip(q[7:], self.lower, self.upper)
        self.configuration.update(q)
        return self.q

    def com_position(self) -> np.ndarray:
        return pin.centerOfMass(self.robot.model, self.robot.data, self.configuration.q)


def zmp_com_feedback(
    com_velocity_ref: np.ndarray,
    zmp_ref: np.ndarray,
    zmp_measured: np.ndarray,
    com_ref: np.ndarray,
    com_measured: np.ndarray,
    k_zmp: float,
    k_com: float,
) -> np.ndarray:
    """Horizontal CoM velocity command x_dot = x_dot* - K_zmp (r*_zmp - r_zmp) + K_com (x* - x)."""
    return (
        np.asarray(com_velocity_ref)
        - k_zmp * (np.asarray(zmp_ref) - np.asarray(zmp_measured))
        + k_com * (np.asarray(com_ref) - np.asarray(com_measured))
    )


class LowPass:
    """First-order low-pass filter: the measured ZMP's touchdown spikes would throw the feedback."""

    def __init__(self, cutoff_hz: float, dt: float, initial: np.ndarray):
        self.alpha = 1.0 - np.exp(-2.0 * np.pi * cutoff_hz * dt)
        self.value = np.asarray(initial, dtype=float).copy()

    def __call__(self, sample: np.ndarray) -> np.ndarray:
        sample = np.asarray(sample, dtype=float)
        if np.all(np.isfinite(sample)):
            self.value = self.value + self.alpha * (sample - self.value)
        return self.value.copy()


def standing_pose(robot: Robot, params: SimulateParams, iterations: int = 200) -> np.ndarray:
    """A standing configuration with flat soles on the floor and the CoM at `com_height`.

    ergoCub's standing pose (core.robot) has a pitched base and slightly yawed soles; the IK
    keeps its joints as the posture reference and puts the soles flat, parallel, at their
    lateral spacing.
    """
    q0 = robot.standing_configuration()
    left = robot.frame_placement(q0, LEFT_SOLE).translation
    right = robot.frame_placement(q0, RIGHT_SOLE).translation
    half_width = 0.5 * (left[1] - right[1])
    center_x = 0.5 * (left[0] + right[0])
    targets = IKTargets(
        left=sole_pose([center_x, half_width], 0.0, 0.0),
        right=sole_pose([center_x, -half_width], 0.0, 0.0),
        com=np.array([center_x, 0.0, params.com_height]),
        chest_yaw=0.0,
        posture=STANDING_JOINTS,
    )
    ik = WholeBodyIK(robot, params, q0)
    for task in (*ik.feet, ik.com, ik.chest, ik.posture):
        task.gain = 0.5
    for _ in range(iterations):
        ik.step(targets)
    return ik.q
