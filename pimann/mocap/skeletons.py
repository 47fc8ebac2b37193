"""What a BVH skeleton's joints are: which joint is which XSens segment, and how its axes sit.

Names: the common conventions are recognised from a file's joint names alone; others are
named in params `data.skeletons`. Axes: no per-skeleton table. Every segment gets the
constant right factor P with R_seg(t) = C R_bvh(t) P that best matches the segment's
XSens frame as the joint positions define it in every frame (bones for the limbs'
long axes, the knee and elbow flexion axes for their lateral axes, the floor for the feet).
The joint's own frame is arbitrary (any rest pose, any local axes), so P is found in the
joint's local coordinates, where a rigid landmark is constant: the long axis is kept
exactly (TRIAD, rather than an SVD fit that would trade it against the secondary) and the
noisier secondary axis is averaged over the frames, weighted by how well each frame
defines it (sin^2 of the knee or elbow angle; low, still feet). The trunk's z is the bone
to the next joint up, the head is T8 on average (no head landmark is common to all rigs),
and a forearm's twist has no landmark at all: the elbow hinge the retargeting imposes
makes it irrelevant.
"""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np

from pimann.core.errors import PimannError
from pimann.core.params import SkeletonParams
from pimann.core.robot import SEGMENTS

SIDES = ("Left", "Right")
_SIDE_WORDS = {"{Left}": SIDES, "{L}": ("L", "R"), "{l}": ("l", "r")}

# Per convention: segment (or "Toes", with the side left out) -> joint names, '|' between
# alternatives (the first the file has wins), {Left} {L} {l} standing for the side.
CONVENTIONS: dict[str, dict[str, str]] = {
    "bandai_namco": {
        "Pelvis": "Hips", "T8": "Chest", "Head": "Head",
        "UpperLeg": "UpperLeg_{L}", "LowerLeg": "LowerLeg_{L}", "Foot": "Foot_{L}",
        "Toes": "Toes_{L}", "UpperArm": "UpperArm_{L}", "ForeArm": "LowerArm_{L}",
    },
    # Blender rigs (ReActIdle; Rigify DEF- bones): the shoulders hang from spine.001 (the
    # chest) in ReActIdle, spine.003 in Rigify; `face` ends the neck chain and turns with it.
    "blender_rigify": {
        "Pelvis": "pelvis|spine", "T8": "spine.003|spine.001", "Head": "face|spine.006|head",
        "UpperLeg": "thigh.{L}", "LowerLeg": "shin.{L}", "Foot": "foot.{L}",
        "Toes": "toe.{L}", "UpperArm": "upper_arm.{L}", "ForeArm": "forearm.{L}",
    },
    # Unity humanoid and Mixamo: T8 is the bone the shoulders hang from.
    "unity_mixamo": {
        "Pelvis": "Hips", "T8": "UpperChest|Spine2|Chest|Spine1", "Head": "Head",
        "UpperLeg": "{Left}UpperLeg|{Left}UpLeg", "LowerLeg": "{Left}LowerLeg|{Left}Leg",
        "Foot": "{Left}Foot", "Toes": "{Left}Toes|{Left}ToeBase",
        "UpperArm": "{Left}UpperArm|{Left}Arm", "ForeArm": "{Left}LowerArm|{Left}ForeArm",
    },
    # XSens MVN export: Chest..Chest4 are L5, L3, T12, T8; Shoulder is the upper arm.
    "xsens_mvn": {
        "Pelvis": "Hips", "T8": "Chest4|Spine3", "Head": "Head",
        "UpperLeg": "{Left}Hip", "LowerLeg": "{Left}Knee", "Foot": "{Left}Ankle",
        "Toes": "{Left}Toe", "UpperArm": "{Left}Shoulder", "ForeArm": "{Left}Elbow",
    },
    "cmu": {
        "Pelvis": "hip", "T8": "chest", "Head": "head",
        "UpperLeg": "{l}Thigh", "LowerLeg": "{l}Shin", "Foot": "{l}Foot",
        "Toes": "{l}Toe", "UpperArm": "{l}Shldr", "ForeArm": "{l}ForeArm",
    },
}  # fmt: skip
_PREFIX = re.compile(r"^(?:.*:|DEF-)")  # Maya/FBX namespaces (mixamorig:), Rigify DEF-


def _key(name: str) -> str:
    return _PREFIX.sub("", name).lower()


def _candidates(convention: dict[str, str], part: str, side: int) -> list[str]:
    names = convention[part]
    for word, values in _SIDE_WORDS.items():
        names = names.replace(word, values[side])
    return names.split("|")


def _convention_map(convention: dict[str, str], joint_names: list[str]):
    """(segment -> joint, foot segment -> toe joint) of the joints the file has."""
    by_key = {}
    for name in joint_names:
        by_key.setdefault(_key(name), name)

    def find(part: str, side: int) -> str | None:
        found = (by_key.get(_key(c)) for c in _candidates(convention, part, side))
        return next((name for name in found if name is not None), None)

    segments, toes = {}, {}
    for segment in SEGMENTS:
        side = 1 if segment.startswith("Right") else 0
        if (joint := find(segment.removeprefix(SIDES[side]), side)) is not None:
            segments[segment] = joint
    for side, foot in enumerate(("LeftFoot", "RightFoot")):
        if (toe := find("Toes", side)) is not None:
            toes[foot] = toe
    return segments, toes


def recognise_skeleton(joint_names: list[str], path: str | Path | None = None) -> SkeletonParams:
    """The built-in convention whose 13 segments all name a joint of the file."""
    best_name, best_missing = "", list(SEGMENTS)
    for name, convention in CONVENTIONS.items():
        segments, toes = _convention_map(convention, joint_names)
        missing = [s for s in SEGMENTS if s not in segments]
        if not missing:
            return SkeletonParams(segments, toes if len(toes) == 2 else None, None)
        if len(missing) < len(best_missing):
            best_name, best_missing = name, missing
    raise PimannError(
        path,
        f"skeleton not recognised: the closest convention ({best_name}) has no joint for "
        f"{', '.join(best_missing)}; name the joints of all 13 segments in params "
        "data.skeletons.<name>.segments and set the source's skeleton: <name>",
    )


@dataclasses.dataclass
class BodyLandmarks:
    """What calibration reads, over all frames, in robot world axes (z up) and metres."""

    rotations: np.ndarray  # (T, 13, 3, 3) world rotation of each segment's joint (C R_bvh)
    origins: np.ndarray  # (T, 13, 3) each segment joint's position
    toes: np.ndarray  # (T, 2, 3) [left, right] toe: toe joint, or the foot bone's end
    wrists: np.ndarray  # (T, 2, 3) [left, right] end of the forearm bone
    spine: np.ndarray  # (T, 3) the first joint above the pelvis on the way to T8
    neck: np.ndarray  # (T, 3) the first joint above T8 on the way to the head
    frame_time: float  # s between frames


_UP = np.array([0.0, 0.0, 1.0])
_FOOT_LOW_M = 0.05  # heel and toe this close to their lowest ...
_FOOT_STILL_M_S = 0.2  # ... and this slow: the foot stands flat on the floor
_DEGENERATE = 1e-4  # mean weight below this: the motion does not define the axis


def _index(name: str) -> int:
    return SEGMENTS.index(name)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def _local_sum(rotations: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """Sum over frames of world vectors (T, 3) written in the joint's local axes."""
    return np.einsum("tji,tj->i", rotations, vectors)


def _triad(primary: np.ndarray, a: int, secondary: np.ndarray, b: int) -> np.ndarray:
    """Rotation whose column a is along `primary` and column b the rest of `secondary`."""
    frame = np.zeros((3, 3))
    frame[:, a] = _unit(primary)
    rest = secondary - frame[:, a] * (secondary @ frame[:, a])
    if not (
        np.linalg.norm(primary) > 0 and np.linalg.norm(rest) > 1e-9 * np.linalg.norm(secondary)
    ):
        raise ValueError("an axis is zero or the two are parallel")
    frame[:, b] = _unit(rest)
    c = 3 - a - b
    frame[:, c] = np.cross(frame[:, (c + 1) % 3], frame[:, (c + 2) % 3])
    return frame


def _hinge_axis(proximal: np.ndarray, distal: np.ndarray) -> np.ndarray:
    """(T, 3) distal x proximal over unit bones, times its sine: frames weighted by sin^2."""
    axis = np.cross(_unit(distal), _unit(proximal))
    return axis * np.linalg.norm(axis, axis=-1, keepdims=True)


def _flat_foot_weights(heel: np.ndarray, toe: np.ndarray, frame_time: float) -> np.ndarray:
    """(T,) 1 where heel and toe are both low and still (the foot flat on the floor), to 0.
    Stillness matters: a take whose ankle hardly rises has its lowest toes at toe-off."""
    weight = np.ones(len(heel))
    for point in (heel, toe):
        low = 1.0 - (point[:, 2] - np.percentile(point[:, 2], 2)) / _FOOT_LOW_M
        speed = (
            np.linalg.norm(np.gradient(point, frame_time, axis=0), axis=-1) if len(point) > 1 else 0
        )
        weight *= np.clip(low, 0.0, 1.0) * np.clip(1.0 - speed / _FOOT_STILL_M_S, 0.0, 1.0)
    return weight if weight.sum() > _DEGENERATE * len(weight) else np.ones(len(heel))


def calibrate_segments(body: BodyLandmarks, path: str | Path | None = None) -> np.ndarray:
    """(13, 3, 3) P per segment: the XSens axes written in the joint's local axes."""
    R, o = body.rotations, body.origins
    n = len(o)
    P = np.empty((len(SEGMENTS), 3, 3))

    def put(segment: str, primary, a: int, secondary, b: int) -> None:
        k = _index(segment)
        try:
            P[k] = _triad(_local_sum(R[:, k], primary), a, _local_sum(R[:, k], secondary), b)
        except ValueError:
            raise PimannError(
                path, f"cannot calibrate {segment}: its axes are degenerate"
            ) from None

    def weighted_or(axis: np.ndarray, fallback: np.ndarray) -> np.ndarray:
        """The flexion axis, or a fallback where the joint never bends in this clip."""
        strength = np.linalg.norm(axis.sum(axis=0)) / n
        return axis if strength > _DEGENERATE else fallback

    hips = o[:, _index("LeftUpperLeg")] - o[:, _index("RightUpperLeg")]
    shoulders = o[:, _index("LeftUpperArm")] - o[:, _index("RightUpperArm")]
    pelvis, t8 = o[:, _index("Pelvis")], o[:, _index("T8")]
    # trunk z: the bone to the next joint up, rigid with the segment (a longer chain would
    # average the spine's bending, which differs from take to take)
    put("Pelvis", hips, 1, body.spine - pelvis, 2)  # y: right to left hip, z: up the spine
    put("T8", shoulders, 1, body.neck - t8, 2)  # y: across the shoulders, z: to the neck
    k = _index("T8")
    t8_world = R[:, k] @ P[k]
    put("Head", t8_world[:, :, 2], 2, t8_world[:, :, 0], 0)  # T8's axes on average
    for s, (side, sign) in enumerate(zip(SIDES, (1.0, -1.0), strict=True)):
        hip, knee = o[:, _index(side + "UpperLeg")], o[:, _index(side + "LowerLeg")]
        ankle = o[:, _index(side + "Foot")]
        # y: left. A knee flexes about the hips' left; per frame, as a standing rig's
        # straight knee may "bend" slightly backwards and would flip the thigh otherwise
        hinge = _hinge_axis(hip - knee, ankle - knee)
        hinge *= np.where(np.einsum("ij,ij->i", hinge, hips) < 0.0, -1.0, 1.0)[:, None]
        knee_axis = weighted_or(hinge, hips)
        put(side + "UpperLeg", hip - knee, 2, knee_axis, 1)
        put(side + "LowerLeg", knee - ankle, 2, knee_axis, 1)
        toe = body.toes[:, s]
        flat = _flat_foot_weights(ankle, toe, body.frame_time)[:, None]
        forward = _unit((toe - ankle) * [1.0, 1.0, 0.0])
        put(side + "Foot", flat * _UP, 2, flat * forward, 0)
        shoulder, elbow = o[:, _index(side + "UpperArm")], o[:, _index(side + "ForeArm")]
        wrist = body.wrists[:, s]
        # XSens arm y points left in the T-pose; both elbows flex about z, left negative
        hinge = sign * _hinge_axis(elbow - shoulder, wrist - elbow)
        elbow_axis = weighted_or(hinge, t8_world[:, :, 2])
        put(side + "UpperArm", sign * (elbow - shoulder), 1, elbow_axis, 2)
        put(side + "ForeArm", sign * (wrist - elbow), 1, elbow_axis, 2)
    return P
