"""Pictures of a trajectory: the robot as a stick figure, beside the person it was retargeted from.

A person has to be able to see at a glance that the robot walks like the person did, so the
two are drawn side by side at one scale, seen from the same fixed world direction, each
panel following its own subject (the robot covers ~0.63x the human's distance, so one shared
world view would pull them apart). Left limbs are blue and right limbs red in both panels.

Drawing is a hand-made orthographic projection onto plain 2-D matplotlib axes rather than
mplot3d: a stick figure needs no hidden-surface removal beyond drawing far bones first, and
reusing one Agg figure whose artists are only updated keeps a frame at a few milliseconds
(pimann.render.scene). Files: pimann.render.picture_files (strips wrap into rows of four).
Reading the person from a mocap file: pimann.render.beside_mocap.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Protocol

import numpy as np
import pinocchio as pin

from pimann.core.contacts import detect_contacts, trajectory_configurations
from pimann.core.errors import PimannError
from pimann.core.params import ContactParams
from pimann.core.robot import LEFT_SOLE, RIGHT_SOLE, SEGMENTS, SOLE_CORNERS, Robot, load_robot
from pimann.core.trajectory import Trajectory
from pimann.render.picture_files import FORMATS, STRIP_COLUMNS, check_output, write_pictures
from pimann.render.scene import CENTRE_COLOUR, LEFT_COLOUR, RIGHT_COLOUR, Scene, Skeleton

log = logging.getLogger(__name__)


class DrawnPerson(Protocol):
    """What drawing a person reads of pimann.mocap.human_motion.HumanMotion; named here, not
    imported, so that the simulation's videos (pimann.sim.video) draw without the mocap readers
    (and the simulate stage does not rerun when they change)."""

    time: np.ndarray
    source: str
    segment_positions: np.ndarray
    orientations: np.ndarray
    pelvis_position: np.ndarray
    mirrored: bool


__all__ = [
    "FORMATS",
    "LEFT_COLOUR",
    "RIGHT_COLOUR",
    "STRIP_FRAMES",
    "Skeleton",
    "check_output",
    "human_skeleton",
    "match_frames",
    "render_trajectory",
    "robot_skeleton",
    "strip_frame_indices",
    "write_pictures",
]

STRIP_FRAMES = 12  # frames of a .png strip: one about every step of a 10 s walk
STRIP_SIZE = (480, 320)  # px of each strip frame (an animation's default: 960 x 480)
ANIMATION_SIZE = (960, 480)

# ergoCub's sole (pimann.core.robot), corners in drawing order around the rectangle
FOOT_CORNERS = SOLE_CORNERS[[0, 1, 3, 2]]
ROBOT_HEAD_TOP = np.array([0.0, 0.0, 0.2])  # head frame (z up) to the top of the head, m

# Human end points in segment frames (XSens T-pose convention: x forward, y left, z up), for
# a person whose thigh + shank measure HUMAN_LEG_LENGTH; scaled to the actual legs.
HUMAN_LEG_LENGTH = 0.88
HUMAN_ENDS = {
    "HeadTop": ("Head", (0.0, 0.0, 0.2)),
    "LeftHand": ("LeftForeArm", (0.0, 0.22, 0.0)),
    "RightHand": ("RightForeArm", (0.0, -0.22, 0.0)),
    "LeftToe": ("LeftFoot", (0.16, 0.0, -0.07)),
    "RightToe": ("RightFoot", (0.16, 0.0, -0.07)),
}
HUMAN_BONES = (
    ("Pelvis", "T8"), ("T8", "Head"), ("Head", "HeadTop"),
    ("Pelvis", "LeftUpperLeg"), ("LeftUpperLeg", "LeftLowerLeg"),
    ("LeftLowerLeg", "LeftFoot"), ("LeftFoot", "LeftToe"),
    ("Pelvis", "RightUpperLeg"), ("RightUpperLeg", "RightLowerLeg"),
    ("RightLowerLeg", "RightFoot"), ("RightFoot", "RightToe"),
    ("T8", "LeftUpperArm"), ("LeftUpperArm", "LeftForeArm"), ("LeftForeArm", "LeftHand"),
    ("T8", "RightUpperArm"), ("RightUpperArm", "RightForeArm"), ("RightForeArm", "RightHand"),
)  # fmt: skip


def _side_colour(name: str) -> str:
    if name.startswith(("l_", "Left")):
        return LEFT_COLOUR
    if name.startswith(("r_", "Right")):
        return RIGHT_COLOUR
    return CENTRE_COLOUR


def robot_skeleton(
    trajectory: Trajectory,
    frames: np.ndarray,
    robot: Robot | None = None,
    contacts: ContactParams | None = None,
) -> Skeleton:
    """Joint origins, sole rectangles, hands and head top of the robot at `frames`; the soles'
    contacts are the file's, else detected by the `contacts` rule (params.yaml `contacts`)."""
    robot = robot or load_robot("retarget")
    model = robot.model
    data = model.createData()  # private: the cached Robot's data may be in use elsewhere
    joint_ids = list(range(1, model.njoints))  # the free flyer and the 26 joints
    index = {j: k for k, j in enumerate(joint_ids)}
    bones = [(index[model.parents[j]], index[j]) for j in joint_ids if model.parents[j] > 0]
    colours = [_side_colour(model.names[j]) for j in joint_ids if model.parents[j] > 0]
    leaves = [
        (LEFT_SOLE, None),
        (RIGHT_SOLE, None),
        ("l_hand_palm", None),
        ("r_hand_palm", None),
        ("head", ROBOT_HEAD_TOP),
    ]
    leaf_ids = [robot.frame_id(name) for name, _ in leaves]
    for k, (name, _) in enumerate(leaves):
        bones.append((index[model.frames[leaf_ids[k]].parentJoint], len(joint_ids) + k))
        colours.append(_side_colour(name))
    sole_ids = leaf_ids[:2]

    points = np.empty((len(frames), len(joint_ids) + len(leaves), 3))
    feet = np.empty((len(frames), 2, 4, 3))
    configurations = trajectory_configurations(robot, trajectory)
    for n, t in enumerate(frames):
        q = configurations[t]
        pin.forwardKinematics(model, data, q)
        for k, j in enumerate(joint_ids):
            points[n, k] = data.oMi[j].translation
        for k, ((_, offset), fid) in enumerate(zip(leaves, leaf_ids, strict=True)):
            placement = pin.updateFramePlacement(model, data, fid)
            tip = placement.translation
            if offset is not None:
                tip = tip + placement.rotation @ offset
            points[n, len(joint_ids) + k] = tip
        for side, fid in enumerate(sole_ids):
            placement = data.oMf[fid]
            feet[n, side] = FOOT_CORNERS @ placement.rotation.T + placement.translation
    rule = contacts
    if trajectory.contacts is not None:
        contacts = np.asarray(trajectory.contacts, dtype=bool)[frames]
    elif rule is not None:  # the evaluation's own detector, so the picture agrees with the metrics
        contacts = detect_contacts(robot, trajectory, rule)[frames]
    else:
        raise PimannError(trajectory.source, "has no contact flags and no contact rule is given")
    return Skeleton(
        title="ergoCub",
        points=points,
        bones=np.array(bones),
        bone_colours=colours,
        path=np.asarray(trajectory.base_position)[:, :2],
        path_index=np.asarray(frames),
        feet=feet,
        contacts=contacts,
    )


def human_skeleton(human: DrawnPerson, frames: np.ndarray) -> Skeleton:
    """The person's segment origins plus head top, hands and toes at `frames`."""
    positions = human.segment_positions[frames]
    seg = {name: k for k, name in enumerate(SEGMENTS)}
    first = human.segment_positions[0]
    leg = np.mean(
        [
            np.linalg.norm(first[seg[f"{s}UpperLeg"]] - first[seg[f"{s}LowerLeg"]])
            + np.linalg.norm(first[seg[f"{s}LowerLeg"]] - first[seg[f"{s}Foot"]])
            for s in ("Left", "Right")
        ]
    )
    scale = leg / HUMAN_LEG_LENGTH if leg > 0 else 1.0
    ends = [
        positions[:, seg[parent]]
        + scale * np.einsum("nij,j->ni", human.orientations[frames, seg[parent]], offset)
        for parent, offset in HUMAN_ENDS.values()
    ]
    points = np.concatenate([positions, np.stack(ends, axis=1)], axis=1)
    names = list(SEGMENTS) + list(HUMAN_ENDS)
    bones = np.array([(names.index(a), names.index(b)) for a, b in HUMAN_BONES])
    return Skeleton(
        title="human" + (" (mirrored)" if human.mirrored else ""),
        points=points,
        bones=bones,
        bone_colours=[_side_colour(b) for _, b in HUMAN_BONES],
        path=human.pelvis_position[:, :2],
        path_index=np.asarray(frames),
    )


def match_frames(times: np.ndarray, source_times: np.ndarray) -> np.ndarray:
    """Index of the source frame nearest each time. Clocks that do not overlap (one file
    stamped from 0, the other with the recording's clock) are aligned at their starts."""
    times = np.asarray(times, dtype=float)
    source = np.asarray(source_times, dtype=float)
    if times[0] > source[-1] or times[-1] < source[0]:
        times = times - times[0] + source[0]
    right = np.clip(np.searchsorted(source, times), 1, len(source) - 1)
    left = right - 1
    nearer_left = np.abs(times - source[left]) <= np.abs(source[right] - times)
    return np.where(nearer_left, left, right) if len(source) > 1 else np.zeros_like(right)


def strip_frame_indices(count: int, frames: int) -> np.ndarray:
    """`frames` indices evenly over `count` samples, first and last included (fewer when the
    clip is shorter)."""
    return np.unique(np.linspace(0, count - 1, frames).round().astype(int))


def clip_rate(clock: np.ndarray) -> float:
    """Samples per second of a clip's clock (25 for a single sample)."""
    duration = clock[-1] - clock[0] if len(clock) > 1 else 0.0
    return (len(clock) - 1) / duration if duration > 0 else 25.0


def render_trajectory(
    trajectory: Trajectory | None,
    output_path: str | Path,
    human: DrawnPerson | None = None,
    *,
    fps: float | None = None,
    frame_rate: float | None = None,
    width: int | None = None,
    height: int | None = None,
    every_n_frames: int = 2,
    strip_frames: int = STRIP_FRAMES,
    strip_columns: int = STRIP_COLUMNS,
    robot: Robot | None = None,
    contacts: ContactParams | None = None,
) -> Path:
    """Draw the robot (and the person beside it) to a .gif, .mp4 or .png strip.

    GIF and MP4 show every `every_n_frames`-th sample, or `frame_rate` frames per second of
    the clip, played at `fps` (default: real time), each `width` x `height` (960 x 480). A PNG
    is `strip_frames` evenly spaced frames in rows of `strip_columns`, each 480 x 320 unless
    given. `human` may be at another rate: frames are matched by time. Either subject may be
    None. `contacts`: the contact rule of a trajectory without contact flags.
    """
    output_path = Path(output_path)
    suffix = check_output(output_path)
    default_width, default_height = STRIP_SIZE if suffix == ".png" else ANIMATION_SIZE
    width, height = width or default_width, height or default_height
    if trajectory is None and human is None:
        raise PimannError(output_path, "nothing to render: no trajectory and no human motion")
    counts = (every_n_frames, strip_frames, strip_columns)
    if width < 64 or height < 64 or min(counts) < 1 or (frame_rate is not None and frame_rate <= 0):
        raise PimannError(
            output_path, "width/height must be >= 64, frame counts >= 1, the frame rate > 0"
        )
    clock = np.asarray(trajectory.time if trajectory is not None else human.time, dtype=float)
    source = trajectory.source if trajectory is not None else human.source
    if len(clock) == 0:
        raise PimannError(source, "no frames to render")

    rate = clip_rate(clock)
    if frame_rate is not None:
        every_n_frames = max(1, round(rate / frame_rate))
    if suffix == ".png":
        frames = strip_frame_indices(len(clock), strip_frames)
    else:
        frames = np.arange(0, len(clock), every_n_frames)
    times = clock[frames]
    skeletons = []
    if trajectory is not None:
        skeletons.append(robot_skeleton(trajectory, frames, robot, contacts))
    if human is not None:
        skeletons.append(human_skeleton(human, match_frames(times, human.time)))
    scene = Scene(skeletons, times - clock[0], width, height)

    fps = rate / every_n_frames if fps is None else fps
    log.info("rendering %d frames of %s to %s", len(frames), source, output_path)
    pictures = scene.frames(len(frames), output_path.name)
    write_pictures(output_path, pictures, fps, strip_columns)
    return output_path
