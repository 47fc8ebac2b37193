"""Typed params.yaml: one frozen pydantic dataclass per stage section.

Unknown keys (a typo), missing keys, wrong types and values out of range are rejected with the
dotted key's name, so a mistyped ablation never silently runs with a default. The `profile`
picks a set of overrides from `profiles` (dotted keys), which scale data and epochs and nothing
else; the base values and every profile's merged result are all checked, so a bad value fails
even where the active profile hides it.

Types are strict where YAML could mislead: an int is not a bool, a string is not a number,
every float is finite (an int is taken as a float). Ranges are field constraints (`Positive`,
`Field(ge=1)`, ...); names used in one place that must exist in another are checked by the
validators of `MpcParams` and `Params`.
"""

from __future__ import annotations

import copy
import dataclasses
import typing
from pathlib import Path
from typing import Annotated, Any, Literal

import yaml
from pydantic import (
    ConfigDict,
    Discriminator,
    Field,
    StrictBool,
    StrictInt,
    StrictStr,
    Tag,
    TypeAdapter,
    ValidationError,
    ValidationInfo,
    model_validator,
)
from pydantic.dataclasses import dataclass
from pydantic_core import PydanticCustomError

from pimann.core.errors import PimannError
from pimann.core.paths import REPO_ROOT

DEFAULT_PARAMS = REPO_ROOT / "params.yaml"

CONFIG = ConfigDict(extra="forbid")

Float = Annotated[float, Field(strict=True, allow_inf_nan=False)]  # an int is taken, a bool not
Int = StrictInt
Bool = StrictBool
Str = StrictStr
Positive = Annotated[Float, Field(gt=0)]
NonNegative = Annotated[Float, Field(ge=0)]
NonNegativeInt = Annotated[Int, Field(ge=0)]
Count = Annotated[Int, Field(ge=1)]
WindowTime = Annotated[Float, Field(ge=-10, le=10)]  # s around the current step


def _fail(problem: str) -> PydanticCustomError:
    """A validator's failure; `@` stands for the dotted key of the section that raised it."""
    return PydanticCustomError("params", "{problem}", {"problem": problem})


@dataclass(frozen=True, config=CONFIG)
class SkeletonParams:
    """A BVH skeleton's joint names for the 13 XSens segments (and the toes contact watches).

    Only names: every axis convention is calibrated from the motion itself (pimann.mocap.
    skeletons), and the skeletons of the common conventions are recognised without an entry.
    """

    segments: dict[Str, Str]  # XSens segment -> BVH joint
    toes: dict[Str, Str] | None  # LeftFoot/RightFoot -> toe joint; None: the foot's child/end
    unit_to_m: Positive | None  # BVH length unit in metres; None: told from the leg length


@dataclass(frozen=True, config=CONFIG)
class SourceParams:
    """One mocap source of the data set: files, skeleton, labels, selection, cutting."""

    path: Str  # glob of files, relative to the shared folder unless absolute
    skeleton: Str  # `auto` (recognised from the joint names) or a key of data.skeletons
    labels: Literal["bandai_namco", "motion"]  # content labels: the dataset's JSON, or none
    contents: list[Str] | None  # labelled contents kept (bandai_namco labels); None: all
    styles: list[Str] | None  # labelled styles kept; None: all
    rate_hz: Positive | None  # overrides the files' frame rate; None: as the file says
    clip_s: Positive | None  # takes longer than this are cut into clips (at pauses if any)
    max_speed: Positive | None  # m/s of the person's pelvis: faster stretches are left out
    max_takes: NonNegativeInt | None  # at most this many files, spread over contents and styles


@dataclass(frozen=True, config=CONFIG)
class DataParams:
    sources: dict[Str, SourceParams]
    skeletons: dict[Str, SkeletonParams]  # name maps of skeletons `auto` does not know
    mirror: Bool


@dataclass(frozen=True, config=CONFIG)
class RetargetParams:
    rate_hz: Positive
    pelvis_gain: Positive
    pelvis_position_weight: NonNegative  # scaled pelvis position: yields to the planted feet
    pelvis_orientation_weight: NonNegative
    segment_gain: Positive
    segment_weight: NonNegative
    trunk_weight: NonNegative
    gain_time_step: Positive
    posture_cost: NonNegative
    iterations_per_frame: Count
    solver: Str
    flat_feet: Bool
    stance_weight: NonNegative  # sole pose cost of a planted foot (it stays where it was put)
    swing_weight: NonNegative  # sole pose cost of a swinging foot
    swing_clearance: NonNegative  # m, least mid-swing sole height
    lift_height: NonNegative  # m, a sole rises this high before it moves (sinks from it to land)
    head_from_t8: Bool
    elbow_hinge: Bool
    min_leg_roll_spread: NonNegative
    min_shoulder_roll: NonNegative
    min_foot_spacing: NonNegative
    contact_height: Positive  # m above its floor: a heel or toe point this low ...
    contact_speed: Positive  # m/s ... and this slow is down
    release_height: Positive  # m: it is up again above this ...
    release_speed: Positive  # m/s ... or faster than this
    release_travel: Positive  # m ... or farther than this from where it came down
    min_contact_s: NonNegative  # s, shorter contacts are dropped
    min_swing_s: NonNegative  # s, shorter lifts are filled
    release_turn: Positive  # rad: a planted foot that turned this far from its touchdown ...
    pivot_step_s: Float  # s ... is lifted this long (a step turn) while the other stands
    workers: Count


@dataclass(frozen=True, config=CONFIG)
class WindowParams:
    """Sample times of the base-velocity windows, in seconds from step i (paper Sec. III-A)."""

    input_s: list[WindowTime]  # the input window around step i (12 samples)
    output_s: list[WindowTime]  # the predicted future window from step i (7 samples)


@dataclass(frozen=True, config=CONFIG)
class FeaturesParams:
    """features: windows, split, normalisation (paper Sec. III-A)."""

    input: Str  # the retargeted collection, relative to the repository
    output_dir: Str  # one <variant>.h5 per variant
    window: Str  # a key of `windows`
    windows: dict[Str, WindowParams]
    test_fraction: Annotated[
        Float, Field(gt=0, lt=1)
    ]  # share of source clips (each with its mirror) held out
    split_seed: Int
    contact_margin_s: NonNegative  # carried contact flags drop this long around every switch
    pose_input: Literal["world", "gravity"]  # the base pose the network sees (features.py)
    # motion classes (pimann.learn.motion_classes) whose training clips are added time-reversed
    time_reversed: list[Literal["forward", "backward", "side", "diagonal", "turning"]]
    gait_phase: bool  # the gait phase in the state (pimann.learn.gait_phase; not the paper)
    gait_phase_step_s: Positive  # the longest step: a longer gap is a pause


@dataclass(frozen=True, config=CONFIG)
class ModelParams:
    """model: MANN architecture (paper Sec. III-B)."""

    n_experts: Count
    gating_hidden: Count
    gating_layers: Count  # linear layers, input -> hidden ... -> n_experts
    prediction_hidden: Count
    prediction_layers: Count  # linear layers, input -> hidden ... -> output
    dropout: Annotated[Float, Field(ge=0, lt=1)]
    activation: Literal["elu"]


@dataclass(frozen=True, config=CONFIG)
class TrainParams:
    """train: optimiser, epochs, PI weights, seeds (paper Sec. III-B)."""

    pi_weights: list[NonNegative]  # the DVC matrix: one ensemble of `seeds` per weight
    seeds: list[NonNegativeInt]
    epochs: Count
    batch_size: Count
    learning_rate: Positive
    weight_decay: NonNegative  # scaled by 1/sqrt(batches_per_epoch * restart_period)
    restart_period: Count  # epochs of the first cosine cycle (Te)
    restart_mult: Count  # each cycle this many times longer (Tmult)
    pi_configuration: Literal["predicted", "ground_truth"]  # where the Jacobians are taken
    pi_gradient: Literal["both", "joints", "base", "joint_velocities"]  # what L_B's gradient moves
    pi_dropout: Bool  # L_B on the dropout-perturbed prediction (the paper) or without dropout
    max_train_samples: Count | None  # evenly spaced subset of the training samples (quick runs)
    eval_batch_size: Count  # test-set batches (no effect on the result)
    device: Literal["auto", "cpu", "cuda"]
    workers: Count  # CPU processes the seeds are split among (no effect on the result)
    # the network's products under autocast in bfloat16, or float32; auto: bfloat16 where the
    # hardware has it (pimann.learn.train.pick_precision)
    precision: Literal["float32", "bfloat16", "auto"]
    threads: Count | Literal["auto"]  # torch threads in all; auto: the free cores (no effect)
    # also train, roll out and measure the ADHERENT baseline (models/adherent: its own
    # features, outputs and rollout, Viceconte et al. 2022), beside `baseline`
    adherent: Bool


@dataclass(frozen=True, config=CONFIG)
class MotionSegment:
    """One command of a rollout scenario: body-frame (heading) velocity and yaw rate."""

    duration: Positive  # s
    vx: Float  # m/s, forward
    vy: Float  # m/s, left
    yaw_rate: Float  # rad/s, counter-clockwise


@dataclass(frozen=True, config=CONFIG)
class StandSegment:
    """A 'stand' command: stop at the goal (steering) or at once, then hold the standing pose."""

    duration: Positive  # s
    stand: Literal[True]


Segment = MotionSegment | StandSegment  # one command of a script
_Command = Annotated[  # in params.yaml: a stand command has `stand`, a motion command not
    Annotated[MotionSegment, Tag("MotionSegment")] | Annotated[StandSegment, Tag("StandSegment")],
    Discriminator(lambda v: "StandSegment" if "stand" in _fields_of(v) else "MotionSegment"),
]


def _fields_of(value: Any) -> Any:
    return value if isinstance(value, dict) else vars(value)


# the rollout keys a protocol may set (the rest of `rollout` holds for it too)
PROTOCOL_KEYS = (
    "k0",
    "k1",
    "goal_factor",
    "goal_radius",
    "command_blend_tau",
    "planar_steering",
    "start_history",
)


@dataclass(frozen=True, config=CONFIG)
class ProtocolParams:
    """One of the authors' test protocols: a command script, rolled out without steering and
    with it, each way with the rollout keys it sets (`PROTOCOL_KEYS`)."""

    script: list[_Command]
    unsteered: dict[Str, Any]
    steered: dict[Str, Any]


@dataclass(frozen=True, config=CONFIG)
class ConsistentParams:
    """rollout.consistent: contact-consistent rollouts, written beside the raw ones: a foot in
    contact (the study's contact rule) is held at its touchdown pose and the legs re-solved."""

    variants: list[Literal["post", "loop"]]  # post: a finished rollout; loop: fed back; []: none
    scenarios: list[Str]  # the scenarios and protocols given such variants
    blend_s: NonNegative  # s over which a touchdown or a lift-off blends held and raw sole
    iterations: Count  # leg IK iterations a frame
    damping: NonNegative  # the leg IK's damping (least squares)
    tolerance: Positive  # m, the held sole's largest allowed distance from its touchdown pose


@dataclass(frozen=True, config=CONFIG)
class RolloutParams:
    """rollout: autoregressive generation and steering (paper Sec. III-C)."""

    k0: NonNegative  # 1/s, steering position gain (Eq. lin_pid)
    k1: NonNegative  # 1/s, steering orientation gain (Eq. rot_pid)
    goal_factor: Positive  # goal = this x the commanded displacement ahead
    goal_radius: Positive  # m, stop within this horizontal distance of the goal
    # future input = (1 - w) prediction + w command, w = (t/T)^tau; None: no blend
    command_blend_tau: NonNegative | None
    stop_blend_s: NonNegative  # s over which the joints return to the standing pose on a stop
    stop_timeout_s: NonNegative  # s after 'stand' that a steered stop happens even off the goal
    planar_steering: Bool  # authors' code: horizontal position error in the yaw frame only
    pose_feedback: Literal["predicted", "generated"]  # p, psi fed back: y_i's or the rollout's
    start_history: Literal["zero", "command"]  # velocity windows at a start (generate.py)
    scenarios: dict[Str, list[_Command]]
    scenario_names: list[Str]  # the scenarios the DVC rollout stage generates
    # the command-following benchmark: each test clip's script (pimann.generate.benchmark_clips)
    benchmark_clips: Bool
    # ... and this many training clips' per motion class (in-distribution level); 0: none
    benchmark_train_clips: NonNegativeInt
    # the authors' test protocols, rolled out as scenarios of their own name (rollout_files)
    protocols: dict[Str, ProtocolParams]
    # ADHERENT's past base velocities: twist (its own generator feeds back the predicted
    # SE(2) twist) | zeros (BLF's MANNAutoregressive pushes zeros)
    adherent_past_velocity: Literal["twist", "zeros"]
    consistent: ConsistentParams  # contact-consistent variants beside the raw rollouts

    @model_validator(mode="after")
    def _protocols(self) -> RolloutParams:
        for name in self.protocols:
            if name in self.scenarios:
                raise _fail(f"@protocols.{name} is also a scenario's name")
            for steering in (False, True):
                self.for_protocol(name, steering)  # every key known, every value in range
        return self

    def for_protocol(self, name: str, steering: bool) -> RolloutParams:
        """These params as protocol `name` sets them for its rollout with or without steering."""
        way = "steered" if steering else "unsteered"
        overrides = getattr(self.protocols[name], way)
        for key in overrides:
            if key not in PROTOCOL_KEYS:
                raise _fail(
                    f"@protocols.{name}.{way}.{key}: not a protocol key; known: "
                    + ", ".join(PROTOCOL_KEYS)
                )
        fields = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        try:
            return RolloutParams(**{**fields, **overrides, "protocols": {}})
        except ValidationError as error:
            raise _fail(f"@protocols.{name}.{way}: {validation_problem(error)}") from None


@dataclass(frozen=True, config=CONFIG)
class ContactParams:
    """contacts: the contact rule of generated trajectories, a Schmitt trigger on the lowest
    sole corner (pimann.core.contacts), shared by every stage that detects contacts."""

    on_height: Positive  # m, lowest sole corner below this -> contact (after the delay)
    off_height: Positive  # m, above this -> no contact (after the delay)
    switch_time: NonNegative  # s, a condition must hold this long before the trigger switches

    @model_validator(mode="after")
    def _hysteresis(self) -> ContactParams:
        if self.off_height < self.on_height:
            raise _fail(
                f"@off_height must be >= @on_height ({self.off_height:g} < {self.on_height:g})"
            )
        return self


@dataclass(frozen=True, config=CONFIG)
class EvaluateParams:
    """evaluate: metrics (paper Sec. IV), and what the claims and figures feature: the PI
    model, the scenario, the weights compared."""

    pi_weight: Float  # the PI model of the drift figures and the steering claims
    # what evaluate selects for the paper's figures and claims
    scenario: Str  # rollout scenario of the paper's test (10 s forward walking)
    box_weights: list[Float]  # weights in the RMSE box plots and the "all w" claims
    large_weight: Float  # the weight said to fail unsteered and to pitch the feet
    foot_height_weights: list[Float]  # the two models of the foot-height figure
    foot_steering: Bool  # foot figures and claims from steered (True) or unsteered rollouts
    drift_reduction: Annotated[
        Float, Field(gt=0, le=1)
    ]  # steering "removes" drift when it cuts the median by this factor
    skating_height: Positive  # m, foot-skating: foot below this in two adjacent frames ...
    skating_speed_per_frame: Positive  # m, ... moving more than this per frame ...
    skating_rate_hz: Positive  # ... at this frame rate
    walk_distance: Positive  # m, forward base travel that counts as walking
    foot_velocity_frame: Literal["local_world_aligned", "world"]  # sole velocities for the RMSE
    gait_window_s: Positive  # s at a rollout's end over which travel, speed and cadence count
    glide_height: Positive  # m, a sole's lowest corner below this ...
    glide_speed: Positive  # m/s, ... moving horizontally faster than this is gliding
    gait_speed_band: Positive  # m/s, the data's gait level at a speed: its walking within this


@dataclass(frozen=True, config=CONFIG)
class SimulateRun:
    """One rollout the simulate stage runs: results/rollouts/<model>/<seed>/<scenario>-<...>.h5."""

    model: Str  # rollout folder: w<pi weight> or baseline
    seed: NonNegativeInt
    scenario: Str
    steering: Bool
    video: Bool  # also render this run to results/sim/<name>.mp4
    controller: Literal["offline", "online"] = "offline"  # DCM plan + QP, or the centroidal MPC
    variant: Literal["raw", "post", "loop"] = "raw"  # the rollout, or a contact-consistent one


@dataclass(frozen=True, config=CONFIG)
class MpcParams:
    """simulate.mpc: the online centroidal MPC with step adjustment (Sec. II-C;
    the authors' values).

    Mass-normalised: forces per unit mass, angular momentum per unit mass.
    """

    horizon_s: Positive = 1.2  # s, 20 knots
    dt: Positive = 0.06  # s, the MPC's period and knot spacing (0.05 on the robot)
    friction: Positive = 0.1  # linearised cone's coefficient (0.33 on the robot)
    corner_x: Positive = 0.1167  # m, the 4 force corners of a foot at (+-x, +-y) in its frame
    corner_y: Positive = 0.0485
    com_z_min: Positive = 0.68  # m, CoM height bounds
    com_z_max: Positive = 0.72
    box_x: list[Float] = dataclasses.field(default_factory=lambda: [-0.01, 0.01])  # m, landing
    box_y: list[Float] = dataclasses.field(default_factory=lambda: [-0.01, 0.05])  # box, left foot
    freeze_s: NonNegative = 0.2  # s: a footstep is frozen this long before its touchdown
    angular_momentum_weight: NonNegative = 1.0
    com_weight: list[NonNegative] = dataclasses.field(default_factory=lambda: [2.0, 2.0, 110.0])
    footstep_weight: NonNegative = 20.0
    force_mean_weight: NonNegative = 10.0  # each corner force toward its foot's mean corner force
    force_rate_weight: list[NonNegative] = dataclasses.field(
        default_factory=lambda: [10.0, 10.0, 10.0]
    )
    force_vertical_weight: NonNegative = (
        100.0  # vertical forces toward the weight shared by the feet
    )
    swing_velocity_weight: NonNegative = 1.0e-3  # makes the airborne feet's velocities unique
    max_iterations: Count = 200  # ipopt iterations per solve
    # how each horizon is solved: ipopt (the reference) or fatrop, the NLP to convergence |
    # rti-<qp>: one convex QP a horizon, the torques linearised at the last horizon's solution
    # one knot on (pimann.sim.centroidal_mpc.SequentialQp), by piqp or osqp
    solver: Literal["ipopt", "fatrop", "rti-piqp", "rti-osqp"] = "rti-piqp"
    sqp_iterations: Count = 1  # rti-*: QPs per warm-started horizon (1: a real-time iteration)

    @model_validator(mode="after")
    def _consistent(self) -> MpcParams:
        if self.com_z_min > self.com_z_max:
            raise _fail("@com_z_min must not exceed @com_z_max")
        for key in ("box_x", "box_y"):
            box = getattr(self, key)
            if len(box) != 2 or box[0] > 0.0 or box[1] < 0.0:
                raise _fail(f"@{key} must be [low <= 0, high >= 0], not {box}")
        for key in ("com_weight", "force_rate_weight"):
            if len(getattr(self, key)) != 3:
                raise _fail(f"@{key} must have 3 entries (x, y, z)")
        if self.horizon_s < 2 * self.dt:
            raise _fail("@horizon_s must span at least 2 knots of dt")
        return self


@dataclass(frozen=True, config=CONFIG)
class PushRollout:
    """A rollout the push-recovery study walks: results/rollouts/<model>/<seed>/<scenario>-..."""

    model: Str
    seed: NonNegativeInt
    scenario: Str
    steering: Bool


@dataclass(frozen=True, config=CONFIG)
class PushParams:
    """simulate.pushes: push recovery, the largest push survived bisected per controller."""

    rollouts: list[PushRollout]  # empty: no push study
    controllers: list[Literal["offline", "online"]]
    directions: list[Literal["lateral", "forward"]]
    duration_s: Positive = 0.1  # s, the push's length, centred on mid single support
    max_force: Positive = 800.0  # N, the bisection's upper end
    tolerance: Positive = 25.0  # N, the bisection stops when the bracket is this narrow
    recovery_s: Positive = 1.5  # s after the push the base must stay up


@dataclass(frozen=True, config=CONFIG)
class SimulateParams:
    """simulate: MuJoCo model, footsteps, DCM/ZMP adjustment, whole-body QP IK (paper Sec. II-C)."""

    timestep: Positive  # s, MuJoCo step
    control_rate_hz: Positive  # IK + feedback rate
    kp_legs_torso: Positive  # position actuator stiffness, Nm/rad
    kp_arms: Positive
    kp_neck: Positive
    kv_ratio: NonNegative  # kv = kv_ratio * kp
    armature: NonNegative  # kg m^2 on every joint
    friction: Positive
    speed_scale: Positive  # the trajectory's time runs this much slower on the robot (0.33x)
    step_scale: Positive  # footstep displacements scaled by this (0.4x)
    min_phase_s: NonNegative  # contacts shorter than this (robot time) are dropped
    min_swing_s: NonNegative  # swings shorter than this (robot time) are dropped: the foot stays
    min_double_s: NonNegative  # s, least double support at every touchdown (taken from the swings)
    swing_height: Positive  # m
    com_height: Positive  # m, LIPM height and IK CoM height
    zmp_hold_s: NonNegative  # s of double support before the first step
    end_hold_s: NonNegative  # s of double support after the last step
    zmp_margin: NonNegative  # m kept inside the support rectangle by the plan
    plan_dt: Positive  # s, DCM/ZMP plan discretisation
    plan_zmp_weight: NonNegative  # ZMP toward the support centre
    plan_com_weight: NonNegative  # CoM toward the generated CoM (if any)
    plan_rate_weight: NonNegative  # smoothness: weight of the ZMP rate
    k_zmp: NonNegative  # ZMP-CoM feedback gains
    k_com: NonNegative
    zmp_filter_hz: Positive  # low-pass cut-off of the measured ZMP
    chest_gain: (
        NonNegative  # IK task gains (1/s); feet and CoM track their next-tick targets exactly
    )
    posture_gain: NonNegative
    posture_cost: NonNegative  # weight of the generated joints in the IK
    ik_solver: Str
    fall_height: Positive  # m, base below this = fall
    output_rate_hz: Positive  # traces written at most this often (small enough to commit)
    video_every_n: Count  # video: every n-th trace sample, played in real time
    video_width: Annotated[Int, Field(ge=16)]
    video_height: Annotated[Int, Field(ge=16)]
    mpc: MpcParams  # the online controller
    pushes: PushParams  # push recovery (results/sim/pushes.png, the summary's `pushes`)
    runs: list[SimulateRun]  # the simulate stage's runs


@dataclass(frozen=True, config=CONFIG)
class FiguresParams:
    """figures: the figures' style (what they show: evaluate)."""

    width_in: Positive  # figure width, inches
    font_pt: Positive
    dpi: Annotated[Int, Field(ge=50)]  # PNG resolution


@dataclass(frozen=True, config=CONFIG)
class Params:
    profile: Literal["paper", "quick"]
    profiles: dict[Str, dict[Str, Any]]
    data: DataParams
    retarget: RetargetParams
    features: FeaturesParams
    model: ModelParams
    train: TrainParams
    rollout: RolloutParams
    contacts: ContactParams
    evaluate: EvaluateParams
    simulate: SimulateParams
    figures: FiguresParams

    @model_validator(mode="after")
    def _references(self, info: ValidationInfo) -> Params:
        # cross-section names, when params.yaml loads: code (tests, studies) that builds
        # params itself may pair sections freely (a scenario of its own, no pushes)
        if (info.context or {}).get("params_file"):
            _check_references(self)
        return self


def model_names(params: Any) -> list[str]:
    """The training outputs' folder names: w<weight> per PI weight, the baseline, and with
    `train.adherent` the ADHERENT baseline."""
    adherent = ["adherent"] if getattr(params.train, "adherent", False) else []
    return [f"w{weight:g}" for weight in params.train.pi_weights] + ["baseline", *adherent]


def _unknown(key: str, value: Any, known: list) -> PydanticCustomError:
    return _fail(f"{key}: unknown {value!r}; known: {', '.join(map(str, known))}")


def _check_references(params: Params) -> None:
    """Names used in one place that must exist in another."""
    for name, item in params.data.sources.items():
        if item.skeleton != "auto" and item.skeleton not in params.data.skeletons:
            known = ["auto", *sorted(params.data.skeletons)]
            raise _unknown(f"data.sources.{name}.skeleton", item.skeleton, known)
    if params.features.window not in params.features.windows:
        raise _unknown("features.window", params.features.window, sorted(params.features.windows))
    for key, values in (
        ("train.seeds", params.train.seeds),
        ("train.pi_weights", params.train.pi_weights),
    ):
        if not values or len(set(values)) != len(values):
            raise _fail(f"{key} must be a non-empty list without repeats")
    scenarios = sorted(params.rollout.scenarios)
    for k, name in enumerate(params.rollout.scenario_names):
        if name not in params.rollout.scenarios:
            raise _unknown(f"rollout.scenario_names.{k}", name, scenarios)
    rolled_out = [*params.rollout.scenario_names, *params.rollout.protocols]
    evaluate, weights = params.evaluate, params.train.pi_weights
    if evaluate.scenario not in rolled_out:
        raise _unknown("evaluate.scenario", evaluate.scenario, rolled_out)
    for key in ("pi_weight", "large_weight"):
        if getattr(evaluate, key) not in weights:
            raise _unknown(f"evaluate.{key}", getattr(evaluate, key), weights)
    for key in ("box_weights", "foot_height_weights"):
        for k, weight in enumerate(getattr(evaluate, key)):
            if weight not in weights:
                raise _unknown(f"evaluate.{key}.{k}", weight, weights)
    runs = {
        "simulate.pushes.rollouts": params.simulate.pushes.rollouts,
        "simulate.runs": params.simulate.runs,
    }
    for where, items in runs.items():
        for k, run in enumerate(items):
            for name, value, known in (
                ("model", run.model, model_names(params)),
                ("seed", run.seed, params.train.seeds),
                ("scenario", run.scenario, rolled_out),
            ):
                if value not in known:
                    raise _unknown(f"{where}.{k}.{name}", value, known)


_PARAMS = TypeAdapter(Params)
_TAGS = {"int", "float", "str", "bool", "none"}


def _is_tag(part: Any) -> bool:
    """A union member's name pydantic puts in an error's location ('MotionSegment', 'int')."""
    sections = {name for name, kind in globals().items() if dataclasses.is_dataclass(kind)}
    return isinstance(part, str) and (part in _TAGS | sections or "[" in part or "-" in part)


def _field_type(loc: list) -> Any:
    """The annotation (with its constraints) at the location `loc` of Params, or None."""
    kind: Any = Params
    for part in loc:
        kind = _strip(kind)
        if dataclasses.is_dataclass(kind):
            kind = typing.get_type_hints(kind, include_extras=True).get(part)
        elif typing.get_origin(kind) is list:
            kind = typing.get_args(kind)[0]
        elif typing.get_origin(kind) is dict:
            kind = typing.get_args(kind)[1]
        else:
            options = [_strip(o) for o in typing.get_args(kind)]
            owners = [
                o
                for o in options
                if dataclasses.is_dataclass(o) and part in {f.name for f in dataclasses.fields(o)}
            ]
            kind = typing.get_type_hints(owners[0], include_extras=True)[part] if owners else None
        if kind is None:
            return None
    return kind


def _strip(kind: Any) -> Any:
    """`kind` without Annotated and without None as a union member."""
    if typing.get_origin(kind) is Annotated:
        return _strip(typing.get_args(kind)[0])
    options = [o for o in typing.get_args(kind) if o is not type(None)]
    if typing.get_origin(kind) in (typing.Union, type(int | str)) and len(options) == 1:
        return _strip(options[0])
    return kind


def _bound(kind: Any) -> str | None:
    """'in [0, 1)', '> 0', '>= 1': the range the field constraints of `kind` allow."""
    if typing.get_origin(kind) is not Annotated:  # `Positive | None`: the Annotated member
        kind = next((o for o in typing.get_args(kind) if typing.get_origin(o) is Annotated), kind)
    limits: dict[str, float] = {}
    for meta in typing.get_args(kind)[1:] if typing.get_origin(kind) is Annotated else []:
        for item in getattr(meta, "metadata", [meta]):
            for name in ("gt", "ge", "lt", "le"):
                if getattr(item, name, None) is not None:
                    limits[name] = getattr(item, name)
    low = "gt" if "gt" in limits else "ge" if "ge" in limits else None
    high = "lt" if "lt" in limits else "le" if "le" in limits else None
    if low and high:
        opening, closing = "(["[low == "ge"], ")]"[high == "le"]
        return f"in {opening}{limits[low]:g}, {limits[high]:g}{closing}"
    symbols = {"gt": ">", "ge": ">=", "lt": "<", "le": "<="}
    side = low or high
    return f"{symbols[side]} {limits[side]:g}" if side else None


_TYPE_NAMES = {"int_type": "int", "float_type": "float", "bool_type": "bool", "string_type": "str"}
_BOUNDS = {
    "greater_than": "gt",
    "greater_than_equal": "ge",
    "less_than": "lt",
    "less_than_equal": "le",
}


def _problem(error: Any) -> str:
    """One line for pydantic's error: the dotted key, what it must be, what it was."""
    loc = [part for part in error["loc"] if not _is_tag(part)]
    key = ".".join(map(str, loc))
    kind, value, ctx = error["type"], error.get("input"), error.get("ctx") or {}
    if kind == "params":
        return ctx["problem"].replace("@", f"{key}." if key else "")
    if kind == "missing":
        return f"missing key {key!r}"
    if kind in _UNKNOWN:
        return f"unknown key {key!r}"
    if kind in _BOUNDS:
        name = _BOUNDS[kind]
        bound = _bound(_field_type(loc)) or f"{name} {ctx[name]:g}"
        return f"{key} must be {bound}, not {value!r}"
    if kind == "finite_number":
        return f"{key} must be a finite number, not {value!r}"
    if kind in _TYPE_NAMES:
        return f"{key} must be {_TYPE_NAMES[kind]}, not {value!r}"
    if kind == "literal_error":
        return f"{key} must be one of {ctx['expected']}, not {value!r}"
    if kind == "list_type":
        return f"{key or 'params'} must be a list, not {value!r}"
    if kind in ("dict_type", "dataclass_type", "dataclass_exact_type"):
        return f"{key or 'params'} must be a mapping"
    return f"{key or 'params'}: {error['msg']}"


def validation_problem(error: ValidationError) -> str:
    """pydantic's error as one line naming the dotted key (a typo's unknown key first: it
    explains the missing one), e.g. for a section built from a file other than params.yaml."""
    errors = sorted(error.errors(), key=lambda e: e["type"] not in _UNKNOWN)
    return _problem(errors[0])


_UNKNOWN = ("unexpected_keyword_argument", "extra_forbidden")


def _validate(raw: dict, source: Path, where: str = "") -> Params:
    try:
        return _PARAMS.validate_python(raw, context={"params_file": True})
    except ValidationError as error:
        raise PimannError(source, validation_problem(error) + where) from None


def _apply_overrides(raw: dict, overrides: Any, name: str, source: Path) -> dict:
    """A copy of `raw` with the profile's dotted-key overrides applied."""
    if not isinstance(overrides, dict):
        raise PimannError(source, f"profiles.{name} must be a mapping of dotted keys")
    raw = copy.deepcopy(raw)
    for dotted, value in overrides.items():
        node = raw
        *parents, leaf = str(dotted).split(".")
        for part in parents:
            if not isinstance(node.get(part), dict):
                raise PimannError(source, f"profile override {dotted!r} names no key")
            node = node[part]
        if leaf not in node:
            raise PimannError(source, f"profile override {dotted!r} names no key")
        node[leaf] = value
    return raw


def load_params(path: str | Path = DEFAULT_PARAMS, profile: str | None = None) -> Params:
    """Read params.yaml and return the effective params of `profile` (default: the file's
    `profile`). The base values and every profile's merged result are validated, so a bad
    value fails even where the chosen profile overrides it."""
    path = Path(path)
    try:
        raw = yaml.safe_load(path.read_text())
    except FileNotFoundError:
        raise PimannError(path, "params file not found") from None
    except yaml.YAMLError as error:
        raise PimannError(path, f"not valid YAML: {error}".replace("\n", " ")) from None
    if not isinstance(raw, dict):
        raise PimannError(path, "params must be a mapping of sections")
    profiles = raw.get("profiles") or {}
    if not isinstance(profiles, dict):
        raise PimannError(path, "profiles must be a mapping of profile names")
    chosen = raw.get("profile") if profile is None else profile
    if chosen not in profiles:
        raise PimannError(path, f"profile {chosen!r} is not one of profiles {sorted(profiles)}")
    _validate(raw, path)  # the base values, as written
    effective = {}
    for name, overrides in profiles.items():
        merged = _apply_overrides(raw, overrides, name, path)
        merged["profile"] = name
        effective[name] = _validate(merged, path, f" (profile {name})")
    return effective[chosen]


def as_dict(params: Any) -> dict:
    """Plain dict of a params section, for recording provenance beside outputs."""
    return dataclasses.asdict(params)
