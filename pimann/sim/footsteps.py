"""Footsteps and contact timing from a generated trajectory's contacts (docs/controllers.md).

The generated joints are not replayed: each contact phase of a foot becomes one footstep
(mean sole position and yaw over the phase), time is slowed by `speed_scale` and the walking
path's translations are scaled by `step_scale` (paper: 0.33x, 0.4x), starting from the
simulated robot's own standing feet. A double-support hold is added before and after, and
every touchdown gets at least `min_double_s` of double support.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pinocchio as pin

from pimann.core.contacts import true_runs
from pimann.core.errors import PimannError
from pimann.core.params import SimulateParams
from pimann.core.robot import LEFT_SOLE, RIGHT_SOLE, Robot
from pimann.core.rotations import rot_z, to_heading_frame
from pimann.core.trajectory import Trajectory
from pimann.sim.wbc import SOLE_HEIGHT


@dataclasses.dataclass
class Footsteps:
    """One foot's footsteps: flat sole poses (x, y, yaw) and contact intervals [t_on, t_off]."""

    positions: np.ndarray  # (n, 2)
    yaws: np.ndarray  # (n,)
    t_on: np.ndarray  # (n,)
    t_off: np.ndarray  # (n,)

    def __len__(self) -> int:
        return len(self.yaws)


@dataclasses.dataclass
class FootstepPlan:
    """Both feet's footsteps on the robot's time axis (s), plus the swing profile."""

    feet: tuple[Footsteps, Footsteps]  # left, right
    duration: float
    swing_height: float
    trajectory_start: float  # generated time at robot time `hold` (for posture references)
    hold: float  # s of double support before the first step
    speed_scale: float

    def in_contact(self, side: int, t: float) -> bool:
        steps = self.feet[side]
        return bool(np.any((steps.t_on <= t + 1e-9) & (t <= steps.t_off + 1e-9)))

    def stance_index(self, side: int, t: float) -> int | None:
        steps = self.feet[side]
        hits = np.flatnonzero((steps.t_on <= t + 1e-9) & (t <= steps.t_off + 1e-9))
        return int(hits[0]) if len(hits) else None

    def foot_pose(self, side: int, t: float) -> tuple[np.ndarray, float]:
        """Sole position (3,) and yaw at time t; a quintic swing between footsteps.

        z is the sole frame's height: -SOLE_HEIGHT puts the foot boxes on the floor.
        """
        steps = self.feet[side]
        t = float(np.clip(t, 0.0, self.duration))
        k = int(np.searchsorted(steps.t_on, t, side="right")) - 1
        k = max(k, 0)
        if t <= steps.t_off[k] or k + 1 >= len(steps):
            xy, yaw = steps.positions[k], steps.yaws[k]
            return np.array([xy[0], xy[1], -SOLE_HEIGHT]), float(yaw)
        s = (t - steps.t_off[k]) / (steps.t_on[k + 1] - steps.t_off[k])
        blend = s**3 * (10.0 - 15.0 * s + 6.0 * s**2)  # quintic, zero velocity and acceleration
        xy = steps.positions[k] + blend * (steps.positions[k + 1] - steps.positions[k])
        yaw = steps.yaws[k] + blend * _wrap(steps.yaws[k + 1] - steps.yaws[k])
        height = self.swing_height * 64.0 * s**3 * (1.0 - s) ** 3  # peak swing_height at s = 0.5
        return np.array([xy[0], xy[1], height - SOLE_HEIGHT]), float(yaw)

    def sole_placement(self, side: int, t: float) -> pin.SE3:
        position, yaw = self.foot_pose(side, t)
        return pin.SE3(rot_z(yaw), position)

    def generated_time(self, t: float) -> float:
        """The generated trajectory's time that robot time t replays (clamped to its span)."""
        return self.trajectory_start + max(t - self.hold, 0.0) * self.speed_scale


def _wrap(angle):
    return (np.asarray(angle) + np.pi) % (2.0 * np.pi) - np.pi


def _mean_angle(angles: np.ndarray) -> float:
    return float(np.angle(np.exp(1j * np.asarray(angles)).mean()))


def compose(pose: np.ndarray, increment: np.ndarray) -> np.ndarray:
    """(x, y, yaw) pose moved by an increment expressed in its own frame."""
    c, s = np.cos(pose[2]), np.sin(pose[2])
    dx, dy, dyaw = increment
    return np.array([pose[0] + c * dx - s * dy, pose[1] + s * dx + c * dy, pose[2] + dyaw])


def relative(pose: np.ndarray, other: np.ndarray) -> np.ndarray:
    """The increment that takes `pose` to `other`, in `pose`'s frame (inverse of compose)."""
    dx, dy = to_heading_frame(np.asarray(other[:2]) - np.asarray(pose[:2]), pose[2])
    return np.array([dx, dy, float(_wrap(other[2] - pose[2]))])


def mid_feet(feet: np.ndarray) -> np.ndarray:
    """(..., 2 feet, 3) sole x, y, yaw -> (..., 3) the pose midway between the feet."""
    yaw = np.angle(np.exp(1j * feet[..., 2]).mean(axis=-1))
    return np.concatenate([feet[..., :2].mean(axis=-2), yaw[..., None]], axis=-1)


def _stance(feet: np.ndarray) -> tuple[np.ndarray, float]:
    """The mid-feet pose and half the lateral distance between the feet (2, 3)."""
    mid = mid_feet(feet)
    return mid, 0.5 * (relative(mid, feet[0])[1] - relative(mid, feet[1])[1])


def _rescale_footsteps(
    generated: list[np.ndarray],
    runs: list[list[tuple[int, int]]],
    standing: np.ndarray,
    step_scale: float,
) -> list[np.ndarray]:
    """Footstep poses (x, y, yaw) for the robot from the generated ones.

    Each footstep, moved sideways to the walking path by half the generated stance width,
    gives a path pose; the path's translations (in its own frame) are scaled by
    `step_scale`, its turns kept, and the robot's feet put back at half its own stance
    width. Scaling the feet one by one would let a turn cross them.
    """
    path_gen, width_gen = _stance(np.array([generated[0][0], generated[1][0]]))
    path_robot, width_robot = _stance(standing)
    out = [np.empty_like(generated[0]), np.empty_like(generated[1])]
    out[0][0], out[1][0] = standing[0], standing[1]
    order = sorted((runs[s][i][0], s, i) for s in (0, 1) for i in range(1, len(runs[s])))
    for _, side, i in order:
        sign = 1.0 if side == 0 else -1.0
        path = compose(generated[side][i], np.array([0.0, -sign * width_gen, 0.0]))
        step = relative(path_gen, path)
        path_gen = path
        path_robot = compose(path_robot, step * [step_scale, step_scale, 1.0])
        out[side][i] = compose(path_robot, np.array([0.0, sign * width_robot, 0.0]))
    return out


def clean_contacts(
    contacts: np.ndarray, time: np.ndarray, min_contact: float, min_swing: float
) -> np.ndarray:
    """Contacts without short blips, both feet down at both ends, never both feet up.

    A contact shorter than `min_contact` or a swing shorter than `min_swing` is flipped (a
    shuffle the robot could not follow); a flight phase is removed by landing the next foot
    at its start.
    """
    contacts = np.asarray(contacts, dtype=bool).copy()
    contacts[0] = contacts[-1] = True  # first, so that a lift it cuts short is dropped too
    for side in (0, 1):
        for value, shortest in ((True, min_contact), (False, min_swing)):  # blips, then lifts
            flags = contacts[:, side] == value
            for start, end in true_runs(flags):
                # a lift cut by the clip's end counts too: it would land at once
                inner = start > 0 and (end < len(flags) or not value)
                if inner and time[end - 1] - time[start] < shortest:
                    contacts[start:end, side] = not value
    for start, end in true_runs(~contacts.any(axis=1)):
        later = contacts[end:]
        first = [np.argmax(later[:, s]) if later[:, s].any() else len(later) for s in (0, 1)]
        contacts[start:end, int(np.argmin(first))] = True
    return contacts


def _widen_double_support(feet: list[Footsteps], minimum: float) -> None:
    """Give every touchdown at least `minimum` of double support before the other foot lifts.

    Detected contacts often hand over in one sample; the ZMP needs time to cross between the
    feet. Half the deficit comes out of each foot's swing.
    """
    for side in (0, 1):
        landing, other = feet[side], feet[1 - side]
        for j in range(1, len(landing)):
            touchdown = landing.t_on[j]
            k = np.flatnonzero((other.t_on <= touchdown + 1e-9) & (touchdown <= other.t_off + 1e-9))
            if not len(k) or k[0] == len(other) - 1:
                continue
            k = k[0]
            deficit = minimum - (other.t_off[k] - touchdown)
            if deficit <= 0:
                continue
            room = min(landing.t_on[j] - landing.t_off[j - 1], other.t_on[k + 1] - other.t_off[k])
            shift = min(0.5 * deficit, 0.25 * room)  # never eat more than half a swing
            landing.t_on[j] -= shift
            other.t_off[k] += shift


def sole_trajectories(robot: Robot, trajectory: Trajectory) -> np.ndarray:
    """(T, 2, 3): x, y, yaw of the left and right soles along the trajectory."""
    out = np.empty((len(trajectory), 2, 3))
    frames = [robot.frame_id(LEFT_SOLE), robot.frame_id(RIGHT_SOLE)]
    for k in range(len(trajectory)):
        q = robot.configuration(
            trajectory.base_position[k],
            trajectory.base_quaternion_xyzw[k],
            trajectory.joint_positions[k],
        )
        pin.framesForwardKinematics(robot.model, robot.data, q)
        for side, frame in enumerate(frames):
            placement = robot.data.oMf[frame]
            out[k, side, :2] = placement.translation[:2]
            out[k, side, 2] = np.arctan2(placement.rotation[1, 0], placement.rotation[0, 0])
    return out


def extract_footsteps(
    robot: Robot,
    trajectory: Trajectory,
    params: SimulateParams,
    standing_feet: np.ndarray,
) -> FootstepPlan:
    """The footstep plan of `trajectory`, starting from the robot's standing soles.

    `standing_feet` (2, 3): x, y, yaw of the simulated robot's left and right soles. The
    generated footsteps are expressed relative to the frame midway between the generated
    initial feet, and each foot's displacements are scaled by `step_scale`.
    """
    if trajectory.contacts is None:
        raise PimannError(trajectory.source, "trajectory has no contacts: cannot extract footsteps")
    if len(trajectory) < 2:
        raise PimannError(trajectory.source, "trajectory too short for footsteps")
    time = np.asarray(trajectory.time, dtype=float)
    robot_time = (time - time[0]) / params.speed_scale
    contacts = clean_contacts(
        trajectory.contacts, robot_time, params.min_phase_s, params.min_swing_s
    )
    soles = sole_trajectories(robot, trajectory)
    hold = params.zmp_hold_s
    last = robot_time[-1] + hold
    runs = [true_runs(contacts[:, side]) for side in (0, 1)]
    generated = [
        np.array(
            [
                [*soles[a:b, side, :2].mean(axis=0), _mean_angle(soles[a:b, side, 2])]
                for a, b in runs[side]
            ]
        )
        for side in (0, 1)
    ]
    poses = _rescale_footsteps(generated, runs, standing_feet, params.step_scale)
    feet = []
    for side in (0, 1):
        t_on = np.array([robot_time[a] + hold for a, _ in runs[side]])
        # a contact sample holds until the next one: [time[a], time[b])
        t_off = np.array([robot_time[min(b, len(time) - 1)] + hold for _, b in runs[side]])
        t_on[0] = 0.0
        t_off[-1] = last + params.end_hold_s
        feet.append(Footsteps(poses[side][:, :2], poses[side][:, 2], t_on, t_off))
    _widen_double_support(feet, params.min_double_s)
    return FootstepPlan(
        feet=(feet[0], feet[1]),
        duration=last + params.end_hold_s,
        swing_height=params.swing_height,
        trajectory_start=float(time[0]),
        hold=hold,
        speed_scale=params.speed_scale,
    )
