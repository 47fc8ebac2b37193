"""Autoregressive trajectory generation with control-informed steering (paper Sec. III-C).

One network step per frame (50 Hz) from the standing configuration, driven by a command script
(a scenario: segments of body-frame velocity and yaw rate, or 'stand'). Step i:

1. Input x_i, built exactly as the features build it from the data (pimann.learn.features; the
   oracle test feeds the data's own outputs back and gets the data's inputs): the base
   orientation R_i = R_{i-1} exp(omega dt) from the previous prediction's velocity sample at
   offset 0 (y_{i-1}'s window is of frame i); the velocity window's past half (offsets <= 0)
   from the history of those predicted samples (after blend and steering, kept in the world
   frame, rotated into the base frame at i); its future half (offsets > 0) the previous
   prediction's window at those offsets (no interpolation), blended with the command and, with
   steering, corrected by Eqs. lin_pid and rot_pid. Then s_{i-1}, sdot_{i-1} from y_{i-1} and
   the base pose p_{i-1}, psi_{i-1} (`rollout.pose_feedback`: y_{i-1}'s or the rollout's).
2. y_i = network(x_i). Its window (of frame i + 1) becomes w * command + (1 - w) * prediction
   with w = (t / window end)^tau (`rollout.command_blend_tau`; the sample at t = 0 stays the
   network's own; null: no blend), then v_c = v - k0 R^T (p - p_d) and omega_c = omega - k1
   vee(skew(R_d^T R)) with steering.
3. Joints s_i and joint velocities sdot_i: y_i's; R_{i+1} = R_i exp(omega_c(t=0) dt) for the
   next step.
4. Base position by leg odometry: the support point (the lowest sole corner of the two feet)
   stays fixed in the world while it stays the support point; when it changes, the new one is
   pinned at its last world position on the ground (z = 0); a change of corner on the same foot
   counts (a rolling foot, as in ADHERENT; the authors' later code re-pins on a change of foot
   only). With R_i and the new joints (FK of the two sole frames), the base is placed so that
   the support point stays put. Contacts: the Schmitt trigger (core.contacts) on each foot's lowest
   corner height, both feet in contact at the start.

Goal rule (authors' values k0 = 0.2, k1 = 2.0, goal factor 2.5, radius 0.3 m; the defaults
here k1 = 4.0 and goal factor 0.25, docs/departures.md). When a motion
command starts, the desired heading R_d takes the base's current yaw (standing roll and pitch)
and a commanded path starts at the base; while the command holds, yaw_d += yaw_rate dt and the
path's point moves at the commanded velocity and the goal p_d is `goal_factor` x the commanded
displacement over the output window (v x 1.2 s) ahead of it (pimann.generate.steering
.CarrotGoal: the authors' goal kept ahead while the command holds, a held joystick). Its pull
k0 x goal_factor x v x 1.2 s (+6% of v at 0.25) and the lag the robot builds up behind the
moving point make a network that walks slower than commanded catch up; the authors' 2.5 (+60%)
overshoots backward. The legs carry the base (leg odometry below), so the speed a rollout
reaches is the legs' own, not the steering's.
On 'stand' the command velocity is zero and the goal freezes at the path's point; with steering
the robot stops once its base is within `goal_radius` of it horizontally, or has passed it
along the last commanded direction, or `stop_timeout_s` after the 'stand'; without steering it
stops at once. A stop brings the joints linearly to the standing pose over `stop_blend_s` (base
roll and pitch likewise, yaw kept) and then holds the standing configuration exactly; the
network restarts from the standing state (zero velocity history) at the next motion command.
A scenario that ends on a motion command ends walking, as the paper's 10 s test.

The ground-projected baseline (layout variant `ground_projected`) is rolled out in its own
frame: the base orientation keeps yaw only (roll and pitch 0), as in its training data.

Batches. These rules run in pimann.generate.batch_generator, vectorised over rollouts of one model
(one network call per step for every walking row, vectorised leg odometry
(pimann.generate.leg_odometry),
contacts and steering; each row its own script, stops and restarts). `generate_rollout` is a
batch of one, so a rollout alone equals its row of any batch (to rounding: on the CPU a MANN
runs in numpy (`rollout_network.NumpyMANN`), and BLAS rounds a row differently at other batch
sizes; 1e-16 in float64). The rollout stage (pimann.generate.rollouts.run_rollouts)
generates one batch per seed (`generate_files`). `python -m benchmarks.generate_speed`
measures it (full-size MANN, 1 thread): a 10-s rollout alone 0.15-0.16 s, 0.03-0.05 s
amortised over a batch of 32, and the quick run's full set batched 4.1x faster than one
rollout at a time (fastest of three alternating passes; single passes 3.2-4.1x).
"""

from __future__ import annotations

import dataclasses
import functools
import logging
import time
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np
import torch
from scipy.spatial.transform import Rotation
from threadpoolctl import ThreadpoolController

from pimann.core.errors import PimannError
from pimann.core.params import (
    DEFAULT_PARAMS,
    ConsistentParams,
    ContactParams,
    Params,
    RolloutParams,
    Segment,
)
from pimann.core.paths import repo_relative
from pimann.core.robot import Robot, load_robot
from pimann.core.trajectory import Trajectory, write_trajectory
from pimann.generate.batch_generator import BatchGenerator
from pimann.generate.command_script import Command, ScriptSteps, scenario_steps  # noqa: F401 (Command)
from pimann.generate.contact_consistent import own_contacts
from pimann.learn.feature_layout import FeatureLayout, Normalisation
from pimann.learn.standing import StandingPose

log = logging.getLogger(__name__)

BATCH_SIZE = 64  # rollouts generated together by `generate_files` (more: chunks)


@dataclasses.dataclass
class Rollout:
    """A generated trajectory plus what the generator decided at each frame (for checks)."""

    trajectory: Trajectory
    goals: np.ndarray  # (T, 3) the goal p_d at each frame (NaN before the first command)
    stopped: np.ndarray  # (T,) bool: standing still or returning to the standing pose
    support: np.ndarray  # (T,) int: 0 left, 1 right (column of `FEET`)
    # (T, 3) the linear base velocity fed back at each frame (world frame): the network's t = 0
    # sample after blend and steering, 0 while stopped; the legs' odometry may not realise it
    base_velocity: np.ndarray


@dataclasses.dataclass(frozen=True)
class RolloutSpec:
    """One row of a batch: its command script, steering switch, and the trajectory's labels."""

    script: Sequence[Segment]
    steering: bool
    source: str = "generated"
    attrs: dict | None = None


def generate_batch(
    model: torch.nn.Module,
    layout: FeatureLayout,
    stats: Normalisation,
    specs: Sequence[RolloutSpec],
    params: RolloutParams,
    robot: Robot | None = None,
    *,
    contact_params: ContactParams,
    standing: StandingPose | None = None,
    start_joint_velocities: np.ndarray | None = None,
    timings: dict[str, float] | None = None,
    consistent: ConsistentParams | None = None,
) -> list[Rollout]:
    """Roll the network out over every row's script at once; one `Rollout` per row, in order.

    `consistent`: contact-consistent rollouts, each foot in contact held where it landed inside
    the loop (pimann.generate.contact_consistent; the held legs recorded, the network fed its
    own, the base placed by the leg odometry on the held feet; attrs `consistent` = "loop",
    contacts: the rule on the file's own soles); None: the raw rollouts.
    `standing`: the pose to start from and return to (default: the robot's nominal one;
    generated files start from the model's, `generate_files`);
    `start_joint_velocities` (nj,): the joints' velocities at the start (default: at rest;
    diagnostics.mid_stride starts rollouts inside a clip's gait);
    `timings`: seconds per section of the step (`SECTIONS`, "record") are added to it.
    """
    if not specs:
        return []
    plan = ScriptSteps([spec.script for spec in specs], float(layout.rate_hz))
    generator = BatchGenerator(
        model,
        layout,
        stats,
        params,
        np.array([spec.steering for spec in specs]),
        robot or load_robot(),
        contact_params,
        standing or StandingPose.nominal(),
        consistent,
    )
    if start_joint_velocities is not None:
        generator.joint_velocities[:] = start_joint_velocities
    names = (
        "position",
        "rotation",
        "joints",
        "joint_velocities",
        "contacts",
        "goal",
        "stopped",
        "foot",
        "base_velocity",
    )
    if generator.hold is not None:  # the held legs, recorded as the rollout's joints
        names += ("held_joints", "held_joint_velocities")
    n = len(plan.active)
    out = {
        name: np.empty(
            (n, *np.shape(getattr(generator, name))),
            dtype=np.asarray(getattr(generator, name)).dtype,
        )
        for name in names
    }
    recording = 0.0
    # numpy's BLAS on one thread: a product of one sample is too small to share, and on a
    # loaded machine each wake-up of a second thread waits for a core (3 s a rollout, not 0.1)
    with torch.inference_mode(), _blas().limit(limits=1, user_api="blas"):
        for k in range(n):
            if k > 0:
                generator.step(k, *plan.at(k))
            clock = time.perf_counter()
            for name in names:
                out[name][k] = getattr(generator, name)
            recording += time.perf_counter() - clock
    if timings is not None:
        for section, seconds in [*generator.timings.items(), ("record", recording)]:
            timings[section] = timings.get(section, 0.0) + seconds

    rollouts = []
    for row, spec in enumerate(specs):
        kept = {
            name: np.ascontiguousarray(values[: plan.lengths[row] + 1, row])
            for name, values in out.items()
        }
        trajectory = Trajectory(
            time=np.arange(len(kept["position"])) * generator.dt,
            base_position=kept["position"],
            base_quaternion_xyzw=Rotation.from_matrix(kept["rotation"]).as_quat(),  # x y z w
            joint_positions=kept["joints"],
            source=spec.source,
            rate_hz=float(layout.rate_hz),
            contacts=kept["contacts"],
            joint_velocities=kept["joint_velocities"],
            attrs={"steering": bool(spec.steering), **(spec.attrs or {})},
        )
        if generator.hold is not None:  # the held legs (the network was fed its own)
            trajectory.joint_positions = kept["held_joints"]
            trajectory.joint_velocities = kept["held_joint_velocities"]
            trajectory.contacts = own_contacts(trajectory, generator.hold.solver, contact_params)
            trajectory.attrs["consistent"] = "loop"
            trajectory.attrs["consistent_residual_max_m"] = float(generator.hold.residual[row])
        rollouts.append(
            Rollout(trajectory, kept["goal"], kept["stopped"], kept["foot"], kept["base_velocity"])
        )
    return rollouts


@functools.cache
def _blas() -> ThreadpoolController:
    """The process's thread pools, found once (a search of the loaded libraries: 7 ms)."""
    return ThreadpoolController()


def generate_rollout(
    model: torch.nn.Module,
    layout: FeatureLayout,
    stats: Normalisation,
    scenario: Sequence[Segment],
    params: RolloutParams,
    steering: bool,
    robot: Robot | None = None,
    *,
    contact_params: ContactParams,
    source: str = "generated",
    attrs: dict | None = None,
    standing: StandingPose | None = None,
) -> Rollout:
    """Roll the network out over `scenario`; see the module docstring for every rule.

    A batch of one (`generate_batch`): the same trajectory as its row
    of any batch. `standing`: the pose to start from and return to (default: the nominal one).
    """
    spec = RolloutSpec(list(scenario), bool(steering), source, attrs)
    return generate_batch(
        model,
        layout,
        stats,
        [spec],
        params,
        robot,
        contact_params=contact_params,
        standing=standing,
    )[0]


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


@dataclasses.dataclass(frozen=True)
class FileJob:
    """One rollout file of a model: its scenario name, script, steering switch and path, and
    the protocol of `rollout.protocols` it runs under (None: `rollout` as it is)."""

    scenario: str
    script: Sequence[Segment]
    steering: bool
    output: Path
    protocol: str | None = None
    loop: bool = False  # the contact-consistent rollout held inside the loop (rollout.consistent)

    def rollout_params(self, params: Params) -> RolloutParams:
        """The rollout params this job runs with."""
        if self.protocol is None:
            return params.rollout
        return params.rollout.for_protocol(self.protocol, self.steering)


def _model_rollouts(
    model_dir: str | Path,
    jobs: Sequence[FileJob],
    params: Params,
    batch_size: int = BATCH_SIZE,
) -> Iterator[tuple[FileJob, Trajectory]]:
    """The trajectories of `jobs` with one trained model, `batch_size` rollouts at a time.

    Attributes as the files have always had them: scenario, model_dir, script, pi_weight,
    seed, variant, start_pose, steering.
    """
    from pimann.core.rollout_files import SCRIPT_ATTR, script_json
    from pimann.learn.model_files import META_FILE, load_model

    model, layout, stats, meta = load_model(model_dir)

    try:  # the data's standing pose the model was trained with (pimann.learn.standing)
        standing = StandingPose.from_json(meta.get("standing"))
    except (KeyError, TypeError, ValueError) as error:
        raise PimannError(
            Path(model_dir) / META_FILE, f"standing: not a standing pose ({error!r})"
        ) from None

    model_attrs = {
        key: meta[key] for key in ("pi_weight", "seed", "variant") if meta.get(key) is not None
    }
    rate = float(layout.rate_hz)
    robot = load_robot()
    groups: dict[tuple[str | None, bool, bool], list[FileJob]] = {}
    for job in jobs:  # a protocol's jobs run with its own params, a batch of their own
        key = (job.protocol, job.steering and job.protocol is not None, job.loop)
        groups.setdefault(key, []).append(job)
    for group in groups.values():
        rollout = group[0].rollout_params(params)
        consistent = params.rollout.consistent if group[0].loop else None
        ordered = sorted(group, key=lambda job: -len(scenario_steps(job.script, rate)))
        for first in range(0, len(ordered), batch_size):
            chunk = ordered[first : first + batch_size]
            specs = [
                RolloutSpec(
                    list(job.script),
                    job.steering,
                    f"{repo_relative(model_dir)}:{job.scenario}",
                    {
                        "scenario": job.scenario,
                        "model_dir": repo_relative(model_dir),
                        SCRIPT_ATTR: script_json(job.script),
                        **model_attrs,
                        "start_pose": standing.origin,
                        **({"protocol": job.protocol} if job.protocol else {}),
                    },
                )
                for job in chunk
            ]
            rollouts = generate_batch(
                model,
                layout,
                stats,
                specs,
                rollout,
                robot,
                contact_params=params.contacts,
                standing=standing,
                consistent=consistent,
            )
            yield from zip(chunk, (rollout.trajectory for rollout in rollouts), strict=True)


def generate_files(
    model_dir: str | Path,
    jobs: Sequence[FileJob],
    params: Params,
    batch_size: int = BATCH_SIZE,
) -> list[Path]:
    """Every job's rollout of one model, generated in batches, each file written atomically."""
    written = []
    for job, trajectory in _model_rollouts(model_dir, jobs, params, batch_size):
        write_trajectory(job.output, trajectory)
        written.append(Path(job.output))
    log.debug("wrote %d rollouts of %s", len(written), model_dir)
    return written


def generate_file(
    model_dir: str | Path,
    scenario_name: str,
    output_path: str | Path,
    steering: bool,
    params: Params,
    params_path: str | Path = DEFAULT_PARAMS,
    segments: Sequence[Segment] | None = None,
) -> Trajectory:
    """`pimann generate MODEL_DIR --scenario NAME -o OUT.h5 [--no-steering]`: written atomically.

    `segments`: the script to run under the name `scenario_name` (default: that scenario of
    rollout.scenarios, or the protocol of that name of rollout.protocols); recorded in the
    file's attrs["script"] (pimann.core.rollout_files.script_json).
    """
    protocol = None
    if segments is not None:
        scenario = list(segments)
    elif scenario_name in params.rollout.protocols:  # run under the protocol's rollout keys
        scenario, protocol = list(params.rollout.protocols[scenario_name].script), scenario_name
    else:
        scenario = scenario_of(params.rollout, scenario_name, params_path)
    job = FileJob(scenario_name, scenario, bool(steering), Path(output_path), protocol)
    ((_, trajectory),) = _model_rollouts(model_dir, [job], params)
    write_trajectory(output_path, trajectory)
    log.info("wrote %s (%d frames, steering %s)", output_path, len(trajectory), steering)
    return trajectory
