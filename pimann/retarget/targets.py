"""Human motion -> IK targets: the authors' pre-processing, foot contacts and body scale.

The robot cannot copy everything a person does: its feet are rigid plates (so the foot
targets are made horizontal, keeping only their heading), its head follows the chest (the
head target keeps the T8's roll and pitch and its own yaw), and its legs must not cross
(the upper legs' rolls are spread apart), its elbows are hinges (the forearm target keeps
only the flexion about the upper arm's z axis: the person's forearm twist and carrying
angle would otherwise pull the shoulder away from the upper-arm target), and its arms
must clear the torso (arm targets closer to the body than the minimum shoulder roll
allows are lifted sideways, so the IK does not tilt the chest to make up for the arms).
The shoulder roll and the feet spacing are also IK inequalities (see ik.py), as a backstop.
"""

from __future__ import annotations

from functools import cache

import numpy as np
import pinocchio as pin

from pimann.core.params import RetargetParams
from pimann.core.robot import JOINT_NAMES, SEGMENTS, Robot, load_robot
from pimann.core.rotations import rot_z, yaw_only
from pimann.mocap.human_motion import HumanMotion

FEET = ("LeftFoot", "RightFoot")


def segment_targets(
    motion: HumanMotion, params: RetargetParams, sole_headings: np.ndarray | None = None
) -> np.ndarray:
    """(T, 13, 3, 3) target orientations after the pre-processing chosen in params; with
    `sole_headings` (T, 2) the flat feet take the planned headings (feet.py)."""
    targets = motion.orientations.copy()
    if params.flat_feet:
        for side, foot in enumerate(FEET):
            k = SEGMENTS.index(foot)
            yaw = np.arctan2(targets[:, k, 1, 0], targets[:, k, 0, 0])
            if sole_headings is not None:
                yaw = sole_headings[:, side]
            targets[:, k] = rot_z(yaw)
    if params.min_leg_roll_spread > -np.pi:
        spread_legs(targets, params.min_leg_roll_spread)
    if params.elbow_hinge:
        hinge_elbows(targets)
    if params.min_shoulder_roll > -np.pi:
        abduct_arms(targets, min_arm_abduction(params.min_shoulder_roll))
    if params.head_from_t8:
        # head = Rz(head yaw) * (T8 without its yaw): T8's roll and pitch, the head's heading
        t8 = targets[:, SEGMENTS.index("T8")]
        head = SEGMENTS.index("Head")
        t8_tilt = np.swapaxes(yaw_only(t8), -1, -2) @ t8
        targets[:, head] = yaw_only(targets[:, head]) @ t8_tilt
    return targets


def leg_length_ratio(motion: HumanMotion, robot: Robot) -> float:
    """Robot thigh + shank length over the person's (median over frames)."""
    p = motion.segment_positions
    idx = [SEGMENTS.index(s) for s in ("LeftUpperLeg", "LeftLowerLeg", "LeftFoot")]
    human = np.median(
        np.linalg.norm(p[:, idx[0]] - p[:, idx[1]], axis=-1)
        + np.linalg.norm(p[:, idx[1]] - p[:, idx[2]], axis=-1)
    )
    return robot_leg_length(robot) / float(human)


def robot_leg_length(robot: Robot) -> float:
    data = robot.model.createData()
    pin.forwardKinematics(robot.model, data, pin.neutral(robot.model))
    joint = [robot.model.getJointId(n) for n in ("l_hip_pitch", "l_knee", "l_ankle_pitch")]
    hip, knee, ankle = (data.oMi[j].translation for j in joint)
    return float(np.linalg.norm(hip - knee) + np.linalg.norm(knee - ankle))


def rot_x(angle: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    out = np.zeros((*np.shape(angle), 3, 3))
    out[..., 1, 1], out[..., 1, 2], out[..., 2, 1], out[..., 2, 2] = c, -s, s, c
    out[..., 0, 0] = 1.0
    return out


def spread_legs(targets: np.ndarray, minimum: float) -> None:
    """In place: where the upper legs' roll difference (in the pelvis frame, abduction
    positive on the left) is below `minimum`, roll each leg (thigh and shank) outward by
    half the deficit about the pelvis's forward axis."""
    pelvis = targets[:, SEGMENTS.index("Pelvis")]
    thighs = [SEGMENTS.index("LeftUpperLeg"), SEGMENTS.index("RightUpperLeg")]
    rolls = []
    for k in thighs:
        relative = np.swapaxes(pelvis, -1, -2) @ targets[:, k]
        rolls.append(np.arctan2(relative[:, 2, 1], relative[:, 2, 2]))  # ZYX roll
    deficit = np.maximum(minimum - (rolls[0] - rolls[1]), 0.0)
    for side, sign in (("Left", 1.0), ("Right", -1.0)):
        # rotation about the pelvis x axis, written in world axes
        turn = pelvis @ rot_x(sign * deficit / 2.0) @ np.swapaxes(pelvis, -1, -2)
        for segment in ("UpperLeg", "LowerLeg"):
            k = SEGMENTS.index(side + segment)
            targets[:, k] = turn @ targets[:, k]


ARM_MARGIN = 0.03  # rad of abduction above the robot's limit pose: keeps the joint bound slack


@cache
def min_arm_abduction(min_shoulder_roll: float) -> float:
    """Angle (rad) between the robot's upper arm and its chest's sagittal plane when the
    shoulder roll is at its minimum and the other joints stand (plus a small margin)."""
    robot = load_robot("retarget")
    q = robot.standing_configuration()
    q[robot.q_index[JOINT_NAMES.index("l_shoulder_roll")]] = min_shoulder_roll
    chest = robot.frame_placement(q, "data_T8").rotation
    arm = robot.frame_placement(q, "data_LeftUpperArm").rotation
    return float(np.arcsin(np.clip(chest[:, 1] @ arm[:, 1], -1.0, 1.0))) + ARM_MARGIN


def abduct_arms(targets: np.ndarray, minimum: float) -> None:
    """In place: lift arms whose upper arm is closer than `minimum` (rad) to the chest's
    sagittal plane outward, about the chest's forward axis, with the forearm.

    With XSens frames (the arm's y axis points left on both sides in the T-pose), the
    abduction of either arm is asin(y_chest . y_arm); the left arm rises about +x, the
    right one about -x."""
    chest = targets[:, SEGMENTS.index("T8")]
    for side, sign in (("Left", 1.0), ("Right", -1.0)):
        arm = targets[:, SEGMENTS.index(side + "UpperArm")]
        abduction = np.arcsin(np.clip(np.einsum("ti,ti->t", chest[:, :, 1], arm[:, :, 1]), -1, 1))
        deficit = np.maximum(minimum - abduction, 0.0)
        turn = chest @ rot_x(sign * deficit) @ np.swapaxes(chest, -1, -2)
        for segment in ("UpperArm", "ForeArm"):
            k = SEGMENTS.index(side + segment)
            targets[:, k] = turn @ targets[:, k]


def hinge_elbows(targets: np.ndarray) -> None:
    """In place: forearm = upper arm * Rz(flexion), the flexion being the twist about z of
    the forearm relative to the upper arm (swing-twist decomposition). In XSens frames
    both elbows flex about the upper arm's z axis (left negative, right positive); a
    straight arm stays straight (no hyperextension, which the robot lacks)."""
    for side, sign in (("Left", -1.0), ("Right", 1.0)):
        upper = targets[:, SEGMENTS.index(side + "UpperArm")]
        k = SEGMENTS.index(side + "ForeArm")
        relative = np.swapaxes(upper, -1, -2) @ targets[:, k]
        # twist about z of a rotation R: angle of the quaternion's (w, z) part
        w = 0.5 * np.sqrt(np.maximum(1.0 + np.trace(relative, axis1=-2, axis2=-1), 0.0))
        z4w = relative[:, 1, 0] - relative[:, 0, 1]  # = 4 w z
        flexion = sign * np.maximum(sign * 2.0 * np.arctan2(z4w, 4.0 * w * w), 0.0)
        targets[:, k] = upper @ rot_z(flexion)
