"""Whole-body differential IK with pink: the robot follows the human segment orientations.

The feet follow the sole targets of feet.py (full poses): a planted sole weighs
`stance_weight` and stays where it was put down, a swinging one `swing_weight`; no sole
corner goes under the floor (a QP inequality). The pelvis follows the person's pelvis
orientation and the scaled pelvis position at lower weights, so the base goes wherever the
planted feet let it (the robot's legs are shorter than the person's). The 10 other segments
are orientation-only costs on the robot's `data_<Segment>` frames (the robot is smaller than
the person, so positions of limbs cannot match, orientations can). A small posture cost
regularises redundant directions. The trunk (T8, Head) weighs more than the limbs: where an
arm reaches a joint limit, the chest should not tilt to make up for it. Joint limits, a
minimum shoulder roll and a minimum lateral foot spacing (in the pelvis frame, to keep the
legs apart: the dataset-1 actor walks with the ankles 2.6 cm apart) are QP inequalities.
Each frame runs a few QP iterations warm-started from the previous frame's solution.

pink gains are unitless per-iteration low-pass factors in (0, 1]; the paper's gains are
rates (1/s). They are converted as gain * `gain_time_step`, capped at 1.
"""

from __future__ import annotations

import numpy as np
import pink
import pinocchio as pin
from pink.limits import ConfigurationLimit, Limit
from pink.tasks import FrameTask, PostureTask

from pimann.core.params import RetargetParams
from pimann.core.robot import JOINT_NAMES, LEFT_SOLE, RIGHT_SOLE, SEGMENTS, Robot, corner_offsets

FEET = ("LeftFoot", "RightFoot")
SHOULDER_ROLLS = ("l_shoulder_roll", "r_shoulder_roll")


class FootSpacingLimit(Limit):
    """Lateral distance of the soles, in the base frame, >= minimum (legs do not cross)."""

    def __init__(self, robot: Robot, minimum: float):
        self.model = robot.model
        self.left, self.right = robot.frame_id(LEFT_SOLE), robot.frame_id(RIGHT_SOLE)
        self.base = robot.model.getFrameId("root_link")
        self.minimum = minimum

    def compute_qp_inequalities(self, configuration, dt):
        data = configuration.data
        world = pin.LOCAL_WORLD_ALIGNED
        jacobian = (
            pin.getFrameJacobian(self.model, data, self.left, world)[:3]
            - pin.getFrameJacobian(self.model, data, self.right, world)[:3]
        )
        rotation = data.oMf[self.base].rotation
        lateral = rotation[:, 1]
        distance = lateral @ (data.oMf[self.left].translation - data.oMf[self.right].translation)
        row = lateral @ jacobian
        row[:6] = 0.0  # a distance in the base frame does not change when the base moves
        return -row[None], np.array([distance - self.minimum])


class FloorLimit(Limit):
    """Every sole corner stays at or above the floor (z >= 0), linearised. The sole targets
    are costs traded against the legs' segment targets, and costs alone let soles through
    the floor (docs/retargeting.md; the whole data set had a sole corner 12.8 cm under it)."""

    def __init__(self, robot: Robot):
        self.model = robot.model
        self.frames = (robot.frame_id(LEFT_SOLE), robot.frame_id(RIGHT_SOLE))

    def compute_qp_inequalities(self, configuration, dt):
        data = configuration.data
        rows, heights = [], []
        for frame in self.frames:
            placement = data.oMf[frame]
            jacobian = pin.getFrameJacobian(self.model, data, frame, pin.LOCAL_WORLD_ALIGNED)
            for offset in corner_offsets(placement.rotation):
                # z of v + omega x r: v_z + omega_x r_y - omega_y r_x
                rows.append(jacobian[2] + offset[1] * jacobian[3] - offset[0] * jacobian[4])
                heights.append(placement.translation[2] + offset[2])
        return -np.array(rows), np.array(heights)


class RetargetIK:
    """Stateful IK: call `solve(pelvis_pose, segment_rotations)` once per frame, in order."""

    def __init__(self, robot: Robot, params: RetargetParams, rate_hz: float):
        self.robot = robot
        self.params = params
        self.dt = 1.0 / rate_hz
        model = pin.Model(robot.model)  # tightened copy: minimum shoulder roll
        for name in SHOULDER_ROLLS:
            index = robot.q_index[JOINT_NAMES.index(name)]
            model.lowerPositionLimit[index] = max(
                model.lowerPositionLimit[index], params.min_shoulder_roll
            )
        self.model = model
        self.lower, self.upper = model.lowerPositionLimit, model.upperPositionLimit
        step = params.gain_time_step
        self.pelvis_task = FrameTask(
            "data_Pelvis",
            position_cost=params.pelvis_position_weight,
            orientation_cost=params.pelvis_orientation_weight,
            gain=min(1.0, params.pelvis_gain * step),
        )
        self.segment_tasks = [
            FrameTask(
                f"data_{segment}",
                position_cost=0.0,
                orientation_cost=params.trunk_weight
                if segment in ("T8", "Head")
                else params.segment_weight,
                gain=min(1.0, params.segment_gain * step),
            )
            for segment in SEGMENTS[1:]
        ]
        self.foot_tasks = [self.segment_tasks[SEGMENTS.index(f) - 1] for f in FEET]
        # the soles track their planned poses exactly each frame (gain 1)
        self.sole_tasks = [
            FrameTask(frame, position_cost=1.0, orientation_cost=1.0, gain=1.0)
            for frame in (LEFT_SOLE, RIGHT_SOLE)
        ]
        self.posture_task = PostureTask(cost=params.posture_cost)
        self.limits = [
            ConfigurationLimit(model),
            FootSpacingLimit(robot, params.min_foot_spacing),
        ]
        # with planned soles (the second pass) no sole corner goes under the floor
        self.limits_with_soles = [*self.limits, FloorLimit(robot)]
        self.configuration: pink.Configuration | None = None

    def reset(self, q: np.ndarray) -> None:
        q = np.clip(q, self.lower, self.upper)
        q[3:7] /= np.linalg.norm(q[3:7])
        self.configuration = pink.Configuration(self.model, self.model.createData(), q)
        self.posture_task.set_target(self.robot.standing_configuration())

    def solve(
        self,
        pelvis: pin.SE3,
        rotations: np.ndarray,
        soles: tuple[pin.SE3, pin.SE3] | None = None,
        sole_weights: tuple[float, float] = (1.0, 1.0),
    ) -> np.ndarray:
        """One frame: the pelvis target pose and the 12 other segments' world rotations (in
        SEGMENTS order) -> q. Without `soles` the pelvis pose is a hard constraint and the
        feet follow their segment targets (the first pass of retarget_motion); with the two
        sole target poses (and their costs) the pelvis is a cost and the soles replace the
        foot segments."""
        if self.configuration is None:
            q = self.robot.standing_configuration()
            q[:3] = pelvis.translation
            q[3:7] = pin.Quaternion(pelvis.rotation).coeffs()
            self.reset(q)
        configuration = self.configuration
        self.pelvis_task.set_target(pelvis)
        for task, rotation in zip(self.segment_tasks, rotations, strict=True):
            task.set_target(pin.SE3(rotation, np.zeros(3)))
        if soles is None:
            tasks, constraints = [*self.segment_tasks, self.posture_task], [self.pelvis_task]
        else:
            for task, target, weight in zip(self.sole_tasks, soles, sole_weights, strict=True):
                task.set_position_cost(weight)
                task.set_orientation_cost(weight)
                task.set_target(target)
            limbs = [t for t in self.segment_tasks if t not in self.foot_tasks]
            tasks = [self.pelvis_task, *limbs, *self.sole_tasks, self.posture_task]
            constraints = []
        limits = self.limits if soles is None else self.limits_with_soles
        for _ in range(self.params.iterations_per_frame):
            velocity = pink.solve_ik(
                configuration,
                tasks,
                self.dt,
                solver=self.params.solver,
                limits=limits,
                constraints=constraints,
                safety_break=False,
            )
            configuration.integrate_inplace(velocity, self.dt)
        return configuration.q.copy()
