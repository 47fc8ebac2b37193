"""Typed params.yaml: one frozen dataclass per stage section.

Unknown keys (a typo) and missing keys are rejected with the dotted key's name, so a
mistyped ablation never silently runs with a default. The `profile` picks a set of
overrides from `profiles` (dotted keys), which scale data and epochs and nothing else.
"""

from __future__ import annotations

import dataclasses
import math
import types
import typing
from pathlib import Path
from typing import Any, Literal

import yaml

from pimann.core.errors import PimannError
from pimann.core.params_checks import check_params
from pimann.core.paths import REPO_ROOT

DEFAULT_PARAMS = REPO_ROOT / "params.yaml"


@dataclasses.dataclass(frozen=True)
class SkeletonParams:
    """A BVH skeleton's joint names for the 13 XSens segments (and the toes contact watches).

    Only names: every axis convention is calibrated from the motion itself (pimann.mocap.
    skeletons), and the skeletons of the common conventions are recognised without an entry.
    """

    segments: dict[str, str]  # XSens segment -> BVH joint
    toes: dict[str, str] | None  # LeftFoot/RightFoot -> toe joint; None: the foot's child/end
    unit_to_m: float | None  # BVH length unit in metres; None: told from the leg length


@dataclasses.dataclass(frozen=True)
class SourceParams:
    """One mocap source of the data set: files, skeleton, labels, selection, cutting."""

    path: str  # glob of files, relative to the shared folder unless absolute
    skeleton: str  # `auto` (recognised from the joint names) or a key of data.skeletons
    labels: Literal["bandai_namco", "motion"]  # content labels: the dataset's JSON, or none
    contents: list[str] | None  # labelled contents kept (bandai_namco labels); None: all
    styles: list[str] | None  # labelled styles kept; None: all
    rate_hz: float | None  # overrides the files' frame rate; None: as the file says
    clip_s: float | None  # takes longer than this are cut into clips (at pauses if any)
    max_speed: float | None  # m/s of the person's pelvis: faster stretches are left out
    max_takes: int | None  # at most this many files, spread over contents and styles


@dataclasses.dataclass(frozen=True)
class DataParams:
    sources: dict[str, SourceParams]
    skeletons: dict[str, SkeletonParams]  # name maps of skeletons `auto` does not know
    mirror: bool


@dataclasses.dataclass(frozen=True)
class RetargetParams:
    rate_hz: float
    pelvis_gain: float
    pelvis_position_weight: float  # scaled pelvis position: yields to the planted feet
    pelvis_orientation_weight: float
    segment_gain: float
    segment_weight: float
    trunk_weight: float
    gain_time_step: float
    posture_cost: float
    iterations_per_frame: int
    solver: str
    flat_feet: bool
    stance_weight: float  # sole pose cost of a planted foot (it stays where it was put)
    swing_weight: float  # sole pose cost of a swinging foot
    swing_clearance: float  # m, least mid-swing sole height
    lift_height: float  # m, a sole rises this high before it moves (sinks from it to land)
    head_from_t8: bool
    elbow_hinge: bool
    min_leg_roll_spread: float
    min_shoulder_roll: float
    min_foot_spacing: float
    contact_height: float  # m above its floor: a heel or toe point this low ...
    contact_speed: float  # m/s ... and this slow is down
    release_height: float  # m: it is up again above this ...
    release_speed: float  # m/s ... or faster than this
    release_travel: float  # m ... or farther than this from where it came down
    min_contact_s: float  # s, shorter contacts are dropped
    min_swing_s: float  # s, shorter lifts are filled
    release_turn: float  # rad: a planted foot that turned this far from its touchdown ...
    pivot_step_s: float  # s ... is lifted this long (a step turn) while the other stands
    workers: int


@dataclasses.dataclass(frozen=True)
class WindowParams:
    """Sample times of the base-velocity windows, in seconds from step i (SPEC 4)."""

    input_s: list[float]  # the input window around step i (12 samples)
    output_s: list[float]  # the predicted future window from step i (7 samples)


@dataclasses.dataclass(frozen=True)
class FeaturesParams:
    """features: windows, split, normalisation (SPEC 4)."""

    input: str  # the retargeted collection, relative to the repository
    output_dir: str  # one <variant>.h5 per variant
    window: str  # a key of `windows`
    windows: dict[str, WindowParams]
    test_fraction: float  # share of source clips (each with its mirror) held out
    split_seed: int
    contact_margin_s: float  # carried contact flags drop this long around every switch
    pose_input: Literal["world", "gravity"]  # the base pose the network sees (features.py)
    # motion classes (pimann.learn.motion_classes) whose training clips are added time-reversed
    time_reversed: list[Literal["forward", "backward", "side", "diagonal", "turning"]]


@dataclasses.dataclass(frozen=True)
class ModelParams:
    """model: MANN architecture (paper Sec. III-B)."""

    n_experts: int
    gating_hidden: int
    gating_layers: int  # linear layers, input -> hidden ... -> n_experts
    prediction_hidden: int
    prediction_layers: int  # linear layers, input -> hidden ... -> output
    dropout: float
    activation: Literal["elu"]


@dataclasses.dataclass(frozen=True)
class TrainParams:
    """train: optimiser, epochs, PI weights, seeds (SPEC 5, 6)."""

    pi_weights: list[float]  # the DVC matrix: one ensemble of `seeds` per weight
    seeds: list[int]
    epochs: int
    batch_size: int
    learning_rate: float
    weight_decay: float  # scaled by 1/sqrt(batches_per_epoch * restart_period)
    restart_period: int  # epochs of the first cosine cycle (Te)
    restart_mult: int  # each cycle this many times longer (Tmult)
    pi_configuration: Literal["predicted", "ground_truth"]  # where the Jacobians are taken
    pi_support: Literal["lower_sole", "data_contacts"]  # which foot L_B keeps still
    pi_gradient: Literal["both", "joints", "base", "joint_velocities"]  # what L_B's gradient moves
    # weight of the joints' consistency term, added to L_D: ((s - s_true)/dt - (sdot - sdot_true))^2
    consistency_weight: float
    pi_dropout: bool  # L_B on the dropout-perturbed prediction (the paper) or without dropout
    input_noise: float  # std (normalised units) of noise on the fed-back inputs; 0: the paper
    rollout_states: float  # share of samples with own-rollout inputs (pimann.learn.rollout_states)
    rollout_steps: int  # frames of each own-rollout piece
    max_train_samples: int | None  # evenly spaced subset of the training samples (quick runs)
    eval_batch_size: int  # test-set batches (no effect on the result)
    device: Literal["auto", "cpu", "cuda"]
    workers: int  # CPU processes the seeds are split among (no effect on the result)
    # the network's products under autocast in bfloat16, or float32; auto: bfloat16 where the
    # hardware has it (pimann.learn.train.pick_precision)
    precision: Literal["float32", "bfloat16", "auto"]
    threads: int | Literal["auto"]  # torch threads in all; auto: the free cores (no effect)


@dataclasses.dataclass(frozen=True)
class MotionSegment:
    """One command of a rollout scenario: body-frame (heading) velocity and yaw rate."""

    duration: float  # s
    vx: float  # m/s, forward
    vy: float  # m/s, left
    yaw_rate: float  # rad/s, counter-clockwise


@dataclasses.dataclass(frozen=True)
class StandSegment:
    """A 'stand' command: stop at the goal (steering) or at once, then hold the standing pose."""

    duration: float  # s
    stand: Literal[True]


Segment = MotionSegment | StandSegment  # one command of a script


@dataclasses.dataclass(frozen=True)
class RolloutParams:
    """rollout: autoregressive generation and steering (paper Sec. III-C)."""

    k0: float  # 1/s, steering position gain (Eq. lin_pid)
    k1: float  # 1/s, steering orientation gain (Eq. rot_pid)
    goal_factor: float  # goal = this x the commanded displacement ahead
    goal_radius: float  # m, stop within this horizontal distance of the goal
    # future input = (1 - w) prediction + w command, w = (t/T)^tau; None: no blend
    command_blend_tau: float | None
    stop_blend_s: float  # s over which the joints return to the standing pose on a stop
    stop_timeout_s: float  # s after 'stand' that a steered stop happens even off the goal
    planar_steering: bool  # authors' code: horizontal position error in the yaw frame only
    held_command: Literal["progress", "carrot"]  # how the goal moves while a command holds
    pose_feedback: Literal["predicted", "generated"]  # p, psi fed back: y_i's or the rollout's
    # sdot fed back: the network's sdot_i | (s_i - s_{i-1}) / dt of its predicted joints
    joint_velocity_feedback: Literal["predicted", "differenced"]
    start_history: Literal["zero", "command"]  # velocity windows at a start (generate.py)
    start_pose: Literal["data", "robot"]  # standing pose of a start and a stop (standing.py)
    scenarios: dict[str, list[Segment]]
    scenario_names: list[str]  # the scenarios the DVC rollout stage generates
    # the command-following benchmark: also roll out each test clip's script
    # (pimann.generate.rollouts)
    benchmark_clips: bool
    # ... and this many training clips' per motion class (in-distribution level); 0: none
    benchmark_train_clips: int


@dataclasses.dataclass(frozen=True)
class EvaluateParams:
    """evaluate: metrics (paper Sec. IV)."""

    contact_on_height: float  # m, lowest sole corner below this -> contact (after the delay)
    contact_off_height: float  # m, above this -> no contact (after the delay)
    contact_switch_time: float  # s, a condition must hold this long before the trigger switches
    skating_height: float  # m, foot-skating: foot below this in two adjacent frames ...
    skating_speed_per_frame: float  # m, ... moving more than this per frame ...
    skating_rate_hz: float  # ... at this frame rate
    walk_distance: float  # m, forward base travel that counts as walking
    foot_velocity_frame: Literal["local_world_aligned", "world"]  # sole velocities for the RMSE


@dataclasses.dataclass(frozen=True)
class SimulateRun:
    """One rollout the simulate stage runs: results/rollouts/<model>/<seed>/<scenario>-<...>.h5."""

    model: str  # rollout folder: w<pi weight> or baseline
    seed: int
    scenario: str
    steering: bool
    video: bool  # also render this run to results/sim/<name>.mp4
    controller: Literal["offline", "online"] = "offline"  # DCM plan + QP, or the centroidal MPC


@dataclasses.dataclass(frozen=True)
class MpcParams:
    """simulate.mpc: the online centroidal MPC with step adjustment (SPEC 9; the authors' values).

    Mass-normalised: forces per unit mass, angular momentum per unit mass.
    """

    horizon_s: float = 1.2  # s, 20 knots
    dt: float = 0.06  # s, the MPC's period and knot spacing (0.05 on the robot)
    friction: float = 0.1  # linearised cone's coefficient (0.33 on the robot)
    corner_x: float = 0.1167  # m, the 4 force corners of a foot at (+-x, +-y) in its frame
    corner_y: float = 0.0485
    com_z_min: float = 0.68  # m, CoM height bounds
    com_z_max: float = 0.72
    box_x: list[float] = dataclasses.field(default_factory=lambda: [-0.01, 0.01])  # m, landing
    box_y: list[float] = dataclasses.field(default_factory=lambda: [-0.01, 0.05])  # box, left foot
    freeze_s: float = 0.2  # s: a footstep is frozen this long before its touchdown
    angular_momentum_weight: float = 1.0
    com_weight: list[float] = dataclasses.field(default_factory=lambda: [2.0, 2.0, 110.0])
    footstep_weight: float = 20.0
    force_mean_weight: float = 10.0  # each corner force toward its foot's mean corner force
    force_rate_weight: list[float] = dataclasses.field(default_factory=lambda: [10.0, 10.0, 10.0])
    force_vertical_weight: float = 100.0  # vertical forces toward the weight shared by the feet
    swing_velocity_weight: float = 1.0e-3  # makes the airborne feet's velocities unique
    max_iterations: int = 200  # ipopt iterations per solve


@dataclasses.dataclass(frozen=True)
class PushRollout:
    """A rollout the push-recovery study walks: results/rollouts/<model>/<seed>/<scenario>-..."""

    model: str
    seed: int
    scenario: str
    steering: bool


@dataclasses.dataclass(frozen=True)
class PushParams:
    """simulate.pushes: push recovery, the largest push survived bisected per controller."""

    rollouts: list[PushRollout]  # empty: no push study
    controllers: list[Literal["offline", "online"]]
    directions: list[Literal["lateral", "forward"]]
    duration_s: float = 0.1  # s, the push's length, centred on mid single support
    max_force: float = 300.0  # N, the bisection's upper end
    tolerance: float = 20.0  # N, the bisection stops when the bracket is this narrow
    recovery_s: float = 1.5  # s after the push the base must stay up


@dataclasses.dataclass(frozen=True)
class SimulateParams:
    """simulate: MuJoCo model, footsteps, DCM/ZMP adjustment, whole-body QP IK (SPEC 9)."""

    timestep: float  # s, MuJoCo step
    control_rate_hz: float  # IK + feedback rate
    kp_legs_torso: float  # position actuator stiffness, Nm/rad
    kp_arms: float
    kp_neck: float
    kv_ratio: float  # kv = kv_ratio * kp
    armature: float  # kg m^2 on every joint
    friction: float
    speed_scale: float  # the trajectory's time runs this much slower on the robot (0.33x)
    step_scale: float  # footstep displacements scaled by this (0.4x)
    min_phase_s: float  # contacts shorter than this (robot time) are dropped
    min_swing_s: float  # swings shorter than this (robot time) are dropped: the foot stays
    min_double_s: float  # s, least double support at every touchdown (taken from the swings)
    swing_height: float  # m
    com_height: float  # m, LIPM height and IK CoM height
    zmp_hold_s: float  # s of double support before the first step
    end_hold_s: float  # s of double support after the last step
    zmp_margin: float  # m kept inside the support rectangle by the plan
    plan_dt: float  # s, DCM/ZMP plan discretisation
    plan_zmp_weight: float  # ZMP toward the support centre
    plan_com_weight: float  # CoM toward the generated CoM (if any)
    plan_rate_weight: float  # smoothness: weight of the ZMP rate
    k_zmp: float  # ZMP-CoM feedback gains
    k_com: float
    zmp_filter_hz: float  # low-pass cut-off of the measured ZMP
    chest_gain: float  # IK task gains (1/s); feet and CoM track their next-tick targets exactly
    posture_gain: float
    posture_cost: float  # weight of the generated joints in the IK
    ik_solver: str
    fall_height: float  # m, base below this = fall
    output_rate_hz: float  # traces written at most this often (small enough to commit)
    video_every_n: int  # video: every n-th trace sample, played in real time
    video_width: int
    video_height: int
    mpc: MpcParams  # the online controller
    pushes: PushParams  # push recovery (results/sim/pushes.png, the summary's `pushes`)
    runs: list[SimulateRun]  # the simulate stage's runs


@dataclasses.dataclass(frozen=True)
class FiguresParams:
    """figures: what evaluate selects for the paper's figures and claims, and the style."""

    scenario: str  # rollout scenario of the paper's test (10 s forward walking)
    pi_weight: float  # the PI model of the drift figures and the steering claims
    box_weights: list[float]  # weights in the RMSE box plots and the "all w" claims
    large_weight: float  # the weight said to fail unsteered and to pitch the feet
    foot_height_weights: list[float]  # the two models of the foot-height figure
    foot_steering: bool  # foot figures and claims from steered (True) or unsteered rollouts
    drift_reduction: float  # steering "removes" drift when it cuts the median by this factor
    width_in: float  # figure width, inches
    font_pt: float
    dpi: int  # PNG resolution


@dataclasses.dataclass(frozen=True)
class Params:
    profile: Literal["paper", "quick"]
    profiles: dict[str, dict[str, Any]]
    data: DataParams
    retarget: RetargetParams
    features: FeaturesParams
    model: ModelParams
    train: TrainParams
    rollout: RolloutParams
    evaluate: EvaluateParams
    simulate: SimulateParams
    figures: FiguresParams


def _build(kind: Any, value: Any, key: str, source: Path) -> Any:
    """Check `value` against the annotation `kind`, recursing into dataclasses and containers."""
    origin = typing.get_origin(kind)
    if dataclasses.is_dataclass(kind):
        if not isinstance(value, dict):
            raise PimannError(source, f"{key or 'params'} must be a mapping")
        hints = typing.get_type_hints(kind)
        names = [f.name for f in dataclasses.fields(kind)]
        unknown = sorted(set(value) - set(names))
        if unknown:
            raise PimannError(source, f"unknown key {_join(key, unknown[0])!r}")
        optional = {f.name for f in dataclasses.fields(kind)
                    if f.default is not dataclasses.MISSING
                    or f.default_factory is not dataclasses.MISSING}  # fmt: skip
        missing = [n for n in names if n not in value and n not in optional]
        if missing:
            raise PimannError(source, f"missing key {_join(key, missing[0])!r}")
        present = [n for n in names if n in value]
        return kind(**{n: _build(hints[n], value[n], _join(key, n), source) for n in present})
    if origin in (types.UnionType, typing.Union):
        options = typing.get_args(kind)
        if value is None and type(None) in options:
            return None
        errors = []
        for option in (o for o in options if o is not type(None)):
            try:
                return _build(option, value, key, source)
            except PimannError as error:
                errors.append(error.problem)
        raise PimannError(source, errors[0] if errors else f"{key} has the wrong type")
    if origin is Literal:
        if value not in typing.get_args(kind):
            raise PimannError(
                source, f"{key} must be one of {list(typing.get_args(kind))}, not {value!r}"
            )
        return value
    if origin is list:
        if not isinstance(value, list):
            raise PimannError(source, f"{key} must be a list")
        (item,) = typing.get_args(kind)
        return [_build(item, v, f"{key}[{i}]", source) for i, v in enumerate(value)]
    if origin is dict:
        if not isinstance(value, dict):
            raise PimannError(source, f"{key} must be a mapping")
        _, item = typing.get_args(kind)
        return {k: _build(item, v, _join(key, str(k)), source) for k, v in value.items()}
    if kind is Any:
        return value
    if kind is float and isinstance(value, int | float) and not isinstance(value, bool):
        if not math.isfinite(value):
            raise PimannError(source, f"{key} must be a finite number, not {value!r}")
        return float(value)
    if not isinstance(value, kind) or (kind is int and isinstance(value, bool)):
        raise PimannError(source, f"{key} must be {kind.__name__}, not {value!r}")
    return value


def _join(prefix: str, name: str) -> str:
    return f"{prefix}.{name}" if prefix else name


def _apply_overrides(raw: dict, overrides: dict[str, Any], source: Path) -> None:
    for dotted, value in overrides.items():
        node = raw
        *parents, leaf = dotted.split(".")
        for part in parents:
            if not isinstance(node.get(part), dict):
                raise PimannError(source, f"profile override {dotted!r} names no key")
            node = node[part]
        if leaf not in node:
            raise PimannError(source, f"profile override {dotted!r} names no key")
        node[leaf] = value


def load_params(path: str | Path = DEFAULT_PARAMS) -> Params:
    """Read params.yaml, apply the chosen profile's overrides, validate every key."""
    path = Path(path)
    try:
        raw = yaml.safe_load(path.read_text())
    except FileNotFoundError:
        raise PimannError(path, "params file not found") from None
    except yaml.YAMLError as error:
        raise PimannError(path, f"not valid YAML: {error}".replace("\n", " ")) from None
    if not isinstance(raw, dict):
        raise PimannError(path, "params must be a mapping of sections")
    profile = raw.get("profile")
    profiles = raw.get("profiles") or {}
    if profile not in profiles:
        raise PimannError(path, f"profile {profile!r} is not one of profiles {sorted(profiles)}")
    _apply_overrides(raw, profiles[profile], path)
    params = _build(Params, raw, "", path)
    check_params(params, path)  # values: ranges and cross-references
    return params


def as_dict(params: Any) -> dict:
    """Plain dict of a params section, for recording provenance beside outputs."""
    return dataclasses.asdict(params)
