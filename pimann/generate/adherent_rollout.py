"""Autoregressive generation with the ADHERENT baseline, as its own generator rolls it out
(the authors' python trajectory_generator.py over BLF's MANNAutoregressive step,
src/ML/src/MANNAutoregressive.cpp), vectorised over a batch of rollouts (rows), and the rollout
stage's runner for it (`run_adherent_rollouts`).

One step (BLF MANNTrajectoryGenerator: setInput, then advance):
1. setInput: the joints and joint velocities are the last output's. The facing frame of the
   state just generated (origin: the ground-projected base; x: unit(root x axis + chest x
   axis), both projected) is the new local frame. The past (1 s + now, 51 frames at 50 Hz,
   first in first out) gains the present: position (0, 0), facing direction (1, 0) and a base
   velocity, `past_velocity`: `"twist"` (`rollout.adherent_past_velocity`, the default) the
   last output's planar twist, its (vx, vy) from the ground base frame of the state before it
   into the world, as ADHERENT's python pushes it: so the sample at offset 0 is what the
   features' velocity of that frame is, (p_i - p_{i-1}) / dt (pimann.learn.adherent), and
   `"zeros"` zero as BLF's MANNAutoregressive pushes it. Its samples every 10 frames (offsets
   -50..0) fill the input's past half, in the new facing frame. The future half is the
   output's future samples blended with the joystick's: (1 - T_k) y_k + T_k d_k,
   T_k = ((k + 1) / 6)^tau, tau 1.5 (positions), 1.3 (directions), 1.3 (velocities)
   (trajectoryBlending). The robot counts as stopped when the new input equals the previous
   one within 5 % (Eigen isApprox).
2. advance: the network's output; the yaw integrates its yaw rate (0 while stopped), roll and
   pitch stay those of the start; the new joints are set and leg odometry places the base: the
   support foot is the one with the lowest sole corner, corners at (+-0.08, +-0.03, 0) m in the
   sole frame (the authors' config_mann.toml); when it changes, its lowest corner's ground
   projection (z = 0) is pinned, and while it stays the support that corner (the same corner)
   is held there. The support foot is therefore exactly still but for its rotation about the
   pinned corner (the base twist BLF then takes from the Jacobian, -J_b^-1 J_s sdot, is the
   one that keeps it still; the trajectory file holds positions and joint velocities).
   Contacts: pimann's rule (params `contacts`, pimann.core.contacts: a Schmitt trigger on each
   sole's lowest corner, both on at the start), as every generated trajectory of the study.

The joystick's desired future (BLF's MANNAutoregressiveInputBuilder draws a Bezier curve
through ellipsoid axes of its config) is here the exact path of the held command: body-frame
velocity v and yaw rate w from the current facing frame, at each future offset t the position
int_0^t R(w s) v ds, the direction (cos w t, sin w t) and the velocity R(w t) v; a stand
command (or none) is standing still. ADHERENT has no steering.

Start (the authors' protocol: standing, the past from zeros): the standing pose of the
training data (its joints, roll and pitch; yaw 0), the lowest corner on the floor; the past as
if standing for the last second (positions 0, directions (1, 0), velocities 0, BLF
MANNTrajectoryGenerator::setInitialState). The first input's future half: `first_input`
`"command"` (the default) the held command's future, so that the very first step already
answers the command; `"still"` standing still, BLF's reset input (its first setInput returns
before touching the input: there is no output yet to blend; ADHERENT's python likewise starts
from a standing input of its data and blends the joystick in from the second step). The
rollout stage pairs them with the past velocities (`LOOP_FIRST_INPUT`): twist and command,
zeros and still (BLF's loop as released).
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import torch
from scipy.spatial.transform import Rotation

from pimann.core.contacts import SchmittTrigger
from pimann.core.errors import PimannError
from pimann.core.params import ContactParams, Params, Segment
from pimann.core.paths import repo_relative
from pimann.core.robot import SOLE_CORNERS, Robot, load_robot
from pimann.core.rollout_files import (
    SCRIPT_ATTR,
    RolloutKey,
    rollout_path,
    script_json,
)
from pimann.core.rotations import rot_z, rotation_rpy
from pimann.core.trajectory import Trajectory, write_trajectory
from pimann.generate.command_script import ScriptSteps
from pimann.generate.rollouts import rollout_scripts, write_seed_rollouts
from pimann.learn.adherent import (
    AdherentLayout,
    BodyFrames,
    facing_direction,
    planar_rotation,
)
from pimann.learn.adherent_train import load_adherent_model
from pimann.learn.feature_layout import Normalisation
from pimann.learn.standing import StandingPose

log = logging.getLogger(__name__)

# the authors' config_mann.toml: the corners leg odometry rolls on, in the sole frame
ADHERENT_CORNERS = np.array([[x, y, 0.0] for x in (0.08, -0.08) for y in (0.03, -0.03)])
BLEND_TAU = (1.5, 1.3, 1.3)  # positions, facing directions, velocities (BLF setInput)
STOP_TOLERANCE = 0.05  # BLF setInput: isApprox with this relative precision
PAST_VELOCITY = ("twist", "zeros")  # rollout.adherent_past_velocity
FIRST_INPUT = ("command", "still")
# the rollout stage's loops: ADHERENT's own generator (its twist, the command from the first
# input) and BLF's MANNAutoregressive (zeros, its reset input standing still)
LOOP_FIRST_INPUT = {"twist": "command", "zeros": "still"}


def _approx(a: np.ndarray, b: np.ndarray, tolerance: float) -> np.ndarray:
    """Eigen's isApprox per row: ||a - b|| <= tolerance min(||a||, ||b||)."""
    norms = np.minimum(np.linalg.norm(a, axis=-1), np.linalg.norm(b, axis=-1))
    return np.linalg.norm(a - b, axis=-1) <= tolerance * norms


def command_future(
    velocity: np.ndarray, yaw_rate: np.ndarray, offsets: Sequence[int], rate_hz: float
) -> np.ndarray:
    """(B, 3, F, 2) the held commands' future (positions, directions, velocities) at the
    offsets, in the current facing frame (module docstring)."""
    t = np.asarray(offsets, dtype=float)[None, :] / rate_hz  # (1, F)
    w = np.asarray(yaw_rate, dtype=float)[:, None]  # (B, 1)
    angle = w * t
    small = np.abs(w) < 1e-9
    safe = np.where(small, 1.0, w)
    a = np.where(small, t, np.sin(angle) / safe)  # int_0^t cos(w s) ds
    b = np.where(small, 0.5 * w * t * t, (1.0 - np.cos(angle)) / safe)  # int_0^t sin(w s) ds
    vx, vy = velocity[:, 0, None], velocity[:, 1, None]
    position = np.stack([a * vx - b * vy, b * vx + a * vy], -1)
    direction = np.stack([np.cos(angle), np.sin(angle)], -1)
    moving = planar_rotation(angle) @ velocity[:, None, :, None]  # (B, F, 2, 1)
    return np.stack([position, direction, moving[..., 0]], axis=1)


class AdherentNetwork:
    """The model as a rollout calls it: physical x (B, in) -> physical y (B, out)."""

    def __init__(self, model: torch.nn.Module, stats: Normalisation):
        self.model, self.stats = model, stats

    def __call__(self, x: np.ndarray) -> np.ndarray:
        with torch.inference_mode():
            xn = torch.as_tensor(self.stats.normalise_x(x), dtype=torch.float32)
            return self.stats.denormalise_y(self.model(xn).double().numpy())


class AdherentGenerator:
    """The rows' state and BLF's step (module docstring), all rows at once."""

    def __init__(
        self,
        network: Callable[[np.ndarray], np.ndarray],
        layout: AdherentLayout,
        robot: Robot,
        contact_params: ContactParams,
        standing: StandingPose,
        rows: int,
        past_velocity: str = "twist",
        first_input: str = "command",
    ):
        for name, value, allowed in (
            ("past_velocity", past_velocity, PAST_VELOCITY),
            ("first_input", first_input, FIRST_INPUT),
        ):
            if value not in allowed:
                raise PimannError(None, f"{name} {value!r} is not one of {allowed}")
        self.network, self.layout = network, layout
        self.past_velocity, self.first_input = past_velocity, first_input
        self.dt = 1.0 / float(layout.rate_hz)
        self.xs, self.ys = layout.x_slices, layout.y_slices
        self.frames = BodyFrames(robot)
        offsets = np.asarray(layout.offsets)
        self.length = int(-offsets.min()) + 1  # the past kept: oldest .. now
        self.taken = np.asarray(layout.past_offsets) + self.length - 1  # history indices
        self.n_future = len(layout.future_offsets)
        k = np.arange(1, self.n_future + 1) / self.n_future
        self.blend = np.stack([k**tau for tau in BLEND_TAU])[None, :, :, None]  # (1, 3, F, 1)
        self.rows = np.arange(rows)
        # the start (BLF reset): standing, yaw 0, the lowest corner on the floor
        self.tilt = rotation_rpy(*standing.roll_pitch, 0.0)
        self.yaw = np.zeros(rows)
        self.joints = np.tile(standing.joints, (rows, 1))
        self.joint_velocities = np.zeros_like(self.joints)
        self.position = np.zeros((rows, 3))
        corners, _ = self._corners(self.rotation, self.position, self.joints, SOLE_CORNERS)
        self.position[:, 2] = -corners[..., 2].min(axis=(1, 2))
        self.support = np.full(rows, -1)  # none yet: the first step pins one
        self.corner = np.zeros(rows, dtype=int)
        self.anchor = np.zeros((rows, 3))
        self.trigger = SchmittTrigger.from_params(contact_params, self.dt, np.ones((rows, 2), bool))
        self.contacts = self.trigger.state
        # the past in the world frame: ground position, facing angle, planar velocity
        ground, angle = self.position[:, :2], self._facing_angle()
        self.past_position = np.repeat(ground[:, None], self.length, axis=1)
        self.past_angle = np.repeat(angle[:, None], self.length, axis=1)
        self.past_velocity_world = np.zeros((rows, self.length, 2))
        self.twist_velocity = np.zeros((rows, 2))  # the last output's planar velocity, world
        still = command_future(
            np.zeros((rows, 2)), np.zeros(rows), layout.future_offsets, layout.rate_hz
        )
        self.x = self._input(still)  # BLF reset's input: standing still
        self.y: np.ndarray | None = None
        self.stopped = np.ones(rows, dtype=bool)  # BLF reset: isRobotStopped

    @property
    def rotation(self) -> np.ndarray:
        """(B, 3, 3) the base orientation: the integrated yaw over the start's roll and pitch."""
        return rot_z(self.yaw) @ self.tilt

    def _corners(
        self, rotation: np.ndarray, position: np.ndarray, joints: np.ndarray, corners: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """((B, 2, C, 3) both soles' corners in the world, (B, 3, 3) chest in the base frame)."""
        positions, rotations = self.frames(joints)
        local = positions[:, :2, None] + np.einsum("bfij,cj->bfci", rotations[:, :2], corners)
        world = np.einsum("bij,bfcj->bfci", rotation, local) + position[:, None, None]
        return world, rotations[:, 2]

    def _facing_angle(self) -> np.ndarray:
        _, chest = self.frames(self.joints)
        facing = facing_direction(self.rotation, chest[:, 2])
        return np.arctan2(facing[:, 1], facing[:, 0])

    def _input(self, future: np.ndarray) -> np.ndarray:
        """x (B, in): the past of the history in the current facing frame, `future` (B, 3, F, 2)
        in it already, the joints and their velocities."""
        rows = len(self.rows)
        to_local = planar_rotation(self.past_angle[:, -1]).transpose(0, 2, 1)  # local <- world
        taken = self.taken
        position = self.past_position[:, taken] - self.past_position[:, -1:]
        angle = self.past_angle[:, taken]
        direction = np.stack([np.cos(angle), np.sin(angle)], -1)
        past = np.stack([position, direction, self.past_velocity_world[:, taken]], 1)  # (B,3,P,2)
        past = (to_local[:, None, None] @ past[..., None])[..., 0]
        window = np.concatenate([past, future], axis=2).reshape(rows, 3, -1)
        x = np.empty((rows, self.layout.input_dim))
        for k, block in enumerate(("base_positions", "facing_directions", "base_velocities")):
            x[:, self.xs[block]] = window[:, k]
        x[:, self.xs["joints"]] = self.joints
        x[:, self.xs["joint_velocities"]] = self.joint_velocities
        return x

    def set_input(self, desired: np.ndarray) -> None:
        """BLF setInput: the next x from the last output, the state and `desired` (B, 3, F, 2)."""
        y = self.y
        assert y is not None
        self.joints = y[:, self.ys["joints"]].copy()  # already the state's (advance)
        self.joint_velocities = y[:, self.ys["joint_velocities"]].copy()
        pushed = self.twist_velocity if self.past_velocity == "twist" else 0.0
        for name, value in (
            ("past_position", self.position[:, :2]),
            ("past_angle", self._facing_angle()),
            ("past_velocity_world", pushed),
        ):
            history = getattr(self, name)
            history[:, :-1] = history[:, 1:]
            history[:, -1] = value
        n, f = len(self.rows), self.n_future
        predicted = np.stack(
            [
                y[:, self.ys[f"{b}_future"]].reshape(n, f, 2)
                for b in ("base_positions", "facing_directions", "base_velocities")
            ],
            1,
        )
        future = (1.0 - self.blend) * predicted + self.blend * desired
        self._take(self._input(future))

    def _take(self, x: np.ndarray) -> None:
        """x becomes the input; stopped where it equals the previous one (BLF setInput)."""
        self.stopped = np.ones(len(self.rows), dtype=bool)
        for block in (*self.xs,):
            self.stopped &= _approx(x[:, self.xs[block]], self.x[:, self.xs[block]], STOP_TOLERANCE)
        self.x = x

    def advance(self) -> None:
        """BLF advance: the network on x, the yaw, the joints, leg odometry, contacts."""
        y = self.y = self.network(self.x)
        before = self.yaw.copy()
        yaw_rate = np.where(self.stopped, 0.0, y[:, self.ys["base_twist"]][:, 2])
        self.yaw = self.yaw + yaw_rate * self.dt
        twist = y[:, self.ys["base_twist"]][:, :2]
        self.twist_velocity = (planar_rotation(before) @ twist[..., None])[..., 0]
        self.joints = y[:, self.ys["joints"]].copy()
        self.joint_velocities = y[:, self.ys["joint_velocities"]].copy()
        rotation = self.rotation
        corners, _ = self._corners(rotation, self.position, self.joints, ADHERENT_CORNERS)
        heights = corners[..., 2]  # (B, 2, C)
        foot = (heights[:, 0].min(axis=1) > heights[:, 1].min(axis=1)).astype(int)  # left on ties
        changed = foot != self.support
        lowest = heights[self.rows, foot].argmin(axis=1)
        self.corner = np.where(changed, lowest, self.corner)
        pinned = corners[self.rows, foot, lowest].copy()
        pinned[:, 2] = 0.0
        self.anchor = np.where(changed[:, None], pinned, self.anchor)
        self.support = foot
        held = corners[self.rows, foot, self.corner] - self.position  # corner - base
        self.position = self.anchor - held
        lowest_heights = self._corners(rotation, self.position, self.joints, SOLE_CORNERS)[0]
        self.contacts = self.trigger.update(lowest_heights[..., 2].min(axis=2))

    def step(self, desired: np.ndarray) -> None:
        """One frame of every row: setInput, then advance; the first input keeps the start's
        past and takes `desired` as its future under `first_input="command"`."""
        if self.y is not None:
            self.set_input(desired)
        elif self.first_input == "command":
            self._take(self._input(desired))
        self.advance()

    def support_corner_world(self) -> np.ndarray:
        """(B, 3) the held support corner where the current state puts it (checks)."""
        corners, _ = self._corners(self.rotation, self.position, self.joints, ADHERENT_CORNERS)
        return corners[self.rows, self.support, self.corner]


@dataclasses.dataclass(frozen=True)
class AdherentRun:
    """One rollout of a batch: its script and the trajectory's labels."""

    script: Sequence[Segment]
    source: str
    attrs: dict


def generate_adherent(
    network: Callable[[np.ndarray], np.ndarray],
    layout: AdherentLayout,
    runs: Sequence[AdherentRun],
    robot: Robot,
    contact_params: ContactParams,
    standing: StandingPose,
    past_velocity: str = "twist",
    first_input: str = "command",
) -> list[Trajectory]:
    """Every run's script rolled out together; one trajectory per run (frame 0: the start)."""
    if not runs:
        return []
    rate = float(layout.rate_hz)
    plan = ScriptSteps([run.script for run in runs], rate)
    generator = AdherentGenerator(
        network, layout, robot, contact_params, standing, len(runs), past_velocity, first_input
    )
    n = len(plan.active)
    record = {
        name: np.empty((n, *np.shape(value)))
        for name, value in (
            ("position", generator.position),
            ("rotation", generator.rotation),
            ("joints", generator.joints),
            ("joint_velocities", generator.joint_velocities),
            ("contacts", generator.contacts),
        )
    }
    for k in range(n):
        if k > 0:
            desired = command_future(
                plan.velocity[k], plan.yaw_rate[k], layout.future_offsets, rate
            )
            generator.step(desired)
        for name in ("position", "joints", "joint_velocities", "contacts"):
            record[name][k] = getattr(generator, name)
        record["rotation"][k] = generator.rotation
    out = []
    for row, run in enumerate(runs):
        kept = {
            name: np.ascontiguousarray(v[: plan.lengths[row] + 1, row])
            for name, v in record.items()
        }
        out.append(
            Trajectory(
                time=np.arange(len(kept["position"])) / rate,
                base_position=kept["position"],
                base_quaternion_xyzw=Rotation.from_matrix(kept["rotation"]).as_quat(),
                joint_positions=kept["joints"],
                source=run.source,
                rate_hz=rate,
                contacts=kept["contacts"].astype(bool),
                joint_velocities=kept["joint_velocities"],
                attrs={"steering": False, **run.attrs},
            )
        )
    return out


def adherent_runs(params: Params) -> dict[str, list[Segment]]:
    """{scenario: script}: pimann.generate.rollouts.rollout_scripts' and each protocol's."""
    scripts = rollout_scripts(params)
    for name, protocol in params.rollout.protocols.items():
        scripts[name] = list(protocol.script)
    return scripts


def _seed_files(job: tuple[Path, dict[str, tuple[list[Segment], Path]], Params]) -> str | None:
    """One seed's rollouts (every script, no steering) written; the error, or None."""
    torch.set_num_threads(1)  # one process per core
    model_dir, files, params = job
    try:
        model, layout, stats, meta = load_adherent_model(model_dir)
        standing = StandingPose.from_json(meta.get("standing"))
        runs = [
            AdherentRun(
                script,
                f"{repo_relative(model_dir)}:{scenario}",
                {
                    "scenario": scenario,
                    "model_dir": repo_relative(model_dir),
                    SCRIPT_ATTR: script_json(script),
                    "pi_weight": 0.0,
                    "seed": int(meta["seed"]),
                    "variant": layout.variant,
                    "start_pose": standing.origin,
                },
            )
            for scenario, (script, _) in files.items()
        ]
        trajectories = generate_adherent(
            AdherentNetwork(model, stats),
            layout,
            runs,
            load_robot(),
            params.contacts,
            standing,
            params.rollout.adherent_past_velocity,
            LOOP_FIRST_INPUT[params.rollout.adherent_past_velocity],
        )
        for (_, path), trajectory in zip(files.values(), trajectories, strict=True):
            write_trajectory(path, trajectory)
    except PimannError as error:
        return str(error)
    return None


def run_adherent_rollouts(
    models_dir: str | Path, out_dir: str | Path, params: Params, workers: int = 2
) -> list[Path]:
    """Every seed of models_dir x every script of `adherent_runs`, without steering, through
    the loop `params.rollout.adherent_past_velocity` names (`LOOP_FIRST_INPUT`), into
    out_dir/<seed>/<scenario>-nosteering.h5 and out_dir/models.json, written atomically."""
    scripts = adherent_runs(params)

    def seed_job(tmp: Path, seed: int, folder: Path) -> tuple:
        files = {
            sc: (script, rollout_path(tmp.parent, RolloutKey(tmp.name, seed, sc, False)))
            for sc, script in scripts.items()
        }
        return folder, files, params

    return write_seed_rollouts(models_dir, out_dir, params, seed_job, _seed_files, workers)
