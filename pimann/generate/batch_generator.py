"""Batched generation: many rollouts of one model advance together, one network call a step.

Evaluation multiplies rollouts (scenarios x benchmark clips x steering x seeds) and a network
evaluated for one sample at a time is mostly overhead: a batch of B rows (each its own
script and steering switch) costs one network call, one vectorised leg-odometry pass
(pimann.generate.leg_odometry), one Schmitt-trigger update and one steering correction per step,
with no Python loop over rows inside a step. The rules are pimann.generate.rollout_batch's (its
module docstring); each row keeps its own state (stopped, stop blend, goal, path, restart).
`pimann.generate.rollout_batch.generate_batch` drives a `BatchGenerator` over the rows' scripts and
a single rollout (`generate_rollout`) is a batch of one, so a row of a batch equals the same
rollout alone (float64: to rounding).

Rows end at different steps: a row past its script's end is held still (stopped) and its
frames are not kept; the network is evaluated on the walking rows only.
"""

from __future__ import annotations

import time
from collections.abc import Sequence

import numpy as np
import torch

from pimann.core.contacts import SchmittTrigger
from pimann.core.errors import PimannError
from pimann.core.params import ConsistentParams, ContactParams, RolloutParams
from pimann.core.robot import Robot
from pimann.core.rotations import (
    exp_so3,
    from_heading_frame,
    matrix_to_rpy,
    roll_pitch,
    rot_z,
    rotation_rpy,
    yaw_of,
    yaw_only,
)
from pimann.core.trajectory import Trajectory
from pimann.generate.contact_consistent import InLoopHold
from pimann.generate.future_window import command_weights, next_future_matrix
from pimann.generate.leg_odometry import Odometry
from pimann.generate.rollout_network import RolloutNetwork
from pimann.generate.steering import CarrotGoal, steer
from pimann.learn.feature_layout import FeatureLayout, Normalisation
from pimann.learn.features import clip_phase, first_differences
from pimann.learn.gait_phase import unit_phase
from pimann.learn.standing import StandingPose

SECTIONS = ("commands", "inputs", "network", "steering", "odometry", "contacts")  # timed


def data_start(
    trajectories: Sequence[Trajectory], steps: Sequence[int], generator: BatchGenerator
) -> None:
    """Start `generator`'s rows inside the data: row r as if frame steps[r] - 1 of
    trajectories[r] had just been generated (`BatchGenerator.start_in_gait` from the clip's
    first differences, pimann.learn.features), so that its first step builds that clip's x at
    steps[r]."""
    layout, length = generator.layout, generator.history_length
    out_offsets = np.asarray(layout.output_offsets)
    rows: list[tuple[np.ndarray, ...]] = []
    phases: list[np.ndarray] = []
    for trajectory, k in zip(trajectories, steps, strict=True):
        rotations, linear, angular, joint_velocities = first_differences(
            trajectory, generator.projected
        )
        phase = clip_phase(trajectory, layout)
        if phase is not None:
            phases.append(phase[k - 1])
        if k - length + 1 < 1 or k + out_offsets.max() >= len(rotations):
            raise PimannError(trajectory.source, f"step {k} leaves no room for the windows")
        frames = np.arange(k - length + 1, k + 1)
        ahead = k + out_offsets
        fed_position, fed_rpy = layout.pose(
            trajectory.base_position[k - 1], matrix_to_rpy(rotations[: k + 1])[k - 1]
        )
        rows.append(
            (
                np.stack([linear[frames], angular[frames]], axis=1),  # (L, 2, 3), world frame
                np.stack([linear[ahead], angular[ahead]]) @ rotations[k],  # R_k^T v, (2, F, 3)
                trajectory.joint_positions[k - 1],
                joint_velocities[k - 1],
                fed_position,
                fed_rpy,
                trajectory.base_position[k - 1],
                rotations[k - 1],
                rotations[k],
            )
        )
    history, future, joints, velocities, fed_position, fed_rpy, position, rotation, ahead = (
        np.stack(part) for part in zip(*rows, strict=True)
    )
    generator.start_in_gait(
        history,
        future,
        (joints, velocities, fed_position, fed_rpy),
        position,
        rotation,
        ahead,
        phase=np.stack(phases) if phases else None,
    )


class BatchGenerator:
    """The rows' state and the per-step rules (pimann.generate.rollout_batch's docstring), all
    rows at once.

    Per step only what some row needs is computed (a stop check while a row stands, the blend
    while a row returns to standing, steering for steered rows): one rollout alone costs
    little more than a one-rollout generator would, and a batch shares the fixed cost.
    """

    def __init__(
        self,
        model: torch.nn.Module,
        layout: FeatureLayout,
        stats: Normalisation,
        params: RolloutParams,
        steering: np.ndarray,
        robot: Robot,
        contact_params: ContactParams,
        standing: StandingPose,
        consistent: ConsistentParams | None = None,
    ):
        """`consistent`: hold each foot in contact where it landed (pimann.generate.
        contact_consistent): the held legs in `held_joints` and `held_joint_velocities`, the leg
        odometry anchored on the held feet, the network fed its own legs (None: no hold, the
        raw rollout)."""
        rows = len(steering)
        self.params, self.network = params, RolloutNetwork(model, layout, stats)
        self.steering = np.asarray(steering, dtype=bool)
        self.standing_joints = standing.joints.copy()
        self.dt = 1.0 / float(layout.rate_hz)
        self.projected = layout.variant == "ground_projected"
        self.layout, self.xs, self.ys = layout, layout.x_slices, layout.y_slices  # computed
        self.input_dim = layout.input_dim
        in_offsets = np.asarray(layout.input_offsets)
        out_offsets = np.asarray(layout.output_offsets, dtype=float)
        self.current = layout.current_output
        self.history_length = max(1, int(-in_offsets.min()) + 1)
        self.past_offsets = np.asarray(layout.past_input_offsets(), dtype=int)
        if not np.all(np.diff(in_offsets) > 0):
            raise PimannError(None, "the input window's offsets must increase")
        self.future_matrix = next_future_matrix(layout)
        self.horizon = out_offsets.max() / layout.rate_hz
        self.goal_rule = CarrotGoal(params.goal_factor, self.horizon)  # while a command holds
        self.weights = command_weights(layout.output_offsets, params.command_blend_tau)[:, None]
        self.keep = 1.0 - self.weights
        rpy = np.array([*standing.roll_pitch, 0.0])
        self.standing_rpy = rpy * ([0.0, 0.0, 1.0] if self.projected else 1.0)
        self.standing_tilt = rotation_rpy(*self.standing_rpy[:2], 0.0)  # R_d = Rz(yaw_d) this
        self.timings, self._clock = dict.fromkeys(SECTIONS, 0.0), 0.0

        # the robots: standing still, the lowest sole corner on the floor
        self.rotation = np.tile(rotation_rpy(*self.standing_rpy), (rows, 1, 1))
        self.joints = np.tile(standing.joints, (rows, 1))
        self.joint_velocities = np.zeros_like(self.joints)
        # the gait phase's (cos, sin) pairs (features.gait_phase, none without it): 0 at the
        # start, held while stopped
        self.phase = np.tile([1.0, 0.0], (rows, len(layout.gait_phase_names) // 2))
        self.yaw = np.full(rows, float(self.standing_rpy[2]))  # unwrapped
        self.heading = yaw_of(self.rotation)  # wrapped
        self.odometry = Odometry(robot, rows)
        lowest = self.odometry.rotated_corners(self.rotation, self.joints)[..., 2, :]
        first = np.zeros((rows, 3))
        first[:, 2] = -lowest.min(axis=(1, 2))
        self.position, _, self.foot = self.odometry.place(self.rotation, self.joints, first)
        # R_{k+1} = R_k exp(omega dt) from the walking rows' last prediction: y_k's window is of
        # frame k + 1, its sample at offset 0 the base motion from frame k to k + 1
        self.next_rotation = self.rotation.copy()
        self.contact_params = contact_params
        self.trigger = SchmittTrigger.from_params(contact_params, self.dt, np.ones((rows, 2), bool))
        self.contacts = self.trigger.state
        # the network's side: velocity history (world frame; (linear, angular) per sample) and
        # the corrected future (base frame)
        self.history = np.zeros((rows, self.history_length, 2, 3))
        self.head = np.zeros(rows, dtype=int)  # index of each row's newest history sample
        self.future = np.zeros((rows, 2, len(out_offsets), 3))
        self.y = np.zeros((rows, layout.output_dim))
        self.fed_position = self.position.copy()
        self.fed_rpy = np.tile(self.standing_rpy, (rows, 1))
        # the command side
        self.goal, self.desired_yaw = np.full((rows, 3), np.nan), self.yaw.copy()
        self.path, self.has_path = np.zeros((rows, 3)), np.zeros(rows, dtype=bool)
        self.heading_velocity = np.zeros((rows, 2))  # the last motion command's (heading frame)
        self.stopped, self.stand_since = np.ones(rows, dtype=bool), np.zeros(rows, dtype=int)
        self.stop_step, self.blending = np.zeros(rows, dtype=int), np.zeros(rows, dtype=bool)
        self.stop_joints, self.stop_roll_pitch = self.joints.copy(), np.zeros((rows, 2))
        self.hold = None
        # the legs held where the feet landed (`consistent`): what the rollout records; the
        # network is fed its own (self.joints), as without the hold
        self.held_joints = self.joints.copy()
        self.held_joint_velocities = self.joint_velocities.copy()
        if consistent is not None:
            self.hold = InLoopHold(robot, rows, consistent, contact_params, self.dt)
            self.timings["consistent"] = 0.0  # timed too: the hold's share of a step
            self._hold()

    def start_in_gait(
        self,
        history: np.ndarray,
        future: np.ndarray,
        state: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
        position: np.ndarray,
        rotation: np.ndarray,
        next_rotation: np.ndarray,
        phase: np.ndarray | None = None,
    ) -> None:
        """Every row walking from inside a gait, as if frame k - 1 had just been generated.

        `history` (B, L, 2, 3): linear and angular base velocities of frames k - L + 1 .. k
        (oldest first, world frame, L >= the input window's past span + 1); `future` (B, 2,
        F_out, 3): the window of frame k at the output offsets, in the base frame at k (what
        y_{k-1} predicts); `state`: joints, joint velocities, base position and roll-pitch-yaw
        at k - 1 as the network sees them (its fed-back pose); `position`, `rotation`: the base
        pose at k - 1, `next_rotation`: at k; `phase` (B, 2 or 4): the gait phase's (cos, sin) at
        k - 1, which a layout with the phase needs. diagnostics.teacher_forcing and the oracle
        test start rollouts of the data's own outputs this way.
        """
        rows, length = len(self.head), history.shape[1]
        if length < self.history_length:
            raise PimannError(
                None, f"a history of {length} frames; the window needs {self.history_length}"
            )
        self.history = np.ascontiguousarray(history[:, -self.history_length :], dtype=float)
        self.head = np.full(rows, self.history_length - 1)
        self.future = np.array(future, dtype=float)
        if self.layout.gait_phase != (phase is not None):
            raise PimannError(None, "a start with a gait phase exactly when the layout has one")
        joints, joint_velocities, fed_position, fed_rpy = state
        if phase is not None:
            self.phase = unit_phase(phase)
        self.joints = np.array(joints, float)
        self.joint_velocities = np.array(joint_velocities, float)
        self.held_joints = self.joints.copy()
        self.held_joint_velocities = self.joint_velocities.copy()
        self.fed_position, self.fed_rpy = np.array(fed_position, float), np.array(fed_rpy, float)
        self.rotation = np.array(rotation, float)
        self.next_rotation = np.array(next_rotation, float)
        self.heading = yaw_of(self.rotation)
        self.yaw = self.heading.copy()
        self.position, heights, self.foot = self.odometry.place(
            self.rotation, self.joints, np.array(position, float)
        )
        self.trigger = SchmittTrigger.from_params(
            self.contact_params, self.dt, heights <= self.contact_params.on_height
        )
        self.contacts = self.trigger.state
        self.stopped[:] = False
        self.desired_yaw = self.yaw.copy()

    @property
    def base_velocity(self) -> np.ndarray:
        """(B, 3) each row's newest linear base velocity of the history (world frame), as fed
        back: the network's t = 0 sample after blend and steering; 0 while stopped."""
        newest = self.history[np.arange(len(self.head)), self.head, 0]
        return np.where(self.stopped[:, None], 0.0, newest)

    def desired(self, rows: np.ndarray) -> np.ndarray:
        """R_d of `rows`: the commanded heading with the standing roll and pitch."""
        return rot_z(self.desired_yaw[rows]) @ self.standing_tilt

    def command(self, k: int, velocity, yaw_rate, stand, changed, active) -> None:
        """Goal, path and desired heading for step k (restarts and stops included)."""
        if changed.any():
            freeze = changed & stand  # the goal freezes at the path's point
            self.stand_since[freeze] = k
            frozen = np.where(self.has_path[:, None], self.path, self.position)
            self.goal[freeze] = frozen[freeze]
            start = changed & ~stand
            self.desired_yaw[start], self.heading_velocity[start] = self.yaw[start], velocity[start]
            self.path[start], self.has_path[start] = self.position[start], True
            restart = np.flatnonzero(start & self.stopped)
            if len(restart):  # restart the network from the standing state
                self.stopped[restart], self.blending[restart] = False, False
                self._start_windows(restart, velocity[restart], yaw_rate[restart])
                self.fed_position[restart] = self.position[restart]
                self.fed_rpy[restart, :2] = self.standing_rpy[:2]
                self.fed_rpy[restart, 2] = self.yaw[restart]
        move = ~stand  # a held command: the path (and the goal) move with it
        self.desired_yaw = self.desired_yaw + np.where(move, yaw_rate * self.dt, 0.0)
        direction = from_heading_frame(velocity, self.desired_yaw)
        self.path[:, :2] += np.where(move[:, None], direction * self.dt, 0.0)
        goal = self.goal_rule(self.path, self.desired(slice(None)), velocity)
        self.goal = np.where(move[:, None], goal, self.goal)
        if not active.all():  # past the script's end: held still, not kept
            self.blending &= active | self.stopped
            self.stopped |= ~active
        candidates = stand & ~self.stopped
        if candidates.any():
            stopping = candidates & self._stop_now(k)
            self.stopped |= stopping
            self.stop_step[stopping], self.blending[stopping] = k, True
            self.stop_joints[stopping] = self.joints[stopping]
            self.stop_roll_pitch[stopping] = roll_pitch(self.rotation[stopping])

    def _start_windows(self, rows: np.ndarray, velocity, yaw_rate) -> None:
        """Velocity windows at a start: zero (standing) or the command held (`start_history`)."""
        self.history[rows] = 0.0
        self.future[rows] = 0.0
        if self.params.start_history == "command":
            rotation = self.rotation[rows]
            linear = np.zeros((len(rows), 3))
            linear[:, :2] = from_heading_frame(velocity, yaw_of(rotation))
            self.history[rows, :, 0] = linear[:, None]
            self.history[rows, :, 1, 2] = yaw_rate[:, None]
            self.future[rows, 0] = linear[:, None] @ rotation  # R^T v
            self.future[rows, 1] = (rotation[:, 2] * yaw_rate[:, None])[:, None]

    def _stop_now(self, k: int) -> np.ndarray:
        """Under 'stand': at once without steering; at, or past, the goal with it."""
        offset = self.position[:, :2] - self.goal[:, :2]
        close = np.hypot(offset[:, 0], offset[:, 1]) <= self.params.goal_radius
        heading = from_heading_frame(self.heading_velocity, self.desired_yaw)
        passed = self.heading_velocity.any(axis=1) & (
            offset[:, 0] * heading[:, 0] + offset[:, 1] * heading[:, 1] >= 0
        )
        late = (k - self.stand_since) * self.dt >= self.params.stop_timeout_s
        return ~self.steering | close | passed | late

    def _standing(self, k: int, rotation: np.ndarray) -> None:
        """Stopped rows: joints and base roll/pitch blend to the standing pose, yaw kept."""
        self.joint_velocities[self.stopped] = 0.0
        rows = np.flatnonzero(self.blending)
        if not len(rows):
            return
        blend = max(self.params.stop_blend_s, self.dt)
        alpha = np.minimum(1.0, (k - self.stop_step[rows] + 1) * self.dt / blend)[:, None]
        joints = (1 - alpha) * self.stop_joints[rows] + alpha * self.standing_joints
        joints = np.where(alpha >= 1.0, self.standing_joints, joints)
        roll_pitch = (1 - alpha) * self.stop_roll_pitch[rows] + alpha * self.standing_rpy[:2]
        self.joint_velocities[rows] = (joints - self.joints[rows]) / self.dt
        self.joints[rows] = joints
        yaw = yaw_of(self.rotation[rows])
        rotation[rows] = rotation_rpy(roll_pitch[:, 0], roll_pitch[:, 1], yaw)

    def _inputs(self, rows: np.ndarray | slice, index: np.ndarray, base: np.ndarray) -> np.ndarray:
        """x of the walking rows (base orientations `base`, R_k): velocity windows in the base
        frame, joints, fed-back pose."""
        xs, n = self.xs, len(index)
        x = np.empty((n, self.input_dim))
        taken = (self.head[index, None] + self.past_offsets) % self.history_length
        past = self.history[index[:, None], taken] @ base[:, None]  # v -> R^T v
        future = self.future_matrix @ self.future[rows]  # (n, 2, F, 3)
        cut = 3 * len(self.past_offsets)
        for block, part in (("base_linear_window", 0), ("base_angular_window", 1)):
            start, stop = xs[block].start, xs[block].stop
            x[:, start : start + cut] = past[:, :, part].reshape(n, -1)
            x[:, start + cut : stop] = future[:, part].reshape(n, -1)
        x[:, xs["joints"]] = self.joints[rows]
        x[:, xs["joint_velocities"]] = self.joint_velocities[rows]
        if self.layout.gait_phase:
            x[:, xs["gait_phase"]] = self.phase[rows]
        fed = self.layout.pose(self.fed_position[rows], self.fed_rpy[rows])
        x[:, xs["base_position"]], x[:, xs["base_rpy"]] = fed
        return x

    def _walking(self, index: np.ndarray, velocity, yaw_rate, rotation: np.ndarray) -> None:
        """One network step of the walking rows: prediction, blend, steering, orientation."""
        ys, now, n = self.ys, self.current, len(index)
        rows = slice(None) if n == len(self.y) else index  # every row: views, not copies
        base = self.next_rotation[rows]  # R_k, from the previous prediction
        x = self._inputs(rows, index, base)
        self._lap("inputs")
        y = self.y[rows] = self.network(x)
        self._lap("network")
        command_world = np.zeros((n, 3))
        command_world[:, :2] = from_heading_frame(velocity[rows], yaw_of(base))
        command_linear = command_world[:, None] @ base  # R^T v, (n, 1, 3)
        command_angular = (base[:, 2] * yaw_rate[rows, None])[:, None]  # R^T [0, 0, yaw rate]
        weights = self.weights
        linear = y[:, ys["base_linear_future"]].reshape(n, -1, 3)
        angular = y[:, ys["base_angular_future"]].reshape(n, -1, 3)
        linear = self.keep * linear + weights * command_linear
        angular = self.keep * angular + weights * command_angular
        steered = self.steering[rows]
        if steered.any():
            p = self.params
            linear_c, angular_c = steer(
                linear,
                angular,
                self.position[rows, None],
                base[:, None],
                self.goal[rows, None],
                self.desired(rows)[:, None],
                p.k0,
                p.k1,
                planar=p.planar_steering,
            )
            if not steered.all():
                linear_c = np.where(steered[:, None, None], linear_c, linear)
                angular_c = np.where(steered[:, None, None], angular_c, angular)
            linear, angular = linear_c, angular_c
        self.future[rows, 0], self.future[rows, 1] = linear, angular
        self._lap("steering")
        rotation[rows] = base
        ahead = base @ exp_so3(angular[:, now] * self.dt)  # R_{k+1}
        ahead = self.next_rotation[rows] = yaw_only(ahead) if self.projected else ahead
        head = self.head[rows] = (self.head[rows] + 1) % self.history_length
        now_velocity = np.empty((n, 2, 3))
        now_velocity[:, 0], now_velocity[:, 1] = linear[:, now], angular[:, now]
        # in the base frame at k + 1 (as the features write it); kept in the world frame
        self.history[index, head] = now_velocity @ np.swapaxes(ahead, 1, 2)  # R v
        self.joint_velocities[rows] = y[:, ys["joint_velocities"]]
        self.joints[rows] = y[:, ys["joints"]]
        if self.layout.gait_phase:
            self.phase[rows] = unit_phase(y[:, ys["gait_phase"]])

    def _lap(self, section: str) -> None:
        """Charge the time since the previous lap to `section` (a few 0.1 us a call)."""
        now = time.perf_counter()
        self.timings[section] += now - self._clock
        self._clock = now

    def step(self, k: int, velocity, yaw_rate, stand, changed, active) -> None:
        """Frame k of every row from frame k - 1 (per row: command, `changed`: it starts)."""
        self._clock = time.perf_counter()
        self.command(k, velocity, yaw_rate, stand, changed, active)
        rotation = self.rotation.copy()
        any_stopped = self.stopped.any()
        if any_stopped:
            self._standing(k, rotation)
        walking = np.flatnonzero(~self.stopped)
        self._lap("commands")
        if len(walking):
            self._walking(walking, velocity, yaw_rate, rotation)
        if len(walking) < len(rotation):  # a row that restarts turns from where it stands
            still = np.ones(len(rotation), dtype=bool)
            still[walking] = False
            self.next_rotation[still] = rotation[still]
        heading = yaw_of(rotation)
        turn = heading - self.heading
        self.yaw, self.heading = self.yaw + np.arctan2(np.sin(turn), np.cos(turn)), heading
        self.rotation = rotation
        self.position, heights, self.foot = self.odometry.place(rotation, self.joints)
        self._lap("odometry")  # with the walking rows' new orientation above
        self.contacts = self.trigger.update(heights)
        self._lap("contacts")
        if self.hold is not None:
            self._hold()
            self._lap("consistent")
        self._feedback(any_stopped)
        self._lap("commands")

    def _hold(self) -> None:
        """The feet in contact held where they landed: the legs re-solved and their joint
        velocities corrected into `held_joints` and `held_joint_velocities` (what the rollout
        records), and the leg odometry's feet moved to where the held legs put them, so that
        its next anchor (a support switch) is a held foot. The network is fed its own legs
        (self.joints): fed the held ones it undoes the hold and stops walking
        (docs/consistent.md)."""
        self.held_joints, self.held_joint_velocities = self.hold.apply(
            self.position, self.rotation, self.joints, self.joint_velocities, self.contacts
        )
        corners = self.odometry.rotated_corners(self.rotation, self.held_joints)
        self.odometry.world_corners = corners + self.position[:, None, :, None]

    def _feedback(self, any_stopped: bool) -> None:
        """The pose fed back at the next step: y_i's, or the rollout's own (stopped rows)."""
        own = self.stopped if self.params.pose_feedback == "predicted" else True
        if not any_stopped and own is not True:  # every row walks: y_i's pose
            self.fed_position = self.y[:, self.ys["base_position"]].copy()
            self.fed_rpy = self.y[:, self.ys["base_rpy"]].copy()
            return
        own_rpy = np.empty((len(self.yaw), 3))
        own_rpy[:, :2], own_rpy[:, 2] = roll_pitch(self.rotation), self.yaw
        own = np.broadcast_to(own, self.yaw.shape)[:, None]
        self.fed_position = np.where(own, self.position, self.y[:, self.ys["base_position"]])
        self.fed_rpy = np.where(own, own_rpy, self.y[:, self.ys["base_rpy"]])
