"""BVH reader: parse, forward kinematics over all frames, calibration to XSens segments.

A BVH skeleton's joint frames are not XSens segment frames: the bind pose is a T-pose in
which each local frame is a signed permutation of the world axes (SPEC 3.1). Each segment
is therefore calibrated as R_seg = C R_bvh P: P writes the segment's XSens x, y, z axes in
the joint's local axes (params `axes`), C turns BVH world axes (Y up, walking along +Z,
left at +X) into the robot's world (z up, x forward, y left). The BVH foot bone points at
the toes, which slope down when the foot is flat, so feet get an extra pitch.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from pimann.errors import PimannError, require_finite
from pimann.mocap.human_motion import HumanMotion
from pimann.params import SkeletonParams
from pimann.robot import SEGMENTS

# BVH world (X left, Y up, Z forward) -> robot world (x forward, y left, z up): p = [Z, X, Y].
BVH_TO_WORLD = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
_AXIS = {"X": 0, "Y": 1, "Z": 2}
_ROTATION_CHANNELS = ("Xrotation", "Yrotation", "Zrotation")
_POSITION_CHANNELS = ("Xposition", "Yposition", "Zposition")


@dataclasses.dataclass
class BvhJoint:
    name: str
    parent: int  # index in the joint list, -1 for the root
    offset: np.ndarray  # (3,) in BVH units
    channels: list[str]
    first_channel: int  # column of its first channel in a motion line


@dataclasses.dataclass
class BvhClip:
    """A parsed BVH file: the joint tree and the raw channel values (frames x channels)."""

    path: Path
    joints: list[BvhJoint]
    frame_time: float
    values: np.ndarray

    def joint_index(self, name: str) -> int:
        for index, joint in enumerate(self.joints):
            if joint.name == name:
                return index
        raise PimannError(self.path, f"skeleton has no joint {name!r}")


def parse_bvh(path: str | Path) -> BvhClip:
    """Read the hierarchy and the motion block, checking every frame line's length."""
    path = Path(path)
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise PimannError(path, "file not found") from None
    except (OSError, UnicodeDecodeError) as error:
        raise PimannError(path, f"cannot read as text ({error})") from None
    head, separator, motion = text.partition("MOTION")
    if not separator:
        raise PimannError(path, "no MOTION section (not a BVH file?)")
    joints = _parse_hierarchy(path, head)
    n_channels = sum(len(j.channels) for j in joints)
    lines = motion.strip().splitlines()
    if len(lines) < 2 or not lines[0].startswith("Frames:") or not lines[1].startswith("Frame"):
        raise PimannError(path, "MOTION section lacks the 'Frames:' and 'Frame Time:' lines")
    try:
        n_frames = int(lines[0].split()[1])
        frame_time = float(lines[1].split(":")[1])
    except (IndexError, ValueError):
        raise PimannError(path, "unreadable 'Frames:' or 'Frame Time:' line") from None
    if not frame_time > 0:
        raise PimannError(path, f"frame time must be positive, not {frame_time}")
    rows = [line.split() for line in lines[2:] if line.strip()]
    if len(rows) < n_frames:
        raise PimannError(
            path, f"truncated: 'Frames: {n_frames}' but {len(rows)} frame lines", frame=len(rows)
        )
    rows = rows[:n_frames]
    for frame, row in enumerate(rows):
        if len(row) != n_channels:
            raise PimannError(
                path, f"frame line has {len(row)} values, expected {n_channels}", frame=frame
            )
    try:
        values = np.array(rows, dtype=float).reshape(n_frames, n_channels)
    except ValueError:
        frame = next(i for i, row in enumerate(rows) if not _all_numbers(row))
        raise PimannError(
            path, "frame line holds a value that is not a number", frame=frame
        ) from None
    require_finite(path, "channel values", values)
    return BvhClip(path, joints, frame_time, values)


def _all_numbers(row: list[str]) -> bool:
    try:
        [float(v) for v in row]
    except ValueError:
        return False
    return True


def _parse_hierarchy(path: Path, head: str) -> list[BvhJoint]:
    tokens = head.split()
    joints: list[BvhJoint] = []
    stack: list[int] = []  # open blocks: joint index, or -2 for an End Site
    pending: int | None = None
    column = 0
    i = 0
    try:
        while i < len(tokens):
            token = tokens[i]
            if token in ("ROOT", "JOINT"):
                parent = next((s for s in reversed(stack) if s >= 0), -1)
                joints.append(BvhJoint(tokens[i + 1], parent, np.zeros(3), [], column))
                pending = len(joints) - 1
                i += 2
            elif token == "End":
                pending = -2
                i += 2
            elif token == "{":
                if pending is None:
                    raise PimannError(path, "hierarchy has a '{' without a joint")
                stack.append(pending)
                pending = None
                i += 1
            elif token == "}":
                stack.pop()
                i += 1
            elif token == "OFFSET":
                if stack[-1] >= 0:
                    joints[stack[-1]].offset = np.array([float(v) for v in tokens[i + 1 : i + 4]])
                i += 4
            elif token == "CHANNELS":
                count = int(tokens[i + 1])
                channels = tokens[i + 2 : i + 2 + count]
                joint = joints[stack[-1]]
                joint.channels, joint.first_channel = channels, column
                column += count
                i += 2 + count
            else:
                i += 1
    except (IndexError, ValueError):
        raise PimannError(path, f"malformed HIERARCHY near token {i} ({tokens[i]!r})") from None
    if not joints:
        raise PimannError(path, "HIERARCHY holds no joint")
    return joints


def forward_kinematics(clip: BvhClip) -> tuple[np.ndarray, np.ndarray]:
    """World rotations (T, J, 3, 3) and positions (T, J, 3) of every joint, in BVH axes/units.

    Local rotation is the product of the rotation channels in their listed order (intrinsic,
    e.g. Z X Y gives Rz Rx Ry); position channels, when present, replace the offset.
    """
    n_frames = len(clip.values)
    rotations = np.empty((n_frames, len(clip.joints), 3, 3))
    positions = np.empty((n_frames, len(clip.joints), 3))
    for index, joint in enumerate(clip.joints):
        columns = {name: joint.first_channel + k for k, name in enumerate(joint.channels)}
        order = [c for c in joint.channels if c in _ROTATION_CHANNELS]
        if order:
            angles = clip.values[:, [columns[c] for c in order]]
            sequence = "".join(c[0] for c in order).upper()
            local = Rotation.from_euler(sequence, angles, degrees=True).as_matrix()
        else:
            local = np.broadcast_to(np.eye(3), (n_frames, 3, 3))
        if all(c in columns for c in _POSITION_CHANNELS):
            translation = clip.values[:, [columns[c] for c in _POSITION_CHANNELS]]
        else:
            translation = np.broadcast_to(joint.offset, (n_frames, 3))
        if joint.parent < 0:
            rotations[:, index] = local
            positions[:, index] = translation
        else:
            parent_rotation = rotations[:, joint.parent]
            rotations[:, index] = parent_rotation @ local
            positions[:, index] = positions[:, joint.parent] + np.einsum(
                "tij,tj->ti", parent_rotation, translation
            )
    return rotations, positions


def axis_permutation(axes: list[str], path: str | Path | None = None) -> np.ndarray:
    """Signed permutation whose columns are the given BVH-local axes (e.g. ['Z', '-Y', 'X'])."""
    matrix = np.zeros((3, 3))
    for column, axis in enumerate(axes):
        name = axis.lstrip("+-")
        if name not in _AXIS or len(axes) != 3:
            raise PimannError(path, f"axes {axes} must be three of X, Y, Z with optional sign")
        matrix[_AXIS[name], column] = -1.0 if axis.startswith("-") else 1.0
    if abs(np.linalg.det(matrix)) != 1.0:
        raise PimannError(path, f"axes {axes} repeat an axis")
    if np.linalg.det(matrix) < 0:
        raise PimannError(path, f"axes {axes} form a left-handed frame")
    return matrix


def segment_calibrations(skeleton: SkeletonParams) -> np.ndarray:
    """(13, 3, 3) right-hand factor P (times the foot pitch for feet) of every segment."""
    calibration = np.empty((len(SEGMENTS), 3, 3))
    foot_pitch = Rotation.from_euler("y", skeleton.foot_pitch_deg, degrees=True).as_matrix()
    for k, segment in enumerate(SEGMENTS):
        calibration[k] = axis_permutation(skeleton.axes[segment])
        if segment.endswith("Foot"):
            calibration[k] = calibration[k] @ foot_pitch
    return calibration


def read_bvh(path: str | Path, skeleton: SkeletonParams) -> HumanMotion:
    """A BVH clip as XSens-convention segment orientations and positions (z up, metres)."""
    clip = parse_bvh(path)
    missing = [s for s in SEGMENTS if skeleton.segments.get(s) not in {j.name for j in clip.joints}]
    if missing:
        names = [skeleton.segments.get(s) for s in missing]
        raise PimannError(path, f"skeleton lacks joints {names} mapped to segments {missing}")
    rotations, positions = forward_kinematics(clip)
    indices = [clip.joint_index(skeleton.segments[s]) for s in SEGMENTS]
    orientations = BVH_TO_WORLD @ rotations[:, indices] @ segment_calibrations(skeleton)
    segment_positions = positions[:, indices] @ BVH_TO_WORLD.T * skeleton.unit_to_m
    time = np.arange(len(clip.values)) * clip.frame_time
    return HumanMotion(time, orientations, segment_positions, source=str(path))
