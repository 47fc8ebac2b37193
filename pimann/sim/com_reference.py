"""The generated CoM mapped onto the robot's footstep plan: the DCM plan's CoM reference.

The offline DCM/ZMP adjustment keeps the CoM on the linear inverted pendulum; this reference
keeps it close to the CoM the network generated. The generated CoM is taken
relative to the generated feet, not in the world, because the robot walks a rescaled path
(`step_scale`) at a slower pace (`speed_scale`) from its own standing feet: in world
coordinates the two CoMs drift apart with every step.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from pimann.core.errors import PimannError
from pimann.core.params import SimulateParams
from pimann.core.robot import Robot
from pimann.core.rotations import from_heading_frame, to_heading_frame
from pimann.core.trajectory import Trajectory
from pimann.sim.dcm import SHIFT_MAX
from pimann.sim.footsteps import FootstepPlan, mid_feet, sole_trajectories


def generated_com_offsets(robot: Robot, trajectory: Trajectory) -> np.ndarray:
    """(T, 2) the generated CoM in its mid-feet frame (forward, left), from pinocchio.

    CoM and soles come from the same model, so the offset does not depend on how the
    retargeting and the simulation models' masses differ from each other.
    """
    com = np.empty((len(trajectory), 2))
    for k in range(len(trajectory)):
        q = robot.configuration(
            trajectory.base_position[k],
            trajectory.base_quaternion_xyzw[k],
            trajectory.joint_positions[k],
        )
        com[k] = pin.centerOfMass(robot.model, robot.data, q)[:2]
    mid = mid_feet(sole_trajectories(robot, trajectory))
    return to_heading_frame(com - mid[:, :2], mid[:, 2])


def _smoothstep(s: np.ndarray) -> np.ndarray:
    s = np.clip(s, 0.0, 1.0)
    return s * s * (3.0 - 2.0 * s)


def com_reference(
    robot: Robot,
    trajectory: Trajectory,
    plan: FootstepPlan,
    params: SimulateParams,
    times: np.ndarray,
) -> np.ndarray:
    """(n+1, 2) horizontal CoM reference at the robot times `times` (the DCM plan's knots).

    Robot time t replays generated time `plan.generated_time(t)`; the generated CoM offset
    from the generated mid-feet pose is interpolated there and put on the robot's planned
    mid-feet pose at t. The forward offset is scaled by `step_scale` like every step
    (the CoM leads the feet by a fraction of the step). The lateral offset is kept: the
    footsteps keep the stance width (the robot's own, equal to the generated one within
    a mm), and the sway is what brings the CoM over the stance foot; 0.4x of it would pull
    the CoM toward the swinging foot, against the ZMP's support constraint.

    In the initial and final holds the reference is the planned mid-feet point (standing);
    the offset fades in over the last `SHIFT_MAX` s of the initial hold and out over the
    first `SHIFT_MAX` s of the final one (smoothstep), so the reference is continuous even
    when the clip starts or ends mid-stride, as the ZMP reference does in dcm.
    """
    times = np.asarray(times, dtype=float)
    if times.ndim != 1 or len(times) < 2 or np.any(np.diff(times) <= 0):
        raise PimannError(trajectory.source, "CoM reference knots must be increasing times")
    if len(trajectory) < 2:
        raise PimannError(trajectory.source, "trajectory too short for a CoM reference")
    generated_time = np.asarray(trajectory.time, dtype=float)
    offsets = generated_com_offsets(robot, trajectory)
    replayed = np.array([plan.generated_time(t) for t in times])
    offset = np.column_stack([np.interp(replayed, generated_time, offsets[:, i]) for i in (0, 1)])
    offset[:, 0] *= params.step_scale
    end = plan.hold + (generated_time[-1] - generated_time[0]) / plan.speed_scale
    fade_in = min(SHIFT_MAX, plan.hold)
    fade_out = min(SHIFT_MAX, max(plan.duration - end, 0.0))
    weight = np.ones(len(times))
    if fade_in > 0:
        weight *= _smoothstep((times - (plan.hold - fade_in)) / fade_in)
    if fade_out > 0:
        weight *= 1.0 - _smoothstep((times - end) / fade_out)
    else:
        weight[times > end] = 0.0
    feet = np.array(
        [[(*pose[:2], yaw) for pose, yaw in (plan.foot_pose(s, t) for s in (0, 1))] for t in times]
    )
    mid = mid_feet(feet)
    return mid[:, :2] + from_heading_frame(weight[:, None] * offset, mid[:, 2])
