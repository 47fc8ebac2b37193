"""Whole-body geometric retargeting of human motion onto ergoCub (docs/retargeting.md).

`retarget_motion` resamples the human motion to the output rate, finds the person's foot
contacts and plans the robot's soles from them (feet.py), pre-processes the segment
targets, then runs the pink IK frame by frame: planted soles stay put, the base follows.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path

import numpy as np
import pinocchio as pin
from pink.exceptions import PinkError

from pimann.core.contacts import FootKinematics, foot_kinematics
from pimann.core.errors import PimannError
from pimann.core.params import Params, RetargetParams
from pimann.core.robot import SEGMENTS, Robot, load_robot
from pimann.core.rotations import rot_z, yaw_of
from pimann.core.trajectory import Trajectory
from pimann.mocap.clips import Clip, Take, clip_motion, read_take, take_clips, take_of
from pimann.mocap.human_motion import HumanMotion
from pimann.mocap.resample import resample
from pimann.retarget.feet import human_contacts, plan_soles
from pimann.retarget.ik import RetargetIK
from pimann.retarget.targets import leg_length_ratio, segment_targets

log = logging.getLogger(__name__)


def solve_joints(
    motion: HumanMotion, params: RetargetParams, scale: float, contacts: np.ndarray
) -> np.ndarray:
    """(T, nq) IK configurations following the motion, in two passes. The first copies the
    person (pelvis pose held, segment orientations followed): where its soles stand during
    each contact is where the robot's own legs put its footsteps. The second pins the soles
    on that plan (feet.py) and lets the base follow; mid-swing, a sole goes where the first
    pass put it relative to the base."""
    robot = load_robot("retarget")
    rate = motion.rate_hz or params.rate_hz
    pelvis = SEGMENTS.index("Pelvis")
    placements = [
        pin.SE3(rotation, scale * position)
        for rotation, position in zip(
            motion.orientations[:, pelvis], motion.pelvis_position, strict=True
        )
    ]
    targets = segment_targets(motion, params)
    first = RetargetIK(robot, params, rate)
    free = np.array(
        [_solve(first, motion, t, placements[t], targets[t, 1:]) for t in range(motion.n_frames)]
    )
    soles = foot_kinematics(robot, free)
    plan = plan_soles(soles.positions, yaw_of(soles.rotations), contacts, motion.time, params)
    targets = segment_targets(motion, params, plan.headings)
    sole_rotations = rot_z(plan.headings)
    copied = soles_in_base(free, soles)
    second = RetargetIK(robot, params, rate)
    second.reset(free[0])
    configurations = np.empty_like(free)
    for t in range(motion.n_frames):
        planned = [pin.SE3(sole_rotations[t, k], plan.positions[t, k]) for k in range(2)]
        if t >= 2 and plan.leg_following[t].any():
            # mid-swing the sole goes where the person's leg puts it relative to the base
            # (the base extrapolated from the last two frames), at the plan's height
            base = _base_pose(robot, configurations[t - 1], configurations[t - 2])
            for k in np.flatnonzero(plan.leg_following[t]):
                share, leg = plan.leg_following[t, k], base * copied[t][k]
                target = planned[k]
                target.translation[:2] += share * (leg.translation[:2] - target.translation[:2])
                turn = pin.log3(target.rotation.T @ leg.rotation)
                target.rotation = target.rotation @ pin.exp3(share * turn)
        configurations[t] = _solve(
            second,
            motion,
            t,
            placements[t],
            targets[t, 1:],
            tuple(planned),
            tuple(plan.weights[t]),
        )
    return configurations


def soles_in_base(configurations: np.ndarray, soles: FootKinematics) -> list[list[pin.SE3]]:
    """Per frame, the soles' poses (`soles`, world) in the base frame (left, right)."""
    out = []
    for t, q in enumerate(configurations):
        base = pin.XYZQUATToSE3(q[:7]).inverse()  # the floating base is the root_link frame
        out.append([base * pin.SE3(soles.rotations[t, k], soles.positions[t, k]) for k in (0, 1)])
    return out


def _base_pose(robot: Robot, last: np.ndarray, before: np.ndarray) -> pin.SE3:
    """The base pose one frame after `last`, at its velocity from `before` to `last`."""
    return pin.XYZQUATToSE3(
        pin.integrate(robot.model, last, pin.difference(robot.model, before, last))[:7]
    )


def _solve(ik: RetargetIK, motion: HumanMotion, t: int, *args) -> np.ndarray:
    try:
        return ik.solve(*args)
    except PinkError as error:  # e.g. the QP has no solution: name the clip and frame
        raise PimannError(motion.source, f"IK failed: {error}", frame=t) from None


def retarget_motion(motion: HumanMotion, params: RetargetParams) -> Trajectory:
    """The robot trajectory (at params.rate_hz) that imitates the human motion; its contact
    flags are the person's foot contacts, during which the robot's soles stay put."""
    if motion.n_frames < 2:
        raise PimannError(motion.source, f"too short to retarget ({motion.n_frames} frame(s))")
    if abs(motion.rate_hz - params.rate_hz) > 1e-6 * params.rate_hz:
        motion = resample(motion, params.rate_hz)
    robot = load_robot("retarget")
    scale = leg_length_ratio(motion, robot)
    contacts = human_contacts(motion, params)
    log.debug("%s: %d frames, leg scale %.3f", motion.source, motion.n_frames, scale)
    configurations = solve_joints(motion, params, scale, contacts)
    base, quaternions, joints = zip(*map(robot.split_configuration, configurations), strict=True)
    return Trajectory(
        time=motion.time - motion.time[0],
        base_position=np.array(base),
        base_quaternion_xyzw=np.array(quaternions),
        joint_positions=np.array(joints),
        source=Path(motion.source).name,
        rate_hz=params.rate_hz,
        contacts=contacts,
        attrs={"mirrored": bool(motion.mirrored), "scale": scale},
    )


def _retarget_span(
    clip: Clip, motion: HumanMotion, params: RetargetParams
) -> tuple[Trajectory, float]:
    """(trajectory, CPU seconds) of a clip's motion, labelled with the clip's take; its
    `source` is the take's file name, which keeps a take's clips on one side of the split."""
    take = clip.take
    start = time.process_time()
    trajectory = retarget_motion(motion, params)
    seconds = time.process_time() - start
    trajectory.source = take.path.name
    trajectory.attrs.update(
        dataset=take.source,
        take=take.name,
        content=take.content or "",
        style=take.style or "",
        clip_start_s=clip.start_s,
    )
    return trajectory, seconds


def retarget_file(path: str | Path, params: Params, mirror: bool = False) -> Trajectory:
    """One mocap file, whole, to a trajectory (read as the source its path belongs to);
    `mirror` returns the sagittal mirror image instead.

    The retargeted trajectory is mirrored in joint space (exact for ergoCub and half the
    cost of retargeting the mirrored person)."""
    from pimann.mocap.mirror import mirror_trajectory

    take = take_of(path, params.data)
    motion = read_take(take)
    clip = Clip(take, 0.0, motion.duration, take.name)
    trajectory, _ = _retarget_span(clip, motion, params.retarget)
    return mirror_trajectory(trajectory) if mirror else trajectory


def retarget_clip(
    take: Take, params: Params
) -> list[tuple[str, Trajectory, dict[str, np.ndarray], float]]:
    """The retarget stage's unit of work on one take: the file read once and cut into clips,
    and per clip (name, trajectory, per-frame quality measures, CPU seconds retargeting)."""
    from pimann.retarget.quality import frame_measures

    motion = read_take(take)
    results = []
    for clip in take_clips(take, motion, take.clip_s, take.max_speed):
        part = clip_motion(motion, clip)
        trajectory, seconds = _retarget_span(clip, part, params.retarget)
        human = resample(part, params.retarget.rate_hz)
        measures = frame_measures(human, trajectory, params.retarget)
        results.append((clip.name, trajectory, measures, seconds))
    return results
