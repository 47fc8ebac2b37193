"""Autoregressive trajectory generation with control-informed steering (SPEC 7, Sec. III-C).

One network step per frame (50 Hz) from the standing configuration, driven by a command script
(a scenario: segments of body-frame velocity and yaw rate, or 'stand'). Step i:

1. Input x_i. Base-velocity window: the past half (offsets <= 0) is the history of generated
   base velocities (each step's t = 0 sample after blending and steering, kept in the world
   frame, rotated into the current base frame, as the authors' code); the future half
   (offsets > 0) is the previous step's future window, blended with the command and, with
   steering, corrected by Eqs. lin_pid and rot_pid. Then s_{i-1}, sdot_{i-1} from y_{i-1} and
   the base pose p_{i-1}, psi_{i-1} (`rollout.pose_feedback`: y_{i-1}'s or the rollout's).
2. y_i = network(x_i). Its future velocities become w * command + (1 - w) * prediction with
   w = (t / window end)^tau (the sample at t = 0 stays the network's own), then
   v_c = v - k0 R^T (p - p_d) and omega_c = omega - k1 vee(skew(R_d^T R)) with steering.
3. Base orientation: R_i = R_{i-1} exp(omega_c(t=0) dt). Joints s_i from y_i.
4. Base position by leg odometry: the support point (the lowest sole corner of the two feet)
   stays fixed in the world while it stays the support point; when it changes, the new one is
   pinned at its last world position on the ground (z = 0); a change of corner on the same foot
   counts (a rolling foot, as in ADHERENT; the authors' later code re-pins on a change of foot
   only). With R_i and the new joints (FK of the two sole frames), the base is placed so that
   the support point stays put. Contacts: the Schmitt trigger (SPEC 1) on each foot's lowest
   corner height, both feet in contact at the start.

Goal rule (authors' values k0 = 0.2, k1 = 2.0, goal factor 2.5, radius 0.3 m). When a motion
command starts, the desired heading R_d takes the base's current yaw (standing roll and pitch)
and a commanded path starts at the base; while the command holds, yaw_d += yaw_rate dt and the
goal p_d is the path's current point, which advances (`rollout.held_command`)
- `progress` (default): along the commanded direction by as much as the robot itself went, so
  steering corrects the lateral and heading drift and leaves the speed to the network
  (`goal_factor` is not used);
- `carrot`: at the commanded velocity, the goal `goal_factor` x the commanded displacement over
  the output window (v x 1.2 s) ahead of it -- the authors' goal at the command change, kept
  ahead while the command holds (a held joystick). Its constant pull k0 x goal_factor x v x
  1.2 s (+60% of v) drives a network out of its training range (a quick-profile model stalled
  at 0.8 m/s with it and walked 6.7 m in 10 s without it), hence not the default.
On 'stand' the command velocity is zero and the goal freezes at the path's point; with steering
the robot stops once its base is within `goal_radius` of it horizontally, or has passed it
along the last commanded direction, or `stop_timeout_s` after the 'stand'; without steering it
stops at once. A stop brings the joints linearly to the standing pose over `stop_blend_s` (base
roll and pitch likewise, yaw kept) and then holds the standing configuration exactly; the
network restarts from the standing state (zero velocity history) at the next motion command.
A scenario that ends on a motion command ends walking, as the paper's 10 s test.

The ground-projected baseline (layout variant `ground_projected`) is rolled out in its own
frame: the base orientation keeps yaw only (roll and pitch 0), as in its training data.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pinocchio as pin
import torch
from scipy.spatial.transform import Rotation

from pimann.contacts import FEET, SchmittTrigger
from pimann.errors import PimannError
from pimann.features import FeatureLayout, Normalisation, matrix_to_rpy
from pimann.params import (
    DEFAULT_PARAMS,
    EvaluateParams,
    MotionSegment,
    Params,
    RolloutParams,
    StandSegment,
    load_params,
)
from pimann.robot import (
    N_JOINTS,
    SOLE_CORNERS,
    Robot,
    load_robot,
)
from pimann.rotations import yaw_of, yaw_only
from pimann.standing import StandingPose
from pimann.steering import goal_from_command, rotation_rpy, steer
from pimann.trajectory import Trajectory, write_trajectory

log = logging.getLogger(__name__)

Segment = MotionSegment | StandSegment


@dataclasses.dataclass(frozen=True)
class Command:
    """One segment as the generator reads it: velocity (x, y) and yaw rate, or stand."""

    velocity: np.ndarray  # (2,) m/s in the heading frame (x forward, y left)
    yaw_rate: float  # rad/s
    stand: bool

    @classmethod
    def of(cls, segment: Segment) -> Command:
        if isinstance(segment, StandSegment):
            return cls(np.zeros(2), 0.0, True)
        velocity = np.array([segment.vx, segment.vy], dtype=float)
        still = not np.any(velocity) and segment.yaw_rate == 0.0
        return cls(velocity, float(segment.yaw_rate), still)  # a zero command is a stand


@dataclasses.dataclass
class Rollout:
    """A generated trajectory plus what the generator decided at each frame (for checks)."""

    trajectory: Trajectory
    goals: np.ndarray  # (T, 3) the goal p_d at each frame (NaN before the first command)
    stopped: np.ndarray  # (T,) bool: standing still or returning to the standing pose
    support: np.ndarray  # (T,) int: 0 left, 1 right (column of `FEET`)


def scenario_steps(scenario: Sequence[Segment], rate_hz: float) -> np.ndarray:
    """Segment index of each generated step (step k runs from (k-1) dt to k dt)."""
    if not scenario:
        raise PimannError(None, "the scenario has no segments")
    ends = np.cumsum([segment.duration for segment in scenario])
    if any(segment.duration <= 0 for segment in scenario):
        raise PimannError(None, "scenario segments must have positive durations")
    n_steps = int(round(ends[-1] * rate_hz))
    start_times = np.arange(n_steps) / rate_hz
    return np.minimum(np.searchsorted(ends, start_times + 0.5 / rate_hz), len(scenario) - 1)


def _interpolation(targets: np.ndarray, knots: np.ndarray) -> np.ndarray:
    """Matrix M with M @ f(knots) = f(targets), linear between knots, clamped at the ends."""
    matrix = np.zeros((len(targets), len(knots)))
    for row, target in enumerate(np.clip(targets, knots[0], knots[-1])):
        upper = min(int(np.searchsorted(knots, target, side="right")), len(knots) - 1)
        lower = max(upper - 1, 0)
        span = knots[upper] - knots[lower]
        fraction = 0.0 if span == 0 else (target - knots[lower]) / span
        matrix[row, lower] += 1.0 - fraction
        matrix[row, upper] += fraction
    return matrix


class _Odometry:
    """Leg odometry: the base placed so that the support point stays where it was."""

    def __init__(self, robot: Robot):
        self.robot = robot
        self.model = robot.model
        self.data = robot.model.createData()  # private: the cached Robot's data may be in use
        self.frame_ids = [robot.frame_id(name) for name in FEET]
        self.q = robot.configuration(np.zeros(3), [0.0, 0.0, 0.0, 1.0], np.zeros(N_JOINTS))
        self.corners_h = np.hstack([SOLE_CORNERS, np.ones((len(SOLE_CORNERS), 1))]).T
        self.support: tuple[int, int] | None = None
        self.anchor = np.zeros(3)
        self.world_corners = np.zeros((2, len(SOLE_CORNERS), 3))

    def corners_in_base(self, joints: np.ndarray) -> np.ndarray:
        """(2, C, 3) sole corners in the base frame, one FK pass over the two sole frames."""
        self.q[self.robot.q_index] = joints
        pin.forwardKinematics(self.model, self.data, self.q)
        out = np.empty_like(self.world_corners)
        for f, frame_id in enumerate(self.frame_ids):
            placement = pin.updateFramePlacement(self.model, self.data, frame_id)
            out[f] = (placement.homogeneous @ self.corners_h)[:3].T
        return out

    def place(self, rotation: np.ndarray, joints: np.ndarray, first: np.ndarray | None = None):
        """Base position for orientation `rotation` and `joints`; `first` sets the start pose.

        Returns (base position, lowest corner height of each foot (2,), support foot index).
        """
        rotated = self.corners_in_base(joints) @ rotation.T  # (2, C, 3), world-aligned
        heights = rotated[..., 2]
        foot = int(np.argmin(heights.min(axis=1)))
        support = (foot, int(np.argmin(heights[foot])))
        if first is not None:
            position = first
            self.support = support
            self.anchor = first + rotated[support]
        else:
            if support != self.support:  # pin the new support point on the ground
                self.support = support
                self.anchor = self.world_corners[support].copy()
                self.anchor[2] = 0.0
            position = self.anchor - rotated[support]
        self.world_corners = rotated + position
        return position, self.world_corners[..., 2].min(axis=1), foot


class _Network:
    """x (physical units) -> y (physical units) for one sample, without autograd."""

    def __init__(self, model: torch.nn.Module, layout: FeatureLayout, stats: Normalisation):
        self.model = model.eval()
        self.parameter = next(model.parameters(), None)
        self.x_mean, self.x_std = stats.x_mean.astype(float), stats.x_std.astype(float)
        self.y_mean, self.y_std = stats.y_mean.astype(float), stats.y_std.astype(float)
        if len(self.x_mean) != layout.input_dim or len(self.y_mean) != layout.output_dim:
            raise PimannError(None, "normalisation statistics do not match the feature layout")

    def __call__(self, x: np.ndarray) -> np.ndarray:
        normalised = ((x - self.x_mean) / self.x_std).astype(np.float32)
        tensor = torch.from_numpy(normalised)[None]
        if self.parameter is not None:
            tensor = tensor.to(self.parameter.device, self.parameter.dtype)
        with torch.inference_mode():
            y = self.model(tensor)[0].double().cpu().numpy()
        return y * self.y_std + self.y_mean


def _planar(yaw: float, vector: np.ndarray) -> np.ndarray:
    """A heading-frame (x, y) vector in the world frame."""
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([c * vector[0] - s * vector[1], s * vector[0] + c * vector[1]])


class _Generator:
    """The rollout's state and its per-step rules (module docstring), one call per frame."""

    def __init__(
        self,
        model: torch.nn.Module,
        layout: FeatureLayout,
        stats: Normalisation,
        params: RolloutParams,
        steering: bool,
        robot: Robot,
        contact_params: EvaluateParams,
        standing: StandingPose,
    ):
        self.params, self.steering, self.network = params, steering, _Network(model, layout, stats)
        self.standing_joints = standing.joints.copy()
        self.dt = 1.0 / float(layout.rate_hz)
        self.projected = layout.variant == "ground_projected"
        self.layout, self.xs, self.ys = layout, layout.x_slices, layout.y_slices
        in_offsets = np.asarray(layout.input_offsets)
        out_offsets = np.asarray(layout.output_offsets, dtype=float)
        self.current = layout.current_output
        self.history_length = max(1, int(-in_offsets.min()) + 1)
        self.past_offsets = in_offsets[in_offsets <= 0]
        # velocity at step i + o (o > 0) is the previous prediction's sample at offset o + 1
        self.future_matrix = _interpolation(in_offsets[in_offsets > 0] + 1.0, out_offsets)
        self.horizon = out_offsets.max() / layout.rate_hz
        span = max(out_offsets.max(), 1.0)
        self.weights = (np.clip(out_offsets / span, 0, 1) ** params.command_blend_tau)[:, None]
        self.weights[out_offsets <= 0] = 0.0
        rpy = np.array([*standing.roll_pitch, 0.0])
        self.standing_rpy = rpy * ([0.0, 0.0, 1.0] if self.projected else 1.0)

        # the robot: standing still
        self.rotation = rotation_rpy(*self.standing_rpy)
        self.joints, self.joint_velocities = standing.joints.copy(), np.zeros(len(standing.joints))
        self.yaw = float(self.standing_rpy[2])  # unwrapped
        self.odometry = _Odometry(robot)
        lowest = (self.odometry.corners_in_base(self.joints) @ self.rotation.T)[..., 2].min()
        self.position, _, self.foot = self.odometry.place(
            self.rotation, self.joints, first=np.array([0.0, 0.0, -lowest])
        )  # the lowest sole corner on the floor
        self.trigger = SchmittTrigger.from_params(contact_params, self.dt, np.array([True, True]))
        self.contacts = self.trigger.state
        # the network's side: velocity history (world frame) and corrected future (base frame)
        self.history = np.zeros((2, self.history_length, 3))
        self.head = 0  # index of the newest history sample
        self.future = np.zeros((2, len(out_offsets), 3))
        self.x = np.zeros(layout.input_dim)
        self.fed_position, self.fed_rpy = self.position.copy(), self.standing_rpy.copy()
        # the command side
        self.goal, self.desired_yaw = np.full(3, np.nan), self.yaw
        self.desired = self.rotation
        self.path: np.ndarray | None = None  # the commanded path's point (world frame)
        self.last_position = self.position
        self.heading_velocity = np.zeros(2)  # the last motion command's (heading frame)
        self.stopped, self.stand_since, self.stop_step = True, 0, 0
        self.stop_from: tuple[np.ndarray, np.ndarray] | None = None

    def command(self, k: int, command: Command, changed: bool) -> None:
        """Goal, path and desired heading for step k (and a restart after a stop)."""
        if changed and command.stand:  # the goal freezes at the path's point
            self.stand_since = k
            self.goal = (self.position if self.path is None else self.path).copy()
        elif changed:
            self.desired_yaw, self.heading_velocity = self.yaw, command.velocity
            self.path = self.position.copy()
            if self.stopped:  # restart the network from the standing state
                self.stopped, self.stop_from = False, None
                self._start_windows(command)
                self.fed_position = self.position.copy()
                self.fed_rpy = np.array([*self.standing_rpy[:2], self.yaw])
        if not command.stand:  # a held command: the path (and the goal) move with it
            self.desired_yaw += command.yaw_rate * self.dt
            direction = _planar(self.desired_yaw, command.velocity)
            if self.params.held_command == "carrot":
                self.path[:2] += direction * self.dt
            elif np.any(direction):  # along the commanded direction, as far as the robot went
                direction /= np.hypot(*direction)
                moved = self.position[:2] - self.last_position[:2]
                self.path[:2] += direction * (direction @ moved)
        self.last_position = self.position
        self.desired = rotation_rpy(*self.standing_rpy[:2], self.desired_yaw)
        if not command.stand:
            self.goal = self.path.copy()
            if self.params.held_command == "carrot":
                displacement = command.velocity * self.horizon
                self.goal = goal_from_command(
                    self.path, self.desired, displacement, self.params.goal_factor
                )
        elif not self.stopped and self._stop_now(k):
            self.stopped, self.stop_step = True, k
            self.stop_from = (self.joints.copy(), self.rotation.copy())

    def _start_windows(self, command: Command) -> None:
        """Velocity windows at a start: zero (standing) or the command held (`start_history`)."""
        self.history[:] = 0.0
        self.future[:] = 0.0
        if self.params.start_history == "command":
            linear = np.array([*_planar(yaw_of(self.rotation), command.velocity), 0.0])
            self.history[0], self.history[1, :, 2] = linear, command.yaw_rate
            self.future[0] = linear @ self.rotation  # R^T v
            self.future[1] = self.rotation[2] * command.yaw_rate

    def _stop_now(self, k: int) -> bool:
        """Under 'stand': at once without steering; at, or past, the goal with it."""
        offset = self.position[:2] - self.goal[:2]
        close = np.hypot(*offset) <= self.params.goal_radius
        passed = np.any(self.heading_velocity) and (
            offset @ _planar(self.desired_yaw, self.heading_velocity) >= 0
        )
        late = (k - self.stand_since) * self.dt >= self.params.stop_timeout_s
        return not self.steering or close or passed or late

    def _standing(self, k: int) -> np.ndarray:
        """Joints and base roll/pitch blend to the standing pose; the new base orientation."""
        if self.stop_from is None:
            self.joint_velocities = np.zeros_like(self.joints)
            return self.rotation
        blend = max(self.params.stop_blend_s, self.dt)
        alpha = min(1.0, (k - self.stop_step + 1) * self.dt / blend)
        from_joints, from_rotation = self.stop_from
        joints = (1 - alpha) * from_joints + alpha * self.standing_joints
        if alpha >= 1.0:
            joints = self.standing_joints.copy()
        roll_pitch = (1 - alpha) * matrix_to_rpy(from_rotation[None])[0, :2]
        roll_pitch += alpha * self.standing_rpy[:2]
        self.joint_velocities = (joints - self.joints) / self.dt
        self.joints = joints
        return rotation_rpy(*roll_pitch, yaw_of(self.rotation))

    def _walking(self, command: Command) -> np.ndarray:
        """One network step: input, prediction, blend, steering; the new base orientation."""
        xs, ys, rotation = self.xs, self.ys, self.rotation
        taken = (self.head + self.past_offsets) % self.history_length
        for block, history, future in (
            ("base_linear_window", self.history[0], self.future[0]),
            ("base_angular_window", self.history[1], self.future[1]),
        ):  # history rows v -> R^T v, the current base frame
            self.x[xs[block]] = np.concatenate(
                [history[taken] @ rotation, self.future_matrix @ future]
            ).ravel()
        self.x[xs["joints"]], self.x[xs["joint_velocities"]] = self.joints, self.joint_velocities
        fed = self.layout.pose(self.fed_position, self.fed_rpy)
        self.x[xs["base_position"]], self.x[xs["base_rpy"]] = fed
        self.y = y = self.network(self.x)

        command_world = np.array([*_planar(yaw_of(rotation), command.velocity), 0.0])
        command_linear = command_world @ rotation  # R^T v
        command_angular = rotation[2] * command.yaw_rate  # R^T [0, 0, yaw rate]
        weights = self.weights
        linear = y[ys["base_linear_future"]].reshape(-1, 3)
        angular = y[ys["base_angular_future"]].reshape(-1, 3)
        linear = (1 - weights) * linear + weights * command_linear
        angular = (1 - weights) * angular + weights * command_angular
        if self.steering:
            linear, angular = steer(
                linear, angular, self.position, rotation, self.goal, self.desired,
                self.params.k0, self.params.k1, planar=self.params.planar_steering,
            )  # fmt: skip
        self.future[0], self.future[1] = linear, angular
        self.head = (self.head + 1) % self.history_length
        self.history[0, self.head] = rotation @ linear[self.current]
        self.history[1, self.head] = rotation @ angular[self.current]
        self.joints = y[ys["joints"]].copy()
        self.joint_velocities = y[ys["joint_velocities"]].copy()
        new_rotation = rotation @ pin.exp3(angular[self.current] * self.dt)
        return yaw_only(new_rotation[None])[0] if self.projected else new_rotation

    def step(self, k: int, command: Command, changed: bool) -> None:
        """Frame k from frame k - 1 under `command` (`changed`: it starts at this step)."""
        self.command(k, command, changed)
        rotation = self._standing(k) if self.stopped else self._walking(command)
        turn = yaw_of(rotation) - yaw_of(self.rotation)
        self.yaw += float(np.arctan2(np.sin(turn), np.cos(turn)))
        self.rotation = rotation
        self.position, heights, self.foot = self.odometry.place(rotation, self.joints)
        self.contacts = self.trigger.update(heights)
        if self.stopped or self.params.pose_feedback == "generated":
            self.fed_position = self.position.copy()
            self.fed_rpy = np.array([*matrix_to_rpy(rotation[None])[0, :2], self.yaw])
        else:
            ys = self.ys
            self.fed_position = self.y[ys["base_position"]].copy()
            self.fed_rpy = self.y[ys["base_rpy"]].copy()


def generate_rollout(
    model: torch.nn.Module,
    layout: FeatureLayout,
    stats: Normalisation,
    scenario: Sequence[Segment],
    params: RolloutParams,
    steering: bool,
    robot: Robot | None = None,
    *,
    contact_params: EvaluateParams | None = None,
    source: str = "generated",
    attrs: dict | None = None,
    standing: StandingPose | None = None,
) -> Rollout:
    """Roll the network out over `scenario`; see the module docstring for every rule.

    `standing`: the pose to start from and return to (default: the robot's nominal one).
    """
    step_segment = scenario_steps(scenario, float(layout.rate_hz))
    commands = [Command.of(segment) for segment in scenario]
    generator = _Generator(
        model, layout, stats, params, steering, robot or load_robot(),
        contact_params or load_params().evaluate, standing or StandingPose.nominal(),
    )  # fmt: skip
    n = len(step_segment) + 1
    out = {
        "position": np.empty((n, 3)),
        "rotation": np.empty((n, 3, 3)),
        "joints": np.empty((n, N_JOINTS)),
        "joint_velocities": np.empty((n, N_JOINTS)),
        "contacts": np.empty((n, 2), dtype=bool),
        "goal": np.empty((n, 3)),
        "stopped": np.empty(n, dtype=bool),
        "foot": np.empty(n, dtype=int),
    }
    for k in range(n):
        if k > 0:
            segment = step_segment[k - 1]
            changed = k == 1 or segment != step_segment[k - 2]
            generator.step(k, commands[segment], changed)
        for name, values in out.items():
            values[k] = getattr(generator, name)

    trajectory = Trajectory(
        time=np.arange(n) * generator.dt,
        base_position=out["position"],
        base_quaternion_xyzw=Rotation.from_matrix(out["rotation"]).as_quat(),  # x y z w
        joint_positions=out["joints"],
        source=source,
        rate_hz=float(layout.rate_hz),
        contacts=out["contacts"],
        joint_velocities=out["joint_velocities"],
        attrs={"steering": bool(steering), **(attrs or {})},
    )
    return Rollout(trajectory, out["goal"], out["stopped"], out["foot"])


def generate(
    model: torch.nn.Module,
    layout: FeatureLayout,
    stats: Normalisation,
    scenario: Sequence[Segment],
    params: RolloutParams,
    steering: bool,
    robot: Robot | None = None,
    **kwargs,
) -> Trajectory:
    """The generated trajectory (50 Hz, frame 0 = standing); `generate_rollout` for details."""
    return generate_rollout(
        model, layout, stats, scenario, params, steering, robot, **kwargs
    ).trajectory


def scenario_of(params: RolloutParams, name: str, params_path: str | Path = DEFAULT_PARAMS):
    """The segments of scenario `name` from params.yaml's rollout.scenarios."""
    if name not in params.scenarios:
        raise PimannError(
            params_path,
            f"unknown scenario {name!r} in rollout.scenarios; known: {sorted(params.scenarios)}",
        )
    return params.scenarios[name]


def generate_file(
    model_dir: str | Path,
    scenario_name: str,
    output_path: str | Path,
    steering: bool = True,
    params: Params | None = None,
    params_path: str | Path = DEFAULT_PARAMS,
    segments: Sequence[Segment] | None = None,
) -> Trajectory:
    """`pimann generate MODEL_DIR --scenario NAME -o OUT.h5 [--no-steering]`: written atomically.

    `segments`: the script to run under the name `scenario_name` (default: that scenario of
    rollout.scenarios); recorded in the file's attrs["script"] (pimann.rollouts.script_json).
    """
    from pimann.rollouts import SCRIPT_ATTR, script_json
    from pimann.train import load_model

    params = params or load_params(params_path)
    if segments is None:
        scenario = scenario_of(params.rollout, scenario_name, params_path)
    else:
        scenario = list(segments)
    model, layout, stats, meta = load_model(model_dir)
    attrs = {"scenario": scenario_name, "model_dir": str(model_dir)}
    attrs[SCRIPT_ATTR] = script_json(scenario)
    for key in ("pi_weight", "seed", "variant"):
        if meta.get(key) is not None:
            attrs[key] = meta[key]
    standing = StandingPose.nominal()
    if params.rollout.start_pose == "data":
        standing = StandingPose.from_json(meta.get("standing"))
    attrs["start_pose"] = standing.origin
    trajectory = generate(
        model, layout, stats, scenario, params.rollout, steering, load_robot(),
        contact_params=params.evaluate, source=f"{model_dir}:{scenario_name}", attrs=attrs,
        standing=standing,
    )  # fmt: skip
    write_trajectory(output_path, trajectory)
    log.info("wrote %s (%d frames, steering %s)", output_path, len(trajectory), steering)
    return trajectory
