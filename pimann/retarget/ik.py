"""Whole-body differential IK with pink: the robot follows the human segment orientations.

Pelvis pose is a hard equality constraint; the 12 other segments are orientation-only
costs on the robot's `data_<Segment>` frames (the robot is smaller than the person, so
positions of limbs cannot match, orientations can). A small posture cost regularises
redundant directions. The trunk (T8, Head) weighs more than the limbs: where an arm
reaches a joint limit, the chest should not tilt to make up for it. Joint limits, a minimum
shoulder roll and a minimum lateral foot spacing (in the pelvis frame, to keep the legs
apart: the dataset-1 actor walks with the ankles 2.6 cm apart) are QP inequalities. Each
frame runs a few QP iterations warm-started from the previous frame's solution.

Feet in contact (from the person's feet) weigh more, so a planted foot does not turn, and
while both are down their relative pose is held: the leg odometry (odometry.py) pins the
base to one planted foot, and this keeps the other one from sliding.

pink gains are unitless per-iteration low-pass factors in (0, 1]; the paper's gains are
rates (1/s). They are converted as gain * `gain_time_step`, capped at 1.
"""

from __future__ import annotations

import numpy as np
import pink
import pinocchio as pin
from pink.limits import ConfigurationLimit, Limit
from pink.tasks import FrameTask, PostureTask, RelativeFrameTask

from pimann.params import RetargetParams
from pimann.robot import JOINT_NAMES, LEFT_SOLE, RIGHT_SOLE, SEGMENTS, Robot
from pimann.rotations import yaw_only

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
            position_cost=1.0,
            orientation_cost=1.0,
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
        # both feet planted: their relative pose is frozen, so neither slides under odometry
        self.feet_task = RelativeFrameTask(
            RIGHT_SOLE,
            LEFT_SOLE,
            position_cost=params.double_support_weight,
            orientation_cost=params.stance_foot_weight,
            gain=1.0,
        )
        self.double_support = False
        self.posture_task = PostureTask(cost=params.posture_cost)
        self.limits = [
            ConfigurationLimit(model),
            FootSpacingLimit(robot, params.min_foot_spacing),
        ]
        self.configuration: pink.Configuration | None = None

    def reset(self, q: np.ndarray) -> None:
        q = np.clip(q, self.lower, self.upper)
        q[3:7] /= np.linalg.norm(q[3:7])
        self.configuration = pink.Configuration(self.model, self.model.createData(), q)
        self.posture_task.set_target(self.robot.standing_configuration())

    def solve(
        self, pelvis: pin.SE3, rotations: np.ndarray, stance: tuple[bool, bool] = (False, False)
    ) -> np.ndarray:
        """One frame: pelvis pose and the 12 other segments' world rotations -> q. A foot in
        `stance` (left, right) weighs stance_foot_weight: a planted foot should not turn; with
        both feet planted, their relative pose stays as it was when the second one landed."""
        if self.configuration is None:
            q = self.robot.standing_configuration()
            q[:3] = pelvis.translation
            q[3:7] = pin.Quaternion(pelvis.rotation).coeffs()
            self.reset(q)
        configuration = self.configuration
        self.pelvis_task.set_target(pelvis)
        for task, rotation in zip(self.segment_tasks, rotations, strict=True):
            task.set_target(pin.SE3(rotation, np.zeros(3)))
        for task, planted in zip(self.foot_tasks, stance, strict=True):
            weight = self.params.stance_foot_weight if planted else self.params.segment_weight
            task.set_orientation_cost(weight)
        tasks = [*self.segment_tasks, self.posture_task]
        double_support = bool(stance[0] and stance[1])
        if double_support and not self.double_support:
            self.feet_task.set_target(self._flat_feet_transform())
        if double_support:
            tasks.append(self.feet_task)
        self.double_support = double_support
        for _ in range(self.params.iterations_per_frame):
            velocity = pink.solve_ik(
                configuration,
                tasks,
                self.dt,
                solver=self.params.solver,
                limits=self.limits,
                constraints=[self.pelvis_task],
                safety_break=False,
            )
            configuration.integrate_inplace(velocity, self.dt)
        return configuration.q.copy()

    def _flat_feet_transform(self) -> pin.SE3:
        """Right sole in the left sole's frame, both feet laid flat on the floor."""
        flat = []
        for frame in (LEFT_SOLE, RIGHT_SOLE):
            placement = self.configuration.get_transform_frame_to_world(frame)
            on_floor = placement.translation * np.array([1.0, 1.0, 0.0])
            flat.append(pin.SE3(yaw_only(placement.rotation), on_floor))
        return flat[0].actInv(flat[1])
