"""The paper's evaluation of a trajectory (paper Sec. IV): support-foot sliding, drift, foot pitch.

Support-foot velocity RMSE: at each step where a foot is in contact, the RMS over the 3 linear
(resp. 3 angular) components of that sole's velocity; summed over the trajectory per foot;
left and right sums averaged ("total RMSE"). The sum grows with the number of frames, so it
compares trajectories of equal length and rate only (the paper: 10 s at 50 Hz, 500 steps).

The authors' metric (`support_rmse_paper_<linear|angular>_*`, the claims'): their rollout's
step from q_{i-1} to q_i (pimann.evaluate.sliding.authors_sole_velocities: support foot,
Jacobian and base twist at the previous state, the soles read at the new one, linear part
inertial-fixed), feet counted by the trigger on their sole origin's height as their rollout
runs it (both on at the start). Ours beside it: the lowest-corner velocity level
(`support_rmse_<linear|angular>_*`) moves the joints at the file's joint velocities (a
rollout's: the network's predicted ones; none: central finite differences of the joints) and
the base so that the lowest-corner foot stays still at the same frame: the support sole never
slides there, the other one slides as the joint velocities move it while both are down; the
position level (`support_rmse_<part>_position_*`) takes every velocity, the base's too, from
central finite differences of q on the configuration manifold (`pinocchio.difference`):
whether the feet of the trajectory a robot would track move; the contact point
(`support_rmse_contact_point_*`) is the position level's velocity of each sole's lowest
corner. Our linear parts in `evaluate.foot_velocity_frame`: LOCAL_WORLD_ALIGNED (the sole
origin's velocity in world axes) or WORLD (inertial-fixed: the velocity of the point at the
world origin, v - omega x p); the WORLD linear part is always reported too
(`support_rmse_linear[_position]_world_*`); the angular part is the same in both. Our linear
parts are also reported with the sole-origin contact rule (`*_origin_contacts_*`).

Foot-skating ratio: pimann.evaluate.sliding.

Drift: base displacement since the first frame, in the first frame's heading frame (x forward,
y left), and changes of roll, pitch and (unwrapped) yaw since the first frame.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pandas as pd
import pinocchio as pin

from pimann.core.contacts import (
    FootKinematics,
    contacts_from_heights,
    foot_kinematics,
    frame_period,
    trajectory_configurations,
)
from pimann.core.errors import PimannError, about
from pimann.core.params import ContactParams, EvaluateParams
from pimann.core.robot import LEG_JOINTS, SOLE_CORNERS, Robot, load_robot
from pimann.core.rotations import quaternion_xyzw_matrices, rpy_arcsin_pitch, to_heading_frame
from pimann.core.trajectory import Trajectory, iter_collection, read_trajectory
from pimann.evaluate.gait import trajectory_gait
from pimann.evaluate.sliding import (
    SHARE_METRICS,
    authors_sole_velocities,
    contact_point_velocities,
    manifold_velocities,
    phase_share_metrics,
    skating_ratio,
    sole_jacobians,
    support_foot_velocities,
)

SIDES = ("left", "right")
# the paper's baseline sliding RMSE (linear, angular): the claims and the data report compare
PAPER_BASELINE_RMSE = {"linear": 22.88, "angular": 17.74}
SQRT3 = math.sqrt(3.0)
WALK_TOUCHDOWNS = 2  # a rollout walks on steps: a glide of walk_distance without them does not
FOOT_VELOCITY_FRAMES = {
    "local_world_aligned": pin.LOCAL_WORLD_ALIGNED,  # the paper's text
    "world": pin.WORLD,  # the authors' code (inertial-fixed)
}


# the sliding metrics: name (in `support_rmse_<name>_*`) -> (part, level, representation,
# contacts); representation None: `evaluate.foot_velocity_frame`; contacts "rule": the evaluate
# rule on the lowest sole corner (or the file's flags), "origin": on the sole origin's height,
# "authors": that trigger as the authors' rollout runs it (both feet on at the start, fed from
# the first step's new state). `paper_*` is the authors' metric (the claims' and the paper's
# figures'), the rest ours beside it.
SLIDING = {
    "paper_linear": ("linear", "authors", "world", "authors"),
    "paper_angular": ("angular", "authors", "world", "authors"),
    "linear": ("linear", "velocity", None, "rule"),
    "angular": ("angular", "velocity", None, "rule"),
    "linear_world": ("linear", "velocity", "world", "rule"),
    "linear_position": ("linear", "position", None, "rule"),
    "angular_position": ("angular", "position", None, "rule"),
    "linear_position_world": ("linear", "position", "world", "rule"),
    "linear_origin_contacts": ("linear", "velocity", None, "origin"),
    "linear_position_origin_contacts": ("linear", "position", None, "origin"),
    "contact_point": ("linear", "contact_point", "local_world_aligned", "rule"),
}
PAPER_SLIDING = ("paper_linear", "paper_angular")  # the authors' metric: frame 0 has no step


def in_representation(velocities: np.ndarray, positions: np.ndarray, frame: str) -> np.ndarray:
    """(..., 6) LOCAL_WORLD_ALIGNED sole velocities in `frame` (a FOOT_VELOCITY_FRAMES key).

    WORLD keeps the angular part and moves the linear one to the world origin: v - omega x p.
    """
    if FOOT_VELOCITY_FRAMES[frame] == pin.LOCAL_WORLD_ALIGNED:
        return velocities
    out = velocities.copy()
    out[..., :3] -= np.cross(velocities[..., 3:], positions)
    return out


@dataclasses.dataclass
class Analysis:
    """Per-frame quantities every metric and plot is computed from (`analyse`)."""

    time: np.ndarray
    feet: FootKinematics  # velocities: velocity level, in the params' representation
    sole_velocities: dict[str, np.ndarray]  # level -> (T, 2, 6) LOCAL_WORLD_ALIGNED
    frame: str  # evaluate.foot_velocity_frame
    contacts: np.ndarray  # (T, 2) bool
    origin_contacts: np.ndarray  # (T, 2) bool, the trigger on the sole origins' heights
    authors_contacts: np.ndarray  # (T, 2) bool, ... as the authors' rollout runs it
    contacts_source: str
    joint_velocities_source: str
    displacement: np.ndarray  # (T, 3) base, start heading frame
    angles: np.ndarray  # (T, 3) roll, pitch, yaw changes since the first frame

    def velocities(self, level: str, frame: str | None = None) -> np.ndarray:
        """(T, 2, 6) sole velocities of a level in a representation (None: the params')."""
        return in_representation(
            self.sole_velocities[level], self.feet.positions, frame or self.frame
        )

    def contacts_of(self, name: str) -> np.ndarray:
        """(T, 2) the contacts a `SLIDING` metric counts."""
        rule = SLIDING[name][3]
        if rule == "authors":
            return self.authors_contacts
        return self.origin_contacts if rule == "origin" else self.contacts

    def rms(self, name: str) -> np.ndarray:
        """(T, 2) per-frame RMS of a `SLIDING` metric, every frame (contact or not)."""
        part, level, frame, _ = SLIDING[name]
        components = slice(0, 3) if part == "linear" else slice(3, 6)
        return np.sqrt(np.mean(self.velocities(level, frame)[..., components] ** 2, axis=-1))


def base_drift(trajectory: Trajectory) -> tuple[np.ndarray, np.ndarray]:
    """(T, 3) base displacement in the first frame's heading frame, (T, 3) rpy changes."""
    angles = rpy_arcsin_pitch(quaternion_xyzw_matrices(trajectory.base_quaternion_xyzw))
    angles[:, 2] = np.unwrap(angles[:, 2])
    yaw0 = angles[0, 2]
    delta = np.asarray(trajectory.base_position, dtype=float) - trajectory.base_position[0]
    return to_heading_frame(delta, yaw0), angles - angles[0]


def _check_time(trajectory: Trajectory) -> np.ndarray:
    time = np.asarray(trajectory.time, dtype=float)
    if len(time) < 2:
        raise PimannError(trajectory.source, f"needs at least 2 frames, has {len(time)}")
    bad = np.flatnonzero(np.diff(time) <= 0)
    if len(bad):
        raise PimannError(
            trajectory.source, "time is not strictly increasing", frame=int(bad[0]) + 1
        )
    return time


def analyse(
    trajectory: Trajectory,
    robot: Robot,
    params: EvaluateParams,
    contacts: ContactParams,
    file_contacts: bool = True,
) -> Analysis:
    """Both levels' sole velocities, contacts (the file's flags, unless `file_contacts` is off
    or there are none: the evaluate rule) and base drift of one trajectory."""
    time = _check_time(trajectory)
    configurations = trajectory_configurations(robot, trajectory)
    differences = manifold_velocities(robot.model, configurations, time)
    joint_velocities, joint_source = differences[:, robot.v_index], "differences"
    if trajectory.joint_velocities is not None:
        joint_velocities, joint_source = np.asarray(trajectory.joint_velocities), "file"
    feet = foot_kinematics(robot, configurations, differences)  # LOCAL_WORLD_ALIGNED
    step_velocities = joint_velocities
    if trajectory.joint_velocities is None:  # the authors' first differences, sdot_i ending at i
        step_velocities = np.zeros_like(joint_velocities)
        step_velocities[1:] = (
            np.diff(configurations[:, robot.q_index], axis=0) / np.diff(time)[:, None]
        )
    jacobians = sole_jacobians(robot, configurations)
    levels = {
        "velocity": support_foot_velocities(robot, jacobians, joint_velocities, feet.heights),
        "position": feet.velocities,
        "authors": authors_sole_velocities(robot, configurations, jacobians, step_velocities, feet),
        "contact_point": contact_point_velocities(feet.velocities, feet.rotations, SOLE_CORNERS),
    }
    feet.velocities = in_representation(
        levels["velocity"], feet.positions, params.foot_velocity_frame
    )
    dt, rule = frame_period(trajectory), contacts
    if file_contacts and trajectory.contacts is not None:
        contacts, contacts_source = np.asarray(trajectory.contacts, dtype=bool), "file"
    else:
        detected = contacts_from_heights(feet.heights, dt, rule)
        contacts, contacts_source = detected, "detected"
    origin_contacts = contacts_from_heights(feet.positions[..., 2], dt, rule)
    authors_contacts = np.zeros_like(origin_contacts)  # frame 0: no step, nothing counted
    authors_contacts[1:] = contacts_from_heights(feet.positions[1:, :, 2], dt, rule, initial=True)
    displacement, angles = base_drift(trajectory)
    return Analysis(
        time,
        feet,
        levels,
        params.foot_velocity_frame,
        contacts,
        origin_contacts,
        authors_contacts,
        contacts_source,
        joint_source,
        displacement,
        angles,
    )


def sliding_frames(
    trajectory: Trajectory,
    robot: Robot | None,
    params: EvaluateParams,
    contacts: ContactParams,
    file_contacts: bool = True,
) -> dict[str, np.ndarray]:
    """{`SLIDING` name: (T, 2) contact-masked per-frame RMS}, plus "contacts" (T, 2).

    Summed over the frames these are the total RMSE's per-foot sums. `file_contacts=False`
    detects the contacts by the evaluate rule even where the file has its own.
    """
    robot = robot or load_robot("retarget")
    a = analyse(trajectory, robot, params, contacts, file_contacts)
    out = {name: np.where(a.contacts_of(name), a.rms(name), 0.0) for name in SLIDING}
    out["contacts"] = a.contacts
    return out


def _finite_or_none(value: float) -> float | None:
    return float(value) if np.isfinite(value) else None


def _mean_where(values: np.ndarray, mask: np.ndarray) -> float | None:
    return _finite_or_none(values[mask].mean()) if mask.any() else None


def _joint_velocity_gap(trajectory: Trajectory, time: np.ndarray) -> float | None:
    """RMS (rad/s) of the file's joint velocities against the joints' central differences: how
    far the velocity level's predicted velocities are from the joints a robot would track."""
    if trajectory.joint_velocities is None:
        return None
    differences = np.gradient(trajectory.joint_positions, time, axis=0)
    return float(np.sqrt(np.mean((differences - trajectory.joint_velocities) ** 2)))


def foot_split(a: Analysis) -> dict[str, float]:
    """Where the position-level linear sliding sum comes from (each a total, like the sum).

    `lower_foot`: frames where the foot in contact is the lower one (the one leg odometry and
    the velocity level hold); `other_foot`: the other foot while it is counted down too
    (double support, a lift-off or touchdown under the trigger's hold), split into its
    horizontal (|v_xy| / sqrt 3: it glides) and vertical (|v_z| / sqrt 3: it rises or lands)
    parts, which add up to it in quadrature frame by frame.
    """
    lower = np.zeros_like(a.contacts)
    lower[np.arange(len(lower)), np.argmin(a.feet.heights, axis=1)] = True  # ties: the left
    velocity = a.velocities("position")[..., :3]
    other, linear = a.contacts & ~lower, a.rms("linear_position")
    parts = {
        "lower_foot": (a.contacts & lower, linear),
        "other_foot": (other, linear),
        "other_foot_horizontal": (other, np.linalg.norm(velocity[..., :2], axis=-1) / SQRT3),
        "other_foot_vertical": (other, np.abs(velocity[..., 2]) / SQRT3),
    }
    return {
        f"support_rmse_linear_position_{name}_total": float(np.where(m, v, 0.0).sum(0).mean())
        for name, (m, v) in parts.items()
    }


def leg_joint_speed_max(joints: np.ndarray, time: np.ndarray) -> float:
    """rad/s: the largest first-difference speed of the leg joints (`LEG_JOINTS`) of joints
    (T, nj) at `time` (T,); 0 for a single frame."""
    if len(joints) < 2:
        return 0.0
    legs = np.asarray(joints, float)[:, LEG_JOINTS]
    return float((np.abs(np.diff(legs, axis=0)) / np.diff(np.asarray(time, float))[:, None]).max())


def trajectory_metrics(
    trajectory: Trajectory,
    robot: Robot | None,
    params: EvaluateParams,
    contacts: ContactParams,
    file_contacts: bool = True,
) -> dict[str, Any]:
    """The paper's metrics of one trajectory, as JSON-serialisable scalars (None: undefined).

    `file_contacts=False`: the contacts by the evaluate rule even where the file has flags
    (the data measured as the rollouts are)."""
    robot = robot or load_robot("retarget")
    a = analyse(trajectory, robot, params, contacts, file_contacts)
    feet = a.feet  # the gait measures (pimann.evaluate.gait) reuse this pass's soles
    corners = a.sole_velocities["contact_point"]
    base_xy, yaw = a.displacement[:, :2], a.angles[:, 2]
    gait = trajectory_gait(
        trajectory,
        feet.heights,
        feet.positions,
        feet.pitches,
        corners,
        base_xy,
        yaw,
        params,
        contacts,
        a.contacts if a.contacts_source == "detected" else None,  # the rule's, never a file's
    )
    contacts = a.contacts
    metrics: dict[str, Any] = {
        "source": trajectory.source,
        "frames": len(a.time),
        "duration_s": float(a.time[-1] - a.time[0]),
        "rate_hz": 1.0 / frame_period(trajectory),
        "contacts_source": a.contacts_source,
        "joint_velocities_source": a.joint_velocities_source,
    }
    for name in SLIDING:
        rms = a.rms(name)
        sums = np.where(a.contacts_of(name), rms, 0.0).sum(axis=0)
        for side, value in zip(SIDES, sums, strict=True):
            metrics[f"support_rmse_{name}_{side}"] = float(value)
        metrics[f"support_rmse_{name}_total"] = float(sums.mean())
        if name in ("linear", "angular"):
            metrics[f"support_rmse_{name}_mean_per_contact_frame"] = _mean_where(rms, contacts)
    metrics.update(foot_split(a))
    rms = {name: a.rms(name) for name in SHARE_METRICS}
    metrics.update(phase_share_metrics(rms, contacts, metrics["rate_hz"]))
    for suffix, level in (("", "velocity"), ("_position", "position")):
        horizontal_speed = np.linalg.norm(a.velocities(level)[..., :2], axis=-1)
        metrics[f"contact_foot_speed_mean{suffix}"] = _mean_where(horizontal_speed, contacts)
    metrics["skating_ratio"] = _finite_or_none(
        skating_ratio(a.time, a.feet.positions, a.feet.heights, params)
    )
    metrics["contact_fraction_left"] = float(contacts[:, 0].mean())
    metrics["contact_fraction_right"] = float(contacts[:, 1].mean())
    metrics["double_support_fraction"] = float(contacts.all(axis=1).mean())
    metrics["touchdowns"] = int(np.sum(~contacts[:-1] & contacts[1:]))
    metrics["joint_velocity_gap_rms"] = _joint_velocity_gap(trajectory, a.time)
    pitch = np.abs(a.feet.pitches)
    metrics["sole_pitch_max_abs"] = float(pitch.max())
    metrics["contact_sole_pitch_max_abs"] = float(pitch[contacts].max()) if contacts.any() else None
    final = a.displacement[-1]
    for name, value in zip(("x", "y", "z"), final, strict=True):
        metrics[f"drift_{name}"] = float(value)
    for name, value in zip(("roll", "pitch", "yaw"), a.angles[-1], strict=True):
        metrics[f"drift_{name}"] = float(value)
    metrics["drift_y_max_abs"] = float(np.abs(a.displacement[:, 1]).max())
    metrics["drift_yaw_max_abs"] = float(np.abs(a.angles[:, 2]).max())
    walked = final[0] >= params.walk_distance and metrics["touchdowns"] >= WALK_TOUCHDOWNS
    metrics["walks"] = bool(walked)
    metrics.update(gait)
    # how far the lowest sole corner goes below the floor (a contact-consistent variant's check)
    metrics["penetration_max_m"] = float(max(0.0, -a.feet.heights.min()))
    # the legs' largest joint speed (a contact-consistent variant folds its legs at a release)
    metrics["leg_joint_speed_max_rad_s"] = leg_joint_speed_max(trajectory.joint_positions, a.time)
    return metrics


def trajectory_time_series(
    trajectory: Trajectory, robot: Robot | None, params: EvaluateParams, contacts: ContactParams
) -> pd.DataFrame:
    """Per-frame drift, foot heights, pitches, contacts and sliding, one row per frame."""
    robot = robot or load_robot("retarget")
    a = analyse(trajectory, robot, params, contacts)
    columns: dict[str, np.ndarray] = {"time": a.time - a.time[0]}
    for k, name in enumerate(("base_x", "base_y", "base_z")):
        columns[name] = a.displacement[:, k]
    for k, name in enumerate(("base_roll", "base_pitch", "base_yaw")):
        columns[name] = a.angles[:, k]
    heights, pitches = a.feet.heights, a.feet.pitches
    rms = {name: a.rms(name) for name in ("linear", "angular", "linear_position")}
    for f, side in enumerate(SIDES):
        columns[f"{side}_foot_height"] = heights[:, f]
        columns[f"{side}_sole_x"] = a.feet.positions[:, f, 0]
        columns[f"{side}_sole_y"] = a.feet.positions[:, f, 1]
        columns[f"{side}_sole_z"] = a.feet.positions[:, f, 2]
        columns[f"{side}_sole_pitch"] = pitches[:, f]
        columns[f"{side}_contact"] = a.contacts[:, f]
        for name, values in rms.items():
            columns[f"{side}_rms_{name}"] = values[:, f]
        columns[f"{side}_speed_xy"] = np.linalg.norm(a.feet.velocities[:, f, :2], axis=-1)
    return pd.DataFrame(columns)


def aggregate(
    runs: Mapping[Any, Mapping[str, Any]] | Sequence[Mapping[str, Any]],
) -> dict[str, dict[str, float | int | None]]:
    """Median and spread over runs (e.g. the five seeds) of every numeric metric.

    Booleans (e.g. `walks`) become 0/1, so their mean is the fraction of runs. Metrics that are
    None in some runs are summarised over the others (`n` says how many).
    """
    dicts = list(runs.values()) if isinstance(runs, Mapping) else list(runs)
    numeric = int | float | bool  # a metric None in the first run still counts from the others
    keys = list(dict.fromkeys(k for d in dicts for k, v in d.items() if isinstance(v, numeric)))
    summary: dict[str, dict[str, float | int | None]] = {}
    for key in keys:
        values = np.array(
            [float(d[key]) for d in dicts if isinstance(d.get(key), int | float | bool)]
        )
        values = values[np.isfinite(values)]
        if len(values) == 0:
            summary[key] = {"n": 0}
            continue
        q1, median, q3 = np.percentile(values, [25, 50, 75])
        summary[key] = {
            "n": len(values),
            "median": float(median),
            "mean": float(values.mean()),
            "q1": float(q1),
            "q3": float(q3),
            "iqr": float(q3 - q1),
            "min": float(values.min()),
            "max": float(values.max()),
        }
    return summary


def metrics_for_file(
    path: str | Path, robot: Robot | None, params: EvaluateParams, contacts: ContactParams
) -> dict[str, Any]:
    """`pimann metrics FILE`: the metrics of the file's trajectory, or {group: metrics} for a
    collection file."""
    path = Path(path)
    is_collection = False
    try:
        with h5py.File(path, "r") as file:
            is_collection = "time" not in file
    except OSError:
        pass  # read_trajectory raises the proper PimannError below
    if not is_collection:
        with about(path):
            return trajectory_metrics(read_trajectory(path), robot, params, contacts)
    result = {}
    for name, trajectory in iter_collection(path):
        with about(path, f"group {name!r}"):
            result[name] = trajectory_metrics(trajectory, robot, params, contacts)
    if not result:
        raise PimannError(path, "holds no trajectory")
    return result
