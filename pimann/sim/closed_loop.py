"""Closed loop: footsteps -> offline DCM/ZMP plan -> whole-body IK + ZMP-CoM feedback -> MuJoCo.

The IK and the feedback run at `control_rate_hz` (100 Hz), MuJoCo at 1 kHz; the measured ZMP
is low-pass filtered at every physics step (docs/controllers.md: unfiltered touchdown spikes
throw the feedback). The generated joints are only a low-weight posture target.

The IK lives in the plan's world, while each touchdown in the simulation lands a few mm off
and the errors add up; the measured CoM and ZMP are therefore shifted by the loaded feet's
drift from their planned spots (leg odometry) before the feedback. Without it a 15-step
backward walk drifted 3.5 cm and tipped over the stance foot's edge.
"""

from __future__ import annotations

import dataclasses
import logging
import time as clock
from collections.abc import Callable

import mujoco
import numpy as np
import pinocchio as pin

from pimann.core.errors import PimannError
from pimann.core.params import SimulateParams
from pimann.core.robot import LEFT_SOLE, RIGHT_SOLE, STANDING_JOINTS, Robot, load_robot
from pimann.core.trajectory import Trajectory
from pimann.sim.com_reference import com_reference
from pimann.sim.dcm import DCMPlan, knot_times, plan_dcm
from pimann.sim.footsteps import FootstepPlan, extract_footsteps
from pimann.sim.model import SimModel, build_sim_model
from pimann.sim.online import OnlineReference, Push, centroidal_state
from pimann.sim.synthetic import standing_feet
from pimann.sim.wbc import IKTargets, LowPass, WholeBodyIK, standing_pose, zmp_com_feedback

TRACE_KEYS = (
    "t",
    "ref",
    "meas",
    "gen",
    "com_ref",
    "com",
    "zmp_ref",
    "zmp",
    "h",
    "ik",
    "soles",
    "soles_ref",
    "base",
    "forces",
    "com_world",
)
SETTLE_S = 0.05  # s after touchdown before a stance foot's position is taken as its anchor
log = logging.getLogger(__name__)


@dataclasses.dataclass
class SimulationResult:
    """Traces at the control rate (after each tick's physics) and one run's summary figures."""

    time: np.ndarray  # (K,)
    joints_reference: np.ndarray  # (K, 26) IK output sent to the actuators
    joints_measured: np.ndarray  # (K, 26)
    joints_generated: np.ndarray  # (K, 26) posture target (generated joints, time-scaled)
    com_reference: np.ndarray  # (K, 3) DCM plan
    com_measured: np.ndarray  # (K, 3) in the plan's frame: less the loaded feet's drift
    zmp_reference: np.ndarray  # (K, 2)
    zmp_measured: np.ndarray  # (K, 2) low-pass filtered, in the plan's frame
    base_height: np.ndarray  # (K,)
    ik_error: np.ndarray  # (K,) m, IK soles and CoM against their targets (reachability)
    foot_slip: float  # m, largest horizontal drift of a stance foot from its touchdown spot
    fallen: bool
    fall_time: float | None
    real_time_factor: float  # simulated seconds per wall-clock second, whole loop
    planned_duration: float
    soles_measured: np.ndarray  # (K, 2, 3) left / right sole positions in the simulation
    soles_reference: np.ndarray  # (K, 2, 3) where the footstep plan has them
    footsteps: FootstepPlan  # the plan that was tracked (for figures: support polygons)
    dcm: DCMPlan
    base_pose: np.ndarray  # (K, 7) simulated base position and quaternion (x y z w), world
    foot_forces: np.ndarray  # (K, 2) floor's normal force on the left / right foot, N
    com_world: np.ndarray  # (K, 3) simulated CoM in the simulation's world (no drift removed)
    foot_slip_per_foot: np.ndarray  # (2,) m, foot_slip of the left / right foot
    controller: str = "offline"  # offline (DCM plan) or online (centroidal MPC)
    mpc_solve_s: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0))  # per solve
    mpc_horizons: list = dataclasses.field(default_factory=list)  # each MpcProblem solved

    @property
    def soles_final(self) -> np.ndarray:
        return self.soles_measured[-1]

    @property
    def soles_planned(self) -> np.ndarray:
        return self.soles_reference[-1]

    @property
    def joint_rmse(self) -> float:
        """RMS error of the measured joints against the IK references (rad)."""
        return float(np.sqrt(np.mean((self.joints_measured - self.joints_reference) ** 2)))

    def summary(self) -> dict[str, float | bool | None]:
        """The run's figures, JSON-ready."""
        com_error = np.linalg.norm(self.com_measured[:, :2] - self.com_reference[:, :2], axis=1)
        zmp_error = np.linalg.norm(self.zmp_measured - self.zmp_reference, axis=1)
        return {
            "fallen": self.fallen,
            "fall_time_s": self.fall_time,
            "simulated_s": float(self.time[-1]) if len(self.time) else 0.0,
            "planned_s": self.planned_duration,
            "foot_slip_m": self.foot_slip,
            "joint_rmse_rad": self.joint_rmse,
            "com_error_max_m": float(com_error.max()),
            "zmp_error_rms_m": float(np.sqrt(np.mean(zmp_error**2))),
            "final_sole_error_m": float(
                np.linalg.norm(self.soles_final[:, :2] - self.soles_planned[:, :2], axis=1).max()
            ),
            "real_time_factor": self.real_time_factor,
            "controller": self.controller,
            "mpc_solve_median_s": _quantile(self.mpc_solve_s, 0.5),
            "mpc_solve_p95_s": _quantile(self.mpc_solve_s, 0.95),
        }


def _quantile(values: np.ndarray, q: float) -> float | None:
    return float(np.quantile(values, q)) if len(values) else None


def _posture_from_trajectory(
    trajectory: Trajectory, plan: FootstepPlan
) -> Callable[[float], np.ndarray]:
    """Generated joints at robot time t, linearly interpolated on the generated clock."""
    times = np.asarray(trajectory.time, dtype=float)
    joints = np.asarray(trajectory.joint_positions, dtype=float)

    def posture(t: float) -> np.ndarray:
        g = plan.generated_time(t)
        return np.array([np.interp(g, times, joints[:, j]) for j in range(joints.shape[1])])

    return posture


def _sole_positions(robot: Robot, q: np.ndarray) -> np.ndarray:
    pin.framesForwardKinematics(robot.model, robot.data, q)
    return np.array(
        [robot.data.oMf[robot.frame_id(f)].translation.copy() for f in (LEFT_SOLE, RIGHT_SOLE)]
    )


def simulate_plan(
    plan: FootstepPlan,
    dcm: DCMPlan,
    params: SimulateParams,
    q0: np.ndarray,
    posture: Callable[[float], np.ndarray] | None = None,
    duration: float | None = None,
    robot: Robot | None = None,
    sim: SimModel | None = None,
    online: OnlineReference | None = None,
    push: Push | None = None,
) -> SimulationResult:
    """Run the controller on a footstep and DCM plan from the standing configuration q0.

    Offline: the CoM and ZMP references are the DCM plan's. Online: `online` replans them
    (and the footsteps of its own copy of the plan) from the measured state every MPC period.
    `push` is an external force on the base.
    """
    robot = robot or load_robot("simulation")
    sim = sim or build_sim_model(params)
    reference: DCMPlan | OnlineReference = dcm if online is None else online
    plan = plan if online is None else online.plan
    base_body = int(sim.model.jnt_bodyid[0])  # the free joint's body
    posture = posture or (lambda t: STANDING_JOINTS)
    dt = 1.0 / params.control_rate_hz
    substeps = max(1, int(round(dt / params.timestep)))
    duration = plan.duration if duration is None else min(duration, plan.duration)
    ticks = int(round(duration / dt))
    data = sim.new_data()
    sim.set_configuration(data, robot, q0)
    ik = WholeBodyIK(robot, params, q0)
    zmp_filter = LowPass(params.zmp_filter_hz, params.timestep, sim.com(data)[:2])
    # where the loaded feet stand against the plan: the IK lives in the plan's world
    drift = LowPass(params.zmp_filter_hz, dt, np.zeros(2))
    trace: dict[str, list] = {k: [] for k in TRACE_KEYS}
    anchors: dict[tuple[int, int], np.ndarray] = {}
    slip = np.zeros(2)
    fall_time = None
    start = clock.perf_counter()
    for tick in range(ticks):
        t = tick * dt
        com_measured = sim.com(data)
        com_measured[:2] -= drift.value
        zmp_measured = zmp_filter.value - drift.value
        if online is not None and online.due(t):
            online.update(t, com_measured, *centroidal_state(sim, data))
        com_ref, velocity_ref, zmp_ref = reference.at(t)
        velocity = zmp_com_feedback(
            velocity_ref[:2],
            zmp_ref,
            zmp_measured,
            com_ref[:2],
            com_measured[:2],
            params.k_zmp,
            params.k_com,
        )
        com_target = np.append(ik.com_position()[:2] + velocity * dt, reference.at(t + dt)[0][2])
        left, right = plan.sole_placement(0, t + dt), plan.sole_placement(1, t + dt)
        yaws = [np.arctan2(p.rotation[1, 0], p.rotation[0, 0]) for p in (left, right)]
        generated = np.asarray(posture(t), dtype=float)
        targets = IKTargets(
            left, right, com_target, float(np.angle(np.exp(1j * np.array(yaws)).mean())), generated
        )
        q_ik = ik.step(targets)
        joints = q_ik[robot.q_index]
        ik_soles = _sole_positions(robot, q_ik)
        ik_error = max(
            np.linalg.norm(ik_soles[0] - left.translation),
            np.linalg.norm(ik_soles[1] - right.translation),
            np.linalg.norm(ik.com_position() - com_target),
        )
        data.ctrl[:] = joints
        if push is not None:
            data.xfrc_applied[base_body, :3] = push.at(t)
        for _ in range(substeps):
            mujoco.mj_step(sim.model, data)
            zmp_filter(sim.zmp(data)[0])
        # stance-foot slip against the spot where it settled after touchdown
        soles = _sole_positions(robot, sim.configuration(data, robot))
        planned = np.array([plan.foot_pose(s, t + dt)[0] for s in (0, 1)])
        load = np.clip(sim.foot_normal_forces(data), 0.0, None)
        if load.sum() > 1.0:
            drift((load[:, None] * (soles[:, :2] - planned[:, :2])).sum(axis=0) / load.sum())
        for side in (0, 1):
            k = plan.stance_index(side, t)
            settled = plan.stance_index(side, t - SETTLE_S) == k
            if k is None or not (settled or plan.feet[side].t_on[k] == 0.0):
                continue
            anchor = anchors.setdefault((side, k), soles[side, :2].copy())
            slip[side] = max(slip[side], float(np.linalg.norm(soles[side, :2] - anchor)))
        com_after, _, zmp_ref_after = reference.at(t + dt)
        values = (
            t + dt,
            joints,
            sim.joints(data),
            generated,
            com_after,
            sim.com(data) - np.append(drift.value, 0.0),
            zmp_ref_after,
            zmp_filter.value - drift.value,
            sim.base_height(data),
            ik_error,
            soles,
            planned,
            np.concatenate([data.qpos[:3], np.roll(data.qpos[3:7], -1)]),
            load,
            sim.com(data),
        )
        for key, value in zip(TRACE_KEYS, values, strict=True):
            trace[key].append(value)
        if sim.base_height(data) < params.fall_height:
            fall_time = t + dt
            log.debug("fell at t = %.2f s", fall_time)  # a result: in the summary, not a fault
            break
    wall = clock.perf_counter() - start
    simulated = len(trace["t"]) * dt
    arrays = {k: np.array(v) for k, v in trace.items()}
    return SimulationResult(
        time=arrays["t"],
        joints_reference=arrays["ref"],
        joints_measured=arrays["meas"],
        joints_generated=arrays["gen"],
        com_reference=arrays["com_ref"],
        com_measured=arrays["com"],
        zmp_reference=arrays["zmp_ref"],
        zmp_measured=arrays["zmp"],
        base_height=arrays["h"],
        ik_error=arrays["ik"],
        foot_slip=float(slip.max()),
        fallen=fall_time is not None,
        fall_time=fall_time,
        real_time_factor=simulated / max(wall, 1e-9),
        planned_duration=plan.duration,
        soles_measured=arrays["soles"],
        soles_reference=arrays["soles_ref"],
        footsteps=plan,
        dcm=dcm,
        base_pose=arrays["base"],
        foot_forces=arrays["forces"],
        com_world=arrays["com_world"],
        foot_slip_per_foot=slip,
        controller="offline" if online is None else "online",
        mpc_solve_s=np.zeros(0) if online is None else np.array(online.solve_times),
        mpc_horizons=[] if online is None else online.horizons,
    )


def simulate_trajectory(
    trajectory: Trajectory,
    params: SimulateParams,
    duration: float | None = None,
    controller: str = "offline",
    push: Push | None = None,
) -> SimulationResult:
    """Track a generated trajectory in MuJoCo with either of the paper's controllers (II-C).

    offline: the DCM plan over the whole walk; online: the centroidal MPC, which takes the
    same plan's CoM as its reference and replans the CoM and the footsteps as it walks.
    """
    robot = load_robot("simulation")
    q0 = standing_pose(robot, params)
    plan = extract_footsteps(robot, trajectory, params, standing_feet(robot, q0))
    reference = None
    if params.plan_com_weight > 0:  # the generated CoM, kept close by the DCM plan
        reference = com_reference(robot, trajectory, plan, params, knot_times(plan, params))
    dcm = plan_dcm(plan, params, pin.centerOfMass(robot.model, robot.data, q0), reference)
    if controller not in ("offline", "online"):
        raise PimannError(trajectory.source, f"unknown controller {controller!r}")
    online = OnlineReference(plan, dcm, params) if controller == "online" else None
    return simulate_plan(
        plan,
        dcm,
        params,
        q0,
        _posture_from_trajectory(trajectory, plan),
        duration,
        robot,
        online=online,
        push=push,
    )
