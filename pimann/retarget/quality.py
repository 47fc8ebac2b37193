"""How good a retargeting is (the targets of docs/retargeting.md).

`frame_measures` gives per-frame raw measures of one clip; `summarize` pools any number of
clips (so medians are over all frames of the set, not medians of medians).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from pimann.core.contacts import FEET, trajectory_configurations
from pimann.core.params import RetargetParams
from pimann.core.robot import (
    JOINT_NAMES,
    SEGMENTS,
    corner_offsets,
    load_robot,
)
from pimann.core.trajectory import Trajectory
from pimann.mocap.human_motion import HumanMotion
from pimann.retarget.targets import segment_targets

AT_LIMIT_RAD = 0.01  # a joint within this of a bound counts as "at its limit"
FLOOR_TOLERANCE = -0.005  # m: a corner lower than this is "below the floor"
SHANK_CLEARANCE = 0.09  # m between the shank axes (about two shank radii)


def _segment_distance(a0, a1, b0, b1) -> np.ndarray:
    """(T,) distance between segments a0-a1 and b0-b1 (sampled: cheap and good to 1 mm)."""
    s = np.linspace(0.0, 1.0, 21)
    pa = a0[:, None] + s[None, :, None] * (a1 - a0)[:, None]
    pb = b0[:, None] + s[None, :, None] * (b1 - b0)[:, None]
    return np.linalg.norm(pa[:, :, None] - pb[:, None], axis=-1).min(axis=(1, 2))


def frame_measures(
    motion: HumanMotion, trajectory: Trajectory, params: RetargetParams
) -> dict[str, np.ndarray]:
    """Per-frame measures of one clip; `motion` at the trajectory's rate."""
    robot = load_robot("retarget")
    model, data = robot.model, robot.model.createData()
    n = len(trajectory)
    segment_frames = [robot.frame_id(f"data_{s}") for s in SEGMENTS]
    knees = [model.getJointId(j) for j in ("l_knee", "r_knee")]
    ankles = [model.getJointId(j) for j in ("l_ankle_pitch", "r_ankle_pitch")]
    rotations = np.empty((n, len(SEGMENTS), 3, 3))
    shanks = np.empty((n, 2, 2, 3))
    sole_frames = [robot.frame_id(name) for name in FEET]
    soles, sole_rotations = np.empty((n, 2, 3)), np.empty((n, 2, 3, 3))
    configurations = trajectory_configurations(robot, trajectory)
    for t in range(n):  # one pass per frame: every frame placement the measures read
        pin.framesForwardKinematics(model, data, configurations[t])
        for k, frame in enumerate(segment_frames):
            rotations[t, k] = data.oMf[frame].rotation
        for k in range(2):
            shanks[t, k] = data.oMi[knees[k]].translation, data.oMi[ankles[k]].translation
            sole = data.oMf[sole_frames[k]]
            soles[t, k], sole_rotations[t, k] = sole.translation, sole.rotation
    corners = soles[:, :, None] + corner_offsets(sole_rotations)  # (T, 2, C, 3)
    targets = segment_targets(motion, params)
    relative = np.swapaxes(rotations, -1, -2) @ targets
    cosine = np.clip((np.trace(relative, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0)
    lower, upper = robot.joint_lower, robot.joint_upper
    joints = trajectory.joint_positions
    at_limit = (joints < lower + AT_LIMIT_RAD) | (joints > upper - AT_LIMIT_RAD)
    dt = np.diff(trajectory.time)[:, None]
    sole_speed = np.linalg.norm(np.diff(soles[..., :2], axis=0), axis=-1) / dt
    contacts = trajectory.contacts if trajectory.contacts is not None else np.zeros((n, 2), bool)
    stance = contacts[1:] & contacts[:-1]
    corner_speed = np.linalg.norm(np.diff(corners[..., :2], axis=0), axis=-1).max(axis=-1) / dt
    shank_gap = _segment_distance(
        shanks[:, 0, 0], shanks[:, 0, 1], shanks[:, 1, 0], shanks[:, 1, 1]
    )
    robot_path = np.linalg.norm(np.diff(trajectory.base_position[:, :2], axis=0), axis=-1).sum()
    human_path = np.linalg.norm(np.diff(motion.pelvis_position[:, :2], axis=0), axis=-1).sum()
    lowest = corners[..., 2].min(axis=(1, 2))  # (T,) the lowest corner of either foot
    return {
        "orientation_error_deg": np.degrees(np.arccos(cosine)),  # (T, 13)
        "at_limit": at_limit,  # (T, 26)
        "stance_speed": sole_speed[stance],  # (contact samples,) sole origin
        "stance_corner_speed": corner_speed[stance],  # the foot's fastest corner
        "corner_below_floor": lowest < FLOOR_TOLERANCE,  # (T,)
        "lowest_corner": lowest,
        "leg_collision": shank_gap < SHANK_CLEARANCE,  # (T,)
        "path_lengths": np.array([[robot_path, human_path]]),  # (1, 2)
    }


def summarize(measures: list[dict[str, np.ndarray]], seconds: float | None = None) -> dict:
    """Pooled quality figures of many clips (JSON-ready)."""
    pooled = {k: np.concatenate([m[k] for m in measures]) for k in measures[0]}
    errors = pooled["orientation_error_deg"]
    at_limit = pooled["at_limit"]
    speed = pooled["stance_speed"]
    robot_path, human_path = pooled["path_lengths"].sum(axis=0)
    n_frames = len(errors)
    result = {
        "clips": len(measures),
        "frames": int(n_frames),
        "orientation_error_deg": {
            s: {
                "median": float(np.median(errors[:, k])),
                "p95": float(np.percentile(errors[:, k], 95)),
            }
            for k, s in enumerate(SEGMENTS)
        },
        "joint_at_limit_share": {
            "any": float(at_limit.any(axis=1).mean()),
            **{j: float(at_limit[:, k].mean()) for k, j in enumerate(JOINT_NAMES)},
        },
        "stance_foot_speed_m_s": _spread(speed),
        "stance_corner_speed_m_s": _spread(pooled["stance_corner_speed"]),
        "corner_below_floor_share": float(pooled["corner_below_floor"].mean()),
        "lowest_corner_m": float(pooled["lowest_corner"].min()),
        "leg_collision_share": float(pooled["leg_collision"].mean()),
        "speed_ratio": float(robot_path / human_path) if human_path > 0 else float("nan"),
    }
    if seconds is not None:
        result["ms_per_frame"] = 1000.0 * seconds / n_frames
    return result


def _spread(values: np.ndarray) -> dict[str, float]:
    if not len(values):
        return {"mean": 0.0, "median": 0.0, "p95": 0.0}
    return {
        "mean": float(values.mean()),
        "median": float(np.median(values)),
        "p95": float(np.percentile(values, 95)),
    }


def quality_report(quality: dict) -> str:
    """The quality figures as a short text table, for people reading the stage's output."""
    lines = [f"{'segment':<16}{'median deg':>11}{'p95 deg':>9}"]
    for segment, error in quality["orientation_error_deg"].items():
        lines.append(f"{segment:<16}{error['median']:>11.2f}{error['p95']:>9.2f}")
    limits = quality["joint_at_limit_share"]
    worst = max((k for k in limits if k != "any"), key=limits.get)
    lines += [
        f"frames with any joint at a limit: {limits['any']:.1%}"
        f" (worst {worst} {limits[worst]:.1%})",
        "stance-foot horizontal speed: median {median:.4f}, p95 {p95:.4f} m/s".format(
            **quality["stance_foot_speed_m_s"]
        ),
        "fastest stance corner speed: median {median:.4f}, p95 {p95:.4f} m/s".format(
            **quality["stance_corner_speed_m_s"]
        ),
        f"frames with a sole corner below the floor: {quality['corner_below_floor_share']:.2%}",
        f"leg self-collision frames: {quality['leg_collision_share']:.2%}",
        f"robot/human base speed ratio: {quality['speed_ratio']:.2f}",
        f"{quality['ms_per_frame']:.2f} ms per frame",
    ]
    return "\n".join(lines)
