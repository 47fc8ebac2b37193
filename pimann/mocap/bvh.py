"""BVH reader: parse, forward kinematics over all frames, segments in XSens convention.

Any skeleton: the joint names come from a built-in convention or params, the axes of every
segment are calibrated from the motion itself (pimann.mocap.skeletons), the length unit
is told from the leg length and the up axis from the hips-to-head direction, so each
segment is R_seg = C R_bvh P with C turning the file's world into the robot's (z up).
The kept libraries bvhio and pybvh were not used: calibration needs only world rotations
and positions of all frames at once, which their per-joint object trees give slowly, and
their own exceptions name neither the file nor the frame, so this ~100-line parser stays.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from pimann.core.errors import PimannError, require_finite
from pimann.core.params import SkeletonParams
from pimann.core.robot import SEGMENTS
from pimann.mocap.human_motion import HumanMotion
from pimann.mocap.skeletons import BodyLandmarks, calibrate_segments, recognise_skeleton

_ROTATION_CHANNELS = ("Xrotation", "Yrotation", "Zrotation")
_POSITION_CHANNELS = ("Xposition", "Yposition", "Zposition")


@dataclasses.dataclass
class BvhJoint:
    name: str
    parent: int  # index in the joint list, -1 for the root
    offset: np.ndarray  # (3,) in BVH units
    channels: list[str]
    first_channel: int  # column of its first channel in a motion line
    end_site: np.ndarray | None = None  # (3,) offset of its End Site, if it has one


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
                offset = np.array([float(v) for v in tokens[i + 1 : i + 4]])
                if stack[-1] >= 0:
                    joints[stack[-1]].offset = offset
                elif (owner := next((s for s in reversed(stack) if s >= 0), None)) is not None:
                    joints[owner].end_site = offset  # an End Site: where the owner's bone ends
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


# Length units a BVH file may use, tried in this order; the first that makes the leg
# (hip to knee to ankle) 0.45-1.3 m long is taken. CMU's converted files use 1/0.45 inch.
LENGTH_UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001, "inch": 0.0254, "CMU unit": 0.0254 / 0.45}
LEG_LENGTH_M = (0.45, 1.3)


def detect_unit(path: str | Path, leg_length: float) -> float:
    """Metres per BVH length unit, from the leg length in file units."""
    for metres in LENGTH_UNITS.values():
        if LEG_LENGTH_M[0] <= leg_length * metres <= LEG_LENGTH_M[1]:
            return metres
    raise PimannError(
        path,
        f"cannot tell the length unit: the leg is {leg_length:.4g} units long, a human leg in "
        f"none of {', '.join(LENGTH_UNITS)}; set unit_to_m in params data.skeletons",
    )


def world_axes(up: np.ndarray) -> np.ndarray:
    """C: the proper rotation (a signed cyclic axis permutation) taking the file's up axis,
    the one closest to `up`, to the robot's z; which way is forward does not matter."""
    axis = int(np.argmax(np.abs(up)))
    sign = 1.0 if up[axis] > 0 else -1.0
    matrix = np.zeros((3, 3))
    matrix[0, (axis + 1) % 3] = 1.0
    matrix[1, (axis + 2) % 3] = sign
    matrix[2, axis] = sign
    return matrix


def _bone_end(clip: BvhClip, rotations, positions, joint: int, what: str) -> np.ndarray:
    """(T, 3) where the joint's bone ends: its farthest child joint, else its End Site."""
    children = [k for k, j in enumerate(clip.joints) if j.parent == joint]
    lengths = [np.linalg.norm(clip.joints[k].offset) for k in children]
    if children and max(lengths) > 0:
        return positions[:, children[int(np.argmax(lengths))]]
    end = clip.joints[joint].end_site
    if end is not None and np.linalg.norm(end) > 0:
        return positions[:, joint] + rotations[:, joint] @ end
    name = clip.joints[joint].name
    raise PimannError(clip.path, f"joint {name!r} ({what}) has no child or End Site ending it")


def _next_on_chain(clip: BvhClip, positions, start: int, end: int, min_length: float):
    """(T, 3) the first joint on the chain from `start` up to `end` at least `min_length`
    from `start` (the joint that moves rigidly with it, where the rig has one), else `end`."""
    chain, joint = [], end
    while joint not in (start, -1):
        chain.append(joint)
        joint = clip.joints[joint].parent
    if joint == start:
        for k in reversed(chain):
            distance = np.linalg.norm(positions[:, k] - positions[:, start], axis=-1)
            if np.median(distance) > min_length:
                return positions[:, k]
    return positions[:, end]


def _check_names(clip: BvhClip, skeleton: SkeletonParams) -> None:
    names = {j.name for j in clip.joints}
    mapped = {s: skeleton.segments.get(s) for s in SEGMENTS}
    mapped.update({f"{foot} toes": toe for foot, toe in (skeleton.toes or {}).items()})
    missing = [s for s, joint in mapped.items() if joint not in names]
    if missing:
        joints = [mapped[s] for s in missing]
        raise PimannError(clip.path, f"skeleton lacks joints {joints} mapped to segments {missing}")


def bvh_landmarks(
    clip: BvhClip, skeleton: SkeletonParams | None = None, rate_hz: float | None = None
) -> BodyLandmarks:
    """The segment joints' world rotations and the points calibration needs (robot axes,
    metres); `skeleton` None: recognised from the joint names."""
    path = clip.path
    if skeleton is None:
        skeleton = recognise_skeleton([j.name for j in clip.joints], path)
    _check_names(clip, skeleton)
    rotations, positions = forward_kinematics(clip)
    index = {s: clip.joint_index(skeleton.segments[s]) for s in SEGMENTS}
    ids = list(index.values())
    hip, knee, ankle = (positions[:, index["Left" + s]] for s in ("UpperLeg", "LowerLeg", "Foot"))
    leg = float(
        np.median(np.linalg.norm(hip - knee, axis=-1) + np.linalg.norm(knee - ankle, axis=-1))
    )
    unit = skeleton.unit_to_m or detect_unit(path, leg)
    to_world = world_axes(
        np.median(positions[:, index["Head"]] - positions[:, index["Pelvis"]], axis=0)
    )

    def world(points: np.ndarray) -> np.ndarray:
        return points @ to_world.T * unit

    toes = [
        positions[:, clip.joint_index(skeleton.toes[foot])]
        if skeleton.toes and foot in skeleton.toes
        else _bone_end(clip, rotations, positions, index[foot], foot)
        for foot in ("LeftFoot", "RightFoot")
    ]
    wrists = [
        _bone_end(clip, rotations, positions, index[arm], arm)
        for arm in ("LeftForeArm", "RightForeArm")
    ]
    spine = _next_on_chain(clip, positions, index["Pelvis"], index["T8"], 0.02 * leg)
    neck = _next_on_chain(clip, positions, index["T8"], index["Head"], 0.02 * leg)
    return BodyLandmarks(
        rotations=to_world @ rotations[:, ids],
        origins=world(positions[:, ids]),
        toes=world(np.stack(toes, axis=1)),
        wrists=world(np.stack(wrists, axis=1)),
        spine=world(spine),
        neck=world(neck),
        frame_time=1.0 / rate_hz if rate_hz else clip.frame_time,
    )


def read_bvh(
    path: str | Path, skeleton: SkeletonParams | None = None, rate_hz: float | None = None
) -> HumanMotion:
    """A BVH clip as XSens-convention segments (z up, metres) with heel and toe points.

    `skeleton` None: recognised from the joint names; `rate_hz` replaces the header's
    frame time."""
    clip = parse_bvh(path)
    if rate_hz is not None and not rate_hz > 0:
        raise PimannError(path, f"rate must be positive, not {rate_hz}")
    body = bvh_landmarks(clip, skeleton, rate_hz)
    orientations = body.rotations @ calibrate_segments(body, path)
    heels = body.origins[:, [SEGMENTS.index("LeftFoot"), SEGMENTS.index("RightFoot")]]
    foot_points = np.stack([heels, body.toes], axis=2)
    n_frames = len(clip.values)
    time = np.arange(n_frames) / rate_hz if rate_hz else np.arange(n_frames) * clip.frame_time
    return HumanMotion(time, orientations, body.origins, str(path), foot_points=foot_points)
