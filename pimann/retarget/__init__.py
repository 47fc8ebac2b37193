"""Whole-body geometric retargeting of human motion onto ergoCub (SPEC 3).

`retarget_motion` resamples the human motion to the output rate, pre-processes the segment
targets, runs the pink IK frame by frame, then replaces the base position by leg odometry.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path

import numpy as np
import pinocchio as pin
from pink.exceptions import PinkError

from pimann.errors import PimannError
from pimann.mocap.human_motion import HumanMotion
from pimann.mocap.resample import resample
from pimann.params import Params, RetargetParams
from pimann.retarget.ik import RetargetIK
from pimann.retarget.odometry import odometry_base_positions, sole_offsets
from pimann.retarget.targets import human_contacts, leg_length_ratio, segment_targets
from pimann.robot import SEGMENTS, load_robot
from pimann.trajectory import Trajectory

log = logging.getLogger(__name__)


def solve_joints(
    motion: HumanMotion, params: RetargetParams, scale: float, contacts: np.ndarray
) -> np.ndarray:
    """(T, nq) IK configurations following the motion (pelvis position scaled)."""
    robot = load_robot("retarget")
    ik = RetargetIK(robot, params, motion.rate_hz or params.rate_hz)
    targets = segment_targets(motion, params, contacts)
    pelvis = SEGMENTS.index("Pelvis")
    configurations = np.empty((motion.n_frames, robot.model.nq))
    for t in range(motion.n_frames):
        placement = pin.SE3(targets[t, pelvis], scale * motion.pelvis_position[t])
        try:
            configurations[t] = ik.solve(placement, targets[t, 1:], tuple(contacts[t]))
        except PinkError as error:  # e.g. the QP has no solution: name the clip and frame
            raise PimannError(motion.source, f"IK failed: {error}", frame=t) from None
    return configurations


def retarget_motion(motion: HumanMotion, params: RetargetParams) -> Trajectory:
    """The robot trajectory (at params.rate_hz) that imitates the human motion."""
    if motion.n_frames < 2:
        raise PimannError(motion.source, f"too short to retarget ({motion.n_frames} frame(s))")
    if abs(motion.rate_hz - params.rate_hz) > 1e-6 * params.rate_hz:
        motion = resample(motion, params.rate_hz)
    robot = load_robot("retarget")
    scale = leg_length_ratio(motion, robot)
    contacts = human_contacts(motion, params)
    log.debug("%s: %d frames, leg scale %.3f", motion.source, motion.n_frames, scale)
    configurations = solve_joints(motion, params, scale, contacts)
    offsets, lowest = sole_offsets(robot, configurations)
    base = odometry_base_positions(offsets, contacts, configurations[:, :3], lowest)
    _, quaternions, joints = zip(*map(robot.split_configuration, configurations), strict=True)
    return Trajectory(
        time=motion.time - motion.time[0],
        base_position=base,
        base_quaternion_xyzw=np.array(quaternions),
        joint_positions=np.array(joints),
        source=Path(motion.source).name,
        rate_hz=params.rate_hz,
        contacts=contacts,
        attrs={"mirrored": bool(motion.mirrored), "scale": scale},
    )


def retarget_file(path: str | Path, params: Params, mirror: bool = False) -> Trajectory:
    """One BVH clip to a trajectory; `mirror` returns the sagittal mirror image instead.

    The retargeted trajectory is mirrored in joint space (exact for ergoCub and half the
    cost of retargeting the mirrored person)."""
    from pimann.mocap.bvh import read_bvh
    from pimann.mocap.mirror import mirror_trajectory

    skeleton = params.data.skeletons[params.data.skeleton]
    trajectory = retarget_motion(read_bvh(path, skeleton), params.retarget)
    return mirror_trajectory(trajectory) if mirror else trajectory


def retarget_clip(
    path: str | Path, params: Params
) -> tuple[str, Trajectory, dict[str, np.ndarray], float]:
    """(clip name, trajectory, per-frame quality measures, CPU seconds spent retargeting):
    the unit of work of the retarget stage and of its speed benchmark."""
    from pimann.mocap.bvh import read_bvh
    from pimann.retarget.quality import frame_measures

    path = Path(path)
    motion = read_bvh(path, params.data.skeletons[params.data.skeleton])
    start = time.process_time()
    trajectory = retarget_motion(motion, params.retarget)
    seconds = time.process_time() - start
    human = resample(motion, params.retarget.rate_hz)
    return path.stem, trajectory, frame_measures(human, trajectory, params.retarget), seconds
