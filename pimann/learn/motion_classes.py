"""Motion classes of a trajectory, per frame, from its base motion (shared by the data report,
the command-following benchmark and the features stage's split, stratified by class).

The base's planar velocity in the heading (yaw) frame and its yaw rate, both averaged over a
centred window of `WINDOW_S` (the mean of the finite-difference velocity over a window is the
displacement across it divided by its duration; the window shrinks at the clip's ends), give
each frame a class. In this order: standing (speed < `STANDING_SPEED` and |yaw rate| <
`STANDING_YAW_RATE`), turning in place (speed < `STANDING_SPEED`, turning faster), turning
(walking with |yaw rate| > `TURN_YAW_RATE`), then by the angle of the velocity from the
heading: forward within `FORWARD_DEG`, backward beyond `BACKWARD_DEG`, side steps (left and
right) within `SIDE_DEG`, diagonal otherwise. Starts and stops (`transitions`): changes between
standing and moving (any other class) whose both states last `MIN_STATE_S` or more, so that
jitter around the thresholds is not counted.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from scipy.spatial.transform import Rotation

from pimann.core.contacts import frame_period
from pimann.core.errors import PimannError
from pimann.core.rotations import to_heading_frame, yaw_of
from pimann.core.trajectory import Trajectory

WINDOW_S = 1.0  # s, centred window of the base velocity and yaw rate
STANDING_SPEED = 0.1  # m/s, planar base speed below which the robot is not walking
STANDING_YAW_RATE = 0.2  # rad/s, ... and below which it is standing, not turning in place
TURN_YAW_RATE = 0.25  # rad/s, walking faster than this is turning
FORWARD_DEG = 30.0  # velocity within +-30 deg of the heading
SIDE_DEG = (60.0, 120.0)  # side steps, left or right
BACKWARD_DEG = 150.0  # beyond +-150 deg
MIN_STATE_S = 0.5  # s, standing and moving must each last this long for a start or stop

CLASSES = ("forward", "backward", "side", "diagonal", "turning", "turning_in_place", "standing")
WALKING = ("forward", "backward", "side", "diagonal", "turning")  # double support is over these


def _window_bounds(n: int, half: int) -> tuple[np.ndarray, np.ndarray]:
    frames = np.arange(n)
    return np.maximum(frames - half, 0), np.minimum(frames + half, n - 1)


def base_motion(trajectory: Trajectory, window_s: float = WINDOW_S):
    """(T, 2) planar base velocity in the heading frame and (T,) yaw rate, window means."""
    time = np.asarray(trajectory.time, dtype=float)
    if len(time) < 2:
        raise PimannError(trajectory.source, f"needs at least 2 frames, has {len(time)}")
    half = max(1, round(window_s / 2 / frame_period(trajectory)))
    lo, hi = _window_bounds(len(time), half)
    span = time[hi] - time[lo]
    rotations = Rotation.from_quat(trajectory.base_quaternion_xyzw).as_matrix()
    yaw = np.unwrap(yaw_of(rotations))
    sums = np.concatenate([[0.0], np.cumsum(yaw)])
    heading = (sums[hi + 1] - sums[lo]) / (hi + 1 - lo)
    position = np.asarray(trajectory.base_position, dtype=float)
    world = (position[hi, :2] - position[lo, :2]) / span[:, None]
    return to_heading_frame(world, heading), (yaw[hi] - yaw[lo]) / span


def classify(velocity: np.ndarray, yaw_rate: np.ndarray) -> np.ndarray:
    """(T,) index into `CLASSES` of each frame, from `base_motion`'s outputs."""
    speed = np.linalg.norm(velocity, axis=-1)
    angle = np.degrees(np.abs(np.arctan2(velocity[:, 1], velocity[:, 0])))
    still = speed < STANDING_SPEED
    code = {name: k for k, name in enumerate(CLASSES)}
    return np.select(
        [
            still & (np.abs(yaw_rate) < STANDING_YAW_RATE),
            still,
            np.abs(yaw_rate) > TURN_YAW_RATE,
            angle <= FORWARD_DEG,
            angle >= BACKWARD_DEG,
            (angle >= SIDE_DEG[0]) & (angle <= SIDE_DEG[1]),
        ],
        [
            code["standing"],
            code["turning_in_place"],
            code["turning"],
            code["forward"],
            code["backward"],
            code["side"],
        ],
        code["diagonal"],
    )


def motion_classes(trajectory: Trajectory) -> np.ndarray:
    """(T,) index into `CLASSES` of each frame of a trajectory."""
    return classify(*base_motion(trajectory))


def class_counts(trajectory: Trajectory) -> np.ndarray:
    """(len(CLASSES),) frames of each class in a trajectory."""
    return np.bincount(motion_classes(trajectory), minlength=len(CLASSES))


def majority_class(counts: np.ndarray) -> str:
    """The class of a clip (or of a source's clips pooled) from `class_counts`: its most
    frequent walking class, since what it teaches is how it walks; standing where more than
    half its frames stand, turning in place where it has no walking frame."""
    counts = np.asarray(counts)
    walking = [CLASSES.index(name) for name in WALKING]
    standing = CLASSES.index("standing")
    if 2 * counts[standing] > counts.sum():
        return "standing"
    if counts[walking].sum() == 0:
        return "turning_in_place" if counts[CLASSES.index("turning_in_place")] else "standing"
    return CLASSES[walking[int(np.argmax(counts[walking]))]]


def spread_pick(order: Sequence[str], groups: Mapping[str, str | None], count: int) -> list[str]:
    """The first `count` names of `order`, each of a group (a style) not picked yet while such
    a name is left, so that a few picks span styles; a None group is a name's own."""
    picked: list[str] = []
    seen: set[str] = set()
    for fresh in (True, False):
        for name in order:
            group = groups.get(name) or f"\0{name}"
            if len(picked) < count and name not in picked and (group not in seen or not fresh):
                picked.append(name)
                seen.add(group)
    return picked


def transitions(moving: np.ndarray, min_frames: int) -> tuple[np.ndarray, np.ndarray]:
    """Frames where a start (standing -> moving) and a stop (moving -> standing) happen.

    Runs of either state shorter than `min_frames` are jitter: they are dropped, and a change
    counts between the remaining runs of different states (at the first frame of the later).
    """
    moving = np.asarray(moving, dtype=bool)
    if len(moving) == 0:
        return np.empty(0, int), np.empty(0, int)
    starts = np.flatnonzero(np.diff(moving.astype(int))) + 1
    starts = np.concatenate([[0], starts])
    lengths = np.diff(np.concatenate([starts, [len(moving)]]))
    keep = lengths >= min_frames
    starts, states = starts[keep], moving[starts[keep]].astype(int)
    change = np.diff(states)
    return starts[1:][change == 1], starts[1:][change == -1]
