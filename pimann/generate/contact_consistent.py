"""Contact-consistent trajectories: a foot in contact stays where it landed (docs/consistent.md).

The network's feet glide at the position level while the contact rule says they are down. A
contact-consistent trajectory holds each sole in place while it is in contact (the study's
rule, pimann.core.contacts, with the `contacts` params, on the lowest corner of the network's
sole): at one horizontal position and yaw, the sole flat (roll = pitch = 0) with its origin on
the floor (z = 0). Each leg's 6 joints are re-solved so that the sole reaches its target; the
base pose, the upper body and a foot in swing stay the network's. Touchdown and lift-off blend
over n = `blend_s` frames, so no joint jumps. At a lift-off the post-process lets the held sole
rise in the network's frame but no faster than `LIFT_SPEED` (the data's pace) while the rule
still counts it down (`lift_heights`).

The legs are solved together for every frame (or every rollout of a batch) at once: damped
Gauss-Newton on the sole's 6D error (position, and the vee of the rotation error's skew
part), warm-started from the network's joints of the same frame, geometric Jacobians of the
numpy leg chains (pimann.generate.leg_odometry.SoleFrames, pinocchio's geometry), a step
kept only where it lowers the error (Levenberg-Marquardt damping), joint limits by clipping
(a joint the network put beyond a limit may not go farther). A sole still beyond
`tolerance` after `iterations` gets up to `EXTRA_ITERATIONS` more (post: every held or
blending one; a lifting foot held behind the network's is 0.05-0.17 m short of its target
after 3 iterations). What remains of a held sole's error is reported (`residual`, the attrs'
`consistent_residual_max_m`): a sole out of the leg's reach from the network's base.

Joint velocities of the output: the file's own plus the change of the correction per frame,
sdot = sdot_raw + (dq_k - dq_{k-1}) / dt with dq = q - q_raw. Where the network's velocities
agree with its positions they agree with the new ones too, and a joint the correction leaves
alone (the upper body, a leg in swing) keeps the network's velocity exactly.

Two ways: `make_consistent` post-processes a finished trajectory (every frame at once), each
stance held at its middle frame's pose over the whole stance (`post_holds`); `InLoopHold` does
one step of a batch of rollouts, held at the touchdown pose as the stance goes (`SoleHolder`),
which the batched generator applies inside its loop (pimann.generate.batch_generator,
`consistent`): the held legs are recorded and place the base, the network is fed its own.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import torch
from scipy.spatial.transform import Rotation

from pimann.core.contacts import (
    FEET,
    SchmittTrigger,
    contacts_from_heights,
    frame_period,
    true_runs,
)
from pimann.core.errors import PimannError
from pimann.core.params import ConsistentParams, ContactParams
from pimann.core.robot import LEG_JOINTS, SOLE_CORNERS, Robot
from pimann.core.rotations import (
    exp_so3,
    quaternion_xyzw_matrices,
    rot_z,
    skew_part,
    vee,
    yaw_of,
)
from pimann.core.trajectory import Trajectory
from pimann.generate.leg_odometry import SoleFrames
from pimann.learn.kinematics_torch import TorchKinematics

# Gauss-Newton iterations beyond `iterations` for the frames whose held sole is still farther
# than `tolerance` from its target (a long stance far from the network's foot); cheap, since
# they run on those frames only, and only while each lowers the squared error below STALL x
# the one before (else the sole is out of reach: its residual is reported)
EXTRA_ITERATIONS = 20
STALL = 0.9
# a foot whose network sole's lowest corner is below this share of the rule's off height is
# held flat on the floor; above it the hold lets it rise, to the network's own height at the
# off height (a lift-off the rule sees when the network's foot does)
FLAT_SHARE = 0.5
# a held sole stays within this of the network's sole origin horizontally and of its yaw;
# beyond, the hold follows the network's foot just enough (`leash`). Tried on 36 retargeted
# walks with a sideways drift: without a leash two clips (turns on the spot) stretched their
# legs out of reach (up to 2.5x their raw sliding); with these none above 1.08x; a leash on
# the hip-to-sole distance (the leg's length) held less (median 17.6 against 15.1)
MAX_HOLD_GAP = 0.15  # m
MAX_HOLD_TURN = 0.5  # rad
# ... and within this of it horizontally while the network's foot is up (its lowest corner
# above FLAT_SHARE x the off height: a lift-off, where the rule's switch time still counts the
# foot down while the network's swings it forward at 1-3 m/s). At MAX_HOLD_GAP the leash
# dragged the held foot after the network's in those counted frames: on the trained models'
# post variants (authors, forward, mixed; both steerings; seeds 0, 1) the frames the leash
# held made 2-8 of w=10's 19-24 forward and steered sliding. Tried 0.2, 0.25, 0.35: 0.25 and
# 0.35 moved a w=10 steered touchdown (cadence 1.75 -> 1.875), 0.2 no MANN's of w <= 20
MAX_LIFT_GAP = 0.2  # m
# a lifting foot (vertical weight below the horizontal one) that its leg cannot reach weighs
# its height and tilt this many times its horizontal place: it rises with the network's
# foot, so the rule sees the lift-off when the network's does. Tried 1, 3, 10 (position-level
# sliding): the analytic test gait's steered rollout, whose lift-offs are out of reach, 41.1
# with 1, 34.2 with 3 (raw 34.7); the retargeted walks' median 14.5 with 1, 14.6 with 3
# (raw 14.8), 10 worse on both. The post's lift at `LIFT_SPEED` (both weights 1) goes without:
# weighed so, w=10's eight authors' and forward rollouts 15.6 against 15.5, every model's 78
# post rollouts (median) 15.6 against 15.5
LIFT_PRIORITY = 3.0
# m/s: a held sole leaving the floor rises no faster than this through the frames the rule
# still counts it down after the network's foot has passed the off height (the retargeted
# data's median there, python -m diagnostics.lift_speed; the network's rises at 0.6-1.2 m/s).
# It crosses the off height in the network's frame, so the rule sees the same lift-off. Slower
# (0.3, 0.45) slides a little less (w=10's eight authors' and forward post rollouts 14.7, 15.2
# against 15.5), faster a little more (0.8: 15.8); we keep the data's pace, not one below it
LIFT_SPEED = 0.56
# a held stance whose flat sole its leg leaves farther than this from the floor pose (an ankle
# at its limit under a foot the network keeps tilted) rests at the network's tilt instead
FLAT_MISS = 0.005  # m
# a post frame whose leg the solver left beyond `tolerance` from the network's joints (a
# stall: its neighbours, solved, reach the same targets) is solved again from the previous
# frame's solved leg, then the next one's, this many times over (a failure next to a failure
# mends once its neighbour has). On w0's authors' test 12 frames' lifting feet sank back
# below the contact rule's off height (up to 0.12 m from their targets), the rule counted
# the feet down 2 frames longer while they blended away at 1-2 m/s
RETRY_PASSES = 3
LEGS = np.array(LEG_JOINTS).reshape(2, 6)  # study joints of the left and the right leg
_CORNERS = np.vstack([SOLE_CORNERS.T, np.ones(len(SOLE_CORNERS))])  # (4, C) homogeneous
_EYE3, _EYE6 = np.eye(3), np.eye(6)


def blend_frames(params: ConsistentParams, dt: float) -> int:
    """Frames over which a touchdown or a lift-off blends (at least 1: a switch in a frame)."""
    return max(1, int(round(params.blend_s / dt)))


def without_yaw(rotation: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotations with their heading taken off, Rz(yaw)^T R: a sole's tilt (roll and
    pitch in its heading's axes), R = Rz(yaw_of(R)) without_yaw(R)."""
    return np.swapaxes(rot_z(yaw_of(rotation)), -1, -2) @ rotation


def homogeneous(position: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    """(..., 4, 4) placements from positions (..., 3) and rotations (..., 3, 3)."""
    out = np.zeros((*position.shape[:-1], 4, 4))
    out[..., :3, :3], out[..., :3, 3], out[..., 3, 3] = rotation, position, 1.0
    return out


def inverse(placement: np.ndarray) -> np.ndarray:
    """(..., 4, 4) inverses of rigid placements."""
    rotation_t = np.swapaxes(placement[..., :3, :3], -1, -2)
    return homogeneous(-(rotation_t @ placement[..., :3, 3:])[..., 0], rotation_t)


def flat_on_floor(placement: np.ndarray) -> np.ndarray:
    """The held pose of soles (..., 4, 4): origin's x, y and the yaw kept, flat, z = 0."""
    position = placement[..., :3, 3].copy()
    position[..., 2] = 0.0
    return homogeneous(position, rot_z(yaw_of(placement[..., :3, :3])))


def interpolate(start: np.ndarray, end: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """Placements (..., 4, 4) a fraction `weight` (...) of the way from `start` to `end`
    (position linearly, rotation along the geodesic)."""
    w = np.asarray(weight, dtype=float)
    position = (1 - w[..., None]) * start[..., :3, 3] + w[..., None] * end[..., :3, 3]
    relative = np.swapaxes(start[..., :3, :3], -1, -2) @ end[..., :3, :3]
    shape = relative.shape[:-2]
    rotvec = _log_so3(relative.reshape(-1, 3, 3))
    step = exp_so3((w.reshape(-1, 1) * np.broadcast_to(rotvec, (w.size, 3))).reshape(-1, 3))
    rotation = start[..., :3, :3] @ step.reshape(*shape, 3, 3)
    return homogeneous(position, rotation)


def _log_so3(rotations: np.ndarray) -> np.ndarray:
    """(N, 3) rotation vectors of rotations (N, 3, 3): vee(R - R^T) angle / (2 sin angle),
    scipy's where the angle nears pi (its axis is not in the skew part there)."""
    cosine = np.clip((np.trace(rotations, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0)
    angle = np.arccos(cosine)
    skew = vee(rotations - np.swapaxes(rotations, -1, -2))  # 2 sin(angle) axis
    small = angle < 1e-6
    factor = np.where(small, 0.5, angle / (2.0 * np.sin(np.where(small, 1.0, angle))))
    out = factor[:, None] * skew
    near_pi = angle > np.pi - 1e-3
    if near_pi.any():
        out[near_pi] = Rotation.from_matrix(rotations[near_pi]).as_rotvec()
    return out


def corner_distance(placement: np.ndarray, target: np.ndarray) -> np.ndarray:
    """(...) the largest distance between a sole's corners at `placement` and at `target`."""
    gap = (placement - target)[..., :3, :] @ _CORNERS  # (..., 3, C)
    return np.sqrt((gap * gap).sum(axis=-2)).max(axis=-1)


@dataclasses.dataclass
class LegSolution:
    joints: np.ndarray  # (B, 26) the joints with the legs re-solved
    residual: np.ndarray  # (B, 2) m, each sole's largest corner distance from its target
    iterations: int  # Gauss-Newton iterations run (the most any frame needed)


class LegSolver:
    """Both legs' joints for sole targets in the base frame, every row (frame, rollout) at once.

    The chains are pimann.generate.leg_odometry.SoleFrames' (pinocchio's geometry), multiplied
    joint after joint so that every joint's axis and origin come out too: the Jacobian is
    geometric (axis x lever arm), one chain pass an iteration.
    """

    def __init__(self, robot: Robot, params: ConsistentParams):
        self.frames = SoleFrames(robot)
        self.params = params
        self.lower = robot.joint_lower[LEGS]
        self.upper = robot.joint_upper[LEGS]
        chains = TorchKinematics(robot, torch.float64, "cpu", frames=FEET)
        if not np.array_equal(chains.index.numpy(), LEGS):
            raise PimannError(robot.urdf_path, "the sole chains are not the 6 leg joints each")
        # each joint's axis in its own frame: P [a] = rot_k, so [a] = P^T rot_k
        skew = np.swapaxes(chains.placement_rot.numpy(), -1, -2) @ chains.rot_k.numpy()
        self.axes = vee(skew)  # (2, 6, 3)
        self.depth = LEGS.shape[1] + 1  # the joints, then the sole frame's fixed placement

    def chain(self, joints: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(soles (B, 2, 4, 4), joint axes (B, 2, 6, 3), joint origins (B, 2, 6, 3)), base
        frame."""
        frames = self.frames
        sin_cos = np.sin(joints[:, frames.index, None] + frames.shift)[..., None, :]
        local = (sin_cos @ frames.varying + frames.constant).reshape(*sin_cos.shape[:3], 4, 4)
        placements = [local[:, :, 0]]
        for k in range(1, self.depth):
            placements.append(placements[-1] @ local[:, :, k])
        joint_frames = np.stack(placements[:-1], axis=2)  # (B, 2, 6, 4, 4)
        axes = (joint_frames[..., :3, :3] @ self.axes[..., None])[..., 0]
        return placements[-1], axes, joint_frames[..., :3, 3]

    def soles(self, joints: np.ndarray) -> np.ndarray:
        """(B, 2, 4, 4) both soles in the base frame."""
        return self.frames.transforms(joints)

    def _error(self, joints: np.ndarray, targets: np.ndarray) -> np.ndarray:
        """(B, 2, 6) position error, then the rotation error's vee(skew(R_t^T R))."""
        return self._error_of(self.soles(joints), targets)

    @staticmethod
    def _error_of(soles: np.ndarray, targets: np.ndarray) -> np.ndarray:
        out = np.empty((*soles.shape[:2], 6))
        out[..., :3] = soles[..., :3, 3] - targets[..., :3, 3]
        relative = np.swapaxes(targets[..., :3, :3], -1, -2) @ soles[..., :3, :3]
        out[..., 3:] = vee(skew_part(relative))
        return out

    def _jacobian(self, joints: np.ndarray, targets: np.ndarray) -> np.ndarray:
        """(B, 2, 6 errors, 6 joints) of `_error`: the lever arm a x (p - o) for the position;
        for vee(skew(M)), M = R_t^T R, d M = [R_t^T a] M, so 0.5 (tr M I - M) R_t^T a."""
        soles, axes, origins = self.chain(joints)
        jacobian = np.empty((*soles.shape[:2], 6, 6))
        lever = soles[..., None, :3, 3] - origins
        a, r = axes, lever  # a x r, component by component (np.cross is slow on small arrays)
        jacobian[..., 0, :] = a[..., 1] * r[..., 2] - a[..., 2] * r[..., 1]
        jacobian[..., 1, :] = a[..., 2] * r[..., 0] - a[..., 0] * r[..., 2]
        jacobian[..., 2, :] = a[..., 0] * r[..., 1] - a[..., 1] * r[..., 0]
        target_t = np.swapaxes(targets[..., :3, :3], -1, -2)
        relative = target_t @ soles[..., :3, :3]
        trace = np.trace(relative, axis1=-2, axis2=-1)[..., None, None]
        jacobian[..., 3:, :] = (
            0.5 * (trace * _EYE3 - relative) @ target_t @ np.swapaxes(axes, -1, -2)
        )
        return jacobian

    def _cost(
        self, joints: np.ndarray, targets: np.ndarray, active: np.ndarray, scale: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """(error (B, 2, 6), each component times `scale`; cost (B, 2): its squared norm, 0
        for an inactive leg)."""
        error = scale * self._error(joints, targets)
        return error, np.where(active, (error * error).sum(axis=-1), 0.0)

    @staticmethod
    def _step(jacobian: np.ndarray, error: np.ndarray, damping: np.ndarray) -> np.ndarray:
        """(B, 2, 6) the damped Gauss-Newton step (J^T J + lambda I) dq = -J^T e."""
        jacobian_t = np.swapaxes(jacobian, -1, -2)
        normal = jacobian_t @ jacobian + damping[..., None, None] * _EYE6
        return np.linalg.solve(normal, -(jacobian_t @ error[..., None]))[..., 0]

    def _iterate(
        self,
        joints: np.ndarray,
        targets: np.ndarray,
        active: np.ndarray,
        error: np.ndarray,
        cost: np.ndarray,
        damping: np.ndarray,
        scale: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """One damped Gauss-Newton step of the active legs, in place, kept only where it
        lowers the leg's error (else its damping grows tenfold: Levenberg-Marquardt, which a
        straight knee at its limit needs); returns the new (error, cost)."""
        jacobian = scale[..., None] * self._jacobian(joints, targets)
        legs = joints[:, LEGS]
        # within the limits; a joint the network put beyond one may not go farther
        lower, upper = np.minimum(self.lower, legs), np.maximum(self.upper, legs)
        step = self._step(jacobian, error, damping)
        blocked = (legs + step < lower) | (legs + step > upper)
        if blocked.any():  # a joint stopped by its limit: the others solve without it
            jacobian = np.where(blocked[..., None, :], 0.0, jacobian)
            step = self._step(jacobian, error, damping)
        trial = joints.copy()
        legs = legs + np.where(active[..., None], step, 0.0)
        trial[:, LEGS] = np.clip(legs, lower, upper)
        trial_error, trial_cost = self._cost(trial, targets, active, scale)
        better = active & (trial_cost < cost)
        joints[:, LEGS] = np.where(better[..., None], trial[:, LEGS], joints[:, LEGS])
        damping[:] = np.where(better, np.maximum(damping / 10, self.params.damping), damping * 10)
        error = np.where(better[..., None], trial_error, error)
        return error, np.where(better, trial_cost, cost)

    def solve(
        self,
        joints: np.ndarray,
        targets: np.ndarray,
        active: np.ndarray,
        strict: np.ndarray | None = None,
        lifting: np.ndarray | None = None,
    ) -> LegSolution:
        """Legs of `active` (B, 2) re-solved from `joints` (B, 26) towards `targets` (B, 2, 4, 4,
        base frame); the other legs and every other joint unchanged. Only the legs of `strict`
        (default: every active one; the held soles) get the iterations beyond `iterations`
        that bring them within `tolerance`. The legs of `lifting` (B, 2) weigh their sole's
        height and tilt `LIFT_PRIORITY` times its horizontal place: a foot held behind the
        network's that its leg cannot reach rises with the network's foot first."""
        joints = np.array(joints, dtype=float)
        rows = np.flatnonzero(active.any(axis=1))
        residual = np.zeros(active.shape)
        if not len(rows):
            return LegSolution(joints, residual, 0)
        part, goal, on = joints[rows], targets[rows], active[rows]
        strict = on if strict is None else on & strict[rows]
        scale = np.ones((*on.shape, 6))
        if lifting is not None:
            scale[lifting[rows]] = [1.0, 1.0, LIFT_PRIORITY, LIFT_PRIORITY, LIFT_PRIORITY, 1.0]
        error, cost = self._cost(part, goal, on, scale)
        damping = np.full(on.shape, float(self.params.damping))
        for _ in range(self.params.iterations):
            error, cost = self._iterate(part, goal, on, error, cost, damping, scale)
        done = self.params.iterations
        # the held soles still beyond tolerance, alone, while their error keeps falling
        gap = np.where(strict, corner_distance(self.soles(part), goal), 0.0)
        on = strict & (gap > self.params.tolerance)
        for _ in range(EXTRA_ITERATIONS):
            some = np.flatnonzero(on.any(axis=1))
            if not len(some):
                break
            done += 1
            sub, before, sub_damping = part[some], cost[some], damping[some]
            error[some], cost[some] = self._iterate(
                sub, goal[some], on[some], error[some], before, sub_damping, scale[some]
            )
            part[some], damping[some] = sub, sub_damping
            gap = corner_distance(self.soles(sub), goal[some])
            on[some] &= (gap > self.params.tolerance) & (cost[some] < STALL * before)
        joints[rows] = part
        residual[rows] = np.where(active[rows], corner_distance(self.soles(part), goal), 0.0)
        return LegSolution(joints, residual, done)


class SoleHolder:
    """The hold of each foot of B rows, frame after frame: two weights and the held pose.

    The horizontal weight (the sole origin's x, y and the yaw) rises by 1 / n a frame while
    the rule says contact and falls by 1 / n once it says swing. The vertical weight (height
    and tilt: flat on the floor) is the horizontal one while the network's lowest corner h is
    below `FLAT_SHARE` x the off height, falling linearly to 0 at the off height: a foot on
    the floor is flat on it, and as the network's foot rises to the rule's off height ours
    rises with it (at the off height, to the network's height exactly), so the rule sees the
    same lift-off and the foot returns to the network's path horizontally in the air, where
    no contact is counted.
    """

    def __init__(
        self, rows: int, params: ConsistentParams, contact_params: ContactParams, dt: float
    ):
        self.rate = 1.0 / blend_frames(params, dt)
        self.off_height = float(contact_params.off_height)
        self.ramp = np.zeros((rows, 2))  # the horizontal weight per foot
        self.held = np.zeros((rows, 2, 3))  # held x, y and yaw per foot

    def advance(self, soles: np.ndarray, contacts: np.ndarray) -> np.ndarray:
        """Weights (B, 2, 2: horizontal, vertical) after a frame with world soles (B, 2, 4, 4)
        and contacts (B, 2); a foot that touches down with no hold left takes its sole's x, y
        and yaw; a held one stays within the `leash` of the network's."""
        landing = contacts & (self.ramp <= 0.0)
        if landing.any():
            self.held[landing, :2] = soles[landing, :2, 3]
            self.held[landing, 2] = yaw_of(soles[landing, :3, :3])
        self.held = leash(self.held, soles)
        self.ramp = np.clip(self.ramp + np.where(contacts, self.rate, -self.rate), 0.0, 1.0)
        return np.stack([self.ramp, self.ramp * flatness(soles, self.off_height)], axis=-1)

    def step(self, soles: np.ndarray, contacts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(targets (B, 2, 4, 4) world, weights (B, 2, 2)) of one frame."""
        weight = self.advance(soles, contacts)
        return hold_targets(soles, self.held, weight), weight


def leash(
    held: np.ndarray, soles: np.ndarray, gap: float | np.ndarray = MAX_HOLD_GAP
) -> np.ndarray:
    """Held (x, y, yaw) (B, 2, 3) moved towards the network's soles (B, 2, 4, 4) just enough to
    stay within `gap` (m; a scalar or (B, 2)) of their origins horizontally and `MAX_HOLD_TURN`
    of their yaw: a foot the network carries far from where it landed (a turn on the spot, a
    long shuffle) is followed rather than held out of its leg's reach."""
    out = held.copy()
    offset = held[..., :2] - soles[..., :2, 3]
    distance = np.linalg.norm(offset, axis=-1, keepdims=True)
    limit = np.asarray(gap, dtype=float)[..., None] if np.ndim(gap) else gap
    out[..., :2] = soles[..., :2, 3] + offset * np.minimum(1.0, limit / np.maximum(distance, 1e-12))
    yaw = yaw_of(soles[..., :3, :3])
    turn = np.arctan2(np.sin(held[..., 2] - yaw), np.cos(held[..., 2] - yaw))
    out[..., 2] = yaw + np.clip(turn, -MAX_HOLD_TURN, MAX_HOLD_TURN)
    return out


def hold_targets(
    soles: np.ndarray,
    held: np.ndarray,
    weight: np.ndarray,
    rest: np.ndarray | None = None,
) -> np.ndarray:
    """Sole targets (..., 4, 4): the network's soles moved by the horizontal weight towards the
    held x, y, yaw and by the vertical weight towards their rest on the floor: `rest` (..., 4,
    4), the tilt (roll and pitch, no yaw) and the origin's height; default flat, z = 0."""
    horizontal, vertical = weight[..., 0], weight[..., 1]
    rotation = soles[..., :3, :3]
    yaw = yaw_of(rotation)
    turn = np.arctan2(np.sin(held[..., 2] - yaw), np.cos(held[..., 2] - yaw))
    tilt = without_yaw(rotation)  # R = Rz(yaw) tilt
    if rest is None:
        rest = np.broadcast_to(np.eye(4), tilt.shape[:-2] + (4, 4))
    tilt = interpolate(homogeneous(np.zeros(tilt.shape[:-2] + (3,)), tilt), rest, vertical)
    position = soles[..., :3, 3].copy()
    position[..., :2] += horizontal[..., None] * (held[..., :2] - position[..., :2])
    position[..., 2] += vertical * (rest[..., 2, 3] - position[..., 2])
    return homogeneous(position, rot_z(yaw + horizontal * turn) @ tilt[..., :3, :3])


def standing_at(tilt: np.ndarray, height: np.ndarray | float = 0.0) -> np.ndarray:
    """(..., 4, 4) a sole at rotation `tilt` (..., 3, 3), its origin above (0, 0) at the height
    that puts its lowest corner at `height` (...)."""
    out = homogeneous(np.zeros(tilt.shape[:-2] + (3,)), tilt)
    out[..., 2, 3] = height - (out[..., 2:3, :] @ _CORNERS)[..., 0, :].min(axis=-1)
    return out


def resting_tilt(soles: np.ndarray) -> np.ndarray:
    """(..., 4, 4) each sole's tilt (its rotation without the yaw) with the origin at the height
    that puts its lowest corner on the floor."""
    return standing_at(without_yaw(soles[..., :3, :3]))


def lifting_rest(
    rest: np.ndarray, soles: np.ndarray, lift: np.ndarray, off_height: float
) -> np.ndarray:
    """`rest` (..., 2, 4, 4) with the frames a held sole lifts at (`lift` (..., 2) > 0) turned
    from its tilt towards the network's sole's (no yaw) as the network's lowest corner rises
    from `FLAT_SHARE` x the off height to it, its lowest corner at `lift`: a foot the network
    pitches as it lifts (w=100's, 10-12 degrees) is not asked to stay flat out of its ankle's
    reach, which left it sinking while the rule counted it."""
    lifting = lift > 0.0
    if not lifting.any():
        return rest
    turned = interpolate(
        standing_at(rest[..., :3, :3]),
        standing_at(without_yaw(soles[..., :3, :3])),
        1.0 - flatness(soles, off_height),
    )
    return np.where(lifting[..., None, None], standing_at(turned[..., :3, :3], lift), rest)


def flatness(soles: np.ndarray, off_height: float) -> np.ndarray:
    """(..., 2) how far each foot is held flat on the floor: 1 while the network's lowest
    corner is below `FLAT_SHARE` x the rule's off height, falling linearly to 0 at it."""
    low = (off_height - lowest_heights(soles)) / ((1.0 - FLAT_SHARE) * off_height)
    return np.clip(low, 0.0, 1.0)


def rollout_contacts(heights: np.ndarray, dt: float, params: ContactParams) -> np.ndarray:
    """(T, 2) the contact rule on lowest-corner heights as the generator runs it: both feet
    down at the start (a rollout starts standing)."""
    flags = contacts_from_heights(heights, dt, params, initial=True)
    flags[0] = True
    return flags


def lowest_heights(soles: np.ndarray) -> np.ndarray:
    """(..., 2) lowest corner height of world soles (..., 2, 4, 4)."""
    return (soles[..., 2:3, :] @ _CORNERS)[..., 0, :].min(axis=-1)


@dataclasses.dataclass
class Consistent:
    """A contact-consistent trajectory and what it took."""

    trajectory: Trajectory
    weights: np.ndarray  # (T, 2, 2) each foot's (horizontal, vertical) hold weight (1: held)
    residual: np.ndarray  # (T, 2) m, held sole's largest corner distance from its target
    contacts: np.ndarray  # (T, 2) the rule's contacts on the raw soles (the holds')
    lift: np.ndarray  # (T, 2) m, the held sole's height at a lift-off (0: on the floor)

    @property
    def held(self) -> np.ndarray:
        """(T, 2) the frames a foot is held flat on the floor (both weights 1, not lifting)."""
        return (self.weights.min(axis=-1) >= 1.0) & (self.lift <= 0.0)


def world_soles(solver: LegSolver, trajectory: Trajectory) -> tuple[np.ndarray, np.ndarray]:
    """(base placements (T, 4, 4), soles (T, 2, 4, 4)) in the world."""
    rotation = quaternion_xyzw_matrices(np.asarray(trajectory.base_quaternion_xyzw, float))
    base = homogeneous(np.asarray(trajectory.base_position, float), rotation)
    return base, base[:, None] @ solver.soles(np.asarray(trajectory.joint_positions, float))


def corrected_velocities(
    raw_velocities: np.ndarray | None, correction: np.ndarray, dt: float
) -> np.ndarray | None:
    """sdot_raw + the correction's backward difference (0 at the first frame); None stays."""
    if raw_velocities is None:
        return None
    change = np.zeros_like(correction)
    change[1:] = np.diff(correction, axis=0) / dt
    return np.asarray(raw_velocities, float) + change


def lift_heights(
    heights: np.ndarray, first: int, last: int, delay: int, off_height: float, step: float
) -> np.ndarray:
    """(T,) the held sole's lowest-corner height through a stance held over frames [first,
    last] whose foot the rule lets go at last + 1, from the network's lowest-corner heights
    (T,): the network's, capped by the line off + (k - c + 1) step through the network's first
    frame above the off height, c = last + 1 - delay. It crosses the off height at c, as the
    network's does (the rule sees the same lift-off), and through the frames the rule still
    counts stands no higher than the line (`step` a frame: the data's pace, where w=10's
    steered feet rise 1.3-2.3 cm a frame, quartile to 90th percentile); on the floor where the
    line is below it, held at its last height after `last`. (The line itself from 2 frames
    before c, above the network's foot there, slid less, w=10's eight authors' and forward post
    rollouts 13.1 against 15.5, but the legs could not reach it: on the retargeted data the
    held soles' largest residual rose from 0.0 mm to 7.9 mm (medians over clips) and 4 post
    rollouts lost 1-2 touchdowns.)"""
    frames = np.arange(len(heights))
    crossing = last + 1 - delay
    rise = off_height + (frames - crossing + 1) * step
    out = np.clip(np.minimum(heights, rise), 0.0, None)
    out[frames < first] = 0.0
    out[frames > last] = out[last]
    return out


def post_holds(
    soles: np.ndarray,
    contacts: np.ndarray,
    frames: int,
    contact_params: ContactParams,
    dt: float,
    lift_speed: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(weights (T, 2, 2), held x, y, yaw (T, 2, 3), the middle frame of the stance each frame's
    hold is of (T, 2), -1: none; the held sole's height at a lift-off (T, 2)) of a finished
    trajectory's feet, world soles (T, 2, 4, 4) and the rule's contacts (T, 2). Knowing the
    whole trajectory, each stance [a, b) is held from the frame before its touchdown ([a - 1,
    b - 1]: the central difference of its first contact frame sees no move) at the network's
    sole pose (x, y, yaw) of its middle frame (leashed: `MAX_HOLD_GAP`, `MAX_LIFT_GAP` while
    the network's foot is up): the hold then sits at most half the network's glide from the
    network's foot, at the touchdown and at the lift-off. The horizontal weight rises over the
    `frames` frames before a - 1, in the air, and falls over those after b - 1, along a
    smootherstep (10 u^3 - 15 u^4 + 6 u^5): the foot leaves the hold slowly while the rule may
    still count it down. The vertical weight: before a - 1, the horizontal one times the
    flatness of the network's lowest corner (a landing foot comes down with the network's);
    where the sole lifts (`lift_heights` above 0), the horizontal one, towards the sole at
    those heights (no higher than a line rising at `lift_speed`, the data's pace, through the
    frames the rule still counts after the network's foot passes the off height), its tilt
    turned towards the network's (`lifting_rest`); elsewhere in the stance as at the landing
    (a network's foot above `FLAT_SHARE` x the off height mid-stance rises with it). Measured on
    w=10's authors'-test rollouts (position-level sliding, seeds 0 / 1): the causal blends
    18.6 / 17.8; held from a - 1 at the touchdown pose 14.9 / 13.9, but held stances its leg
    could not keep flat left the floor (fewer contact frames counted, 19 touchdowns against
    14); with `FLAT_MISS`'s tilted rest and the middle frame's pose 19.9 / 11.0 (held through
    b: 27.6 / 12.4; the touchdown pose: 19.5 / 11.2, the gait's touchdowns no longer the raw
    ones); with the stalled legs solved again from their neighbours (`retry_from_neighbours`)
    13.6 / 10.9, and the smoothstep blends 12.4 / 10.0 (the linear ones moved the foot 20% of
    its gap in the frame after the last contact, which the rule's central difference counts;
    the smootherstep 6%: with `MAX_LIFT_GAP` 11.3 / 9.7 -> 10.9 / 9.5); the lift at
    `LIFT_SPEED` (against the sole released from `FLAT_SHARE` of the off height to reach the
    network's height at it) 9.2 / 8.8, steered 18.1 / 21.8 (from 20.3 / 23.3)."""
    count = len(soles)
    ramp = np.zeros(contacts.shape)
    vertical = np.zeros(contacts.shape)
    lift = np.zeros(contacts.shape)
    held = np.zeros((*contacts.shape, 3))
    middles = np.full(contacts.shape, -1)
    steps = np.arange(count)
    yaws = yaw_of(soles[..., :3, :3])
    off = float(contact_params.off_height)
    heights = lowest_heights(soles)
    low = flatness(soles, off)
    delay = SchmittTrigger.from_params(contact_params, dt).delay_samples
    for foot in range(contacts.shape[1]):
        for a, b in true_runs(contacts[:, foot]):
            first, last = max(a - 1, 0), b - 1
            weight = np.clip(1.0 - np.maximum(first - steps, steps - last) / frames, 0.0, 1.0)
            weight = weight**3 * (10.0 - 15.0 * weight + 6.0 * weight * weight)  # smootherstep
            take = (weight > ramp[:, foot]) | (weight >= 1.0)  # a shared blend: the larger
            ramp[take, foot] = weight[take]
            rise = np.zeros(count)
            if b < count:  # the last stance of the trajectory never lifts off
                rise = lift_heights(heights[:, foot], first, last, delay, off, lift_speed * dt)
            lifting = (steps >= first) & (rise > 0.0)
            vertical[take, foot] = np.where(lifting, weight, weight * low[:, foot])[take]
            lift[take, foot] = rise[take]
            middle = (a + b - 1) // 2
            held[take, foot, :2] = soles[middle, foot, :2, 3]
            held[take, foot, 2] = yaws[middle, foot]
            middles[take, foot] = middle
    held = leash(held, soles, np.where(low < 1.0, MAX_LIFT_GAP, MAX_HOLD_GAP))
    return np.stack([ramp, vertical], axis=-1), held, middles, lift


def retry_from_neighbours(
    solver: LegSolver,
    solution: LegSolution,
    targets: np.ndarray,
    active: np.ndarray,
    lifting: np.ndarray,
    tolerance: float,
) -> LegSolution:
    """`solution` of every frame of a trajectory (targets (T, 2, 4, 4), base frame) with each
    leg the solver left beyond `tolerance` solved again from its previous frame's solved joints,
    then from its next frame's (`RETRY_PASSES` times): a leg keeps the smaller residual."""
    joints, residual = solution.joints.copy(), solution.residual.copy()
    for shift in (1, -1) * RETRY_PASSES:
        failed = active & (residual > tolerance)
        failed[[0, -1][shift < 0]] = False  # no neighbour on that side
        rows = np.flatnonzero(failed.any(axis=1))
        if not len(rows):
            break
        start, on = joints[rows], failed[rows]
        for foot in range(2):
            start[np.ix_(on[:, foot], LEGS[foot])] = joints[rows - shift][
                np.ix_(on[:, foot], LEGS[foot])
            ]
        again = solver.solve(start, targets[rows], on, on, lifting[rows])
        better = on & (again.residual < residual[rows])
        for foot in range(2):
            pick = better[:, foot]
            joints[np.ix_(rows[pick], LEGS[foot])] = again.joints[np.ix_(pick, LEGS[foot])]
            residual[rows[pick], foot] = again.residual[pick, foot]
    return LegSolution(joints, residual, solution.iterations)


def make_consistent(
    trajectory: Trajectory,
    robot: Robot,
    params: ConsistentParams,
    contact_params: ContactParams,
    solver: LegSolver | None = None,
) -> Consistent:
    """The trajectory with each foot held where it landed while in contact (module docstring);
    its contacts: the rule on its own soles; attrs: the raw one's, `consistent` = "post" and the
    largest residual (m)."""
    solver = solver or LegSolver(robot, params)
    dt = frame_period(trajectory)
    base, soles = world_soles(solver, trajectory)
    contacts = rollout_contacts(lowest_heights(soles), dt, contact_params)
    weights, held, middle, lift = post_holds(
        soles, contacts, blend_frames(params, dt), contact_params, dt, LIFT_SPEED
    )
    raw_joints = np.asarray(trajectory.joint_positions, float)
    lifting = weights[..., 1] < weights[..., 0]
    tolerance = float(params.tolerance)
    active = weights.max(axis=-1) > 0.0  # every held or blending foot brought to tolerance:
    # with 3 iterations alone a lifting foot stayed up to 0.17 m from its target and slid
    to_base = inverse(base)[:, None]

    def solved(rest: np.ndarray) -> LegSolution:
        """The legs solved towards the holds resting at `rest` (base frame targets)."""
        targets = to_base @ hold_targets(soles, held, weights, rest)
        solution = solver.solve(raw_joints, targets, active, active, lifting)
        return retry_from_neighbours(solver, solution, targets, active, lifting, tolerance)

    off = float(contact_params.off_height)
    rest = np.broadcast_to(np.eye(4), soles.shape).copy()  # flat on the floor
    solution = solved(lifting_rest(rest, soles, lift, off))
    held_frames = weights.min(axis=-1) >= 1.0  # on the floor or lifting at `lift`
    on_floor = held_frames & (lift <= 0.0)
    # a stance its leg cannot hold flat (an ankle at its limit under a tilted foot) rests at the
    # network's tilt of its middle frame instead, its lowest corner on the floor
    tilted = np.zeros(held_frames.shape, dtype=bool)
    for foot in range(held_frames.shape[1]):
        for a, b in true_runs(on_floor[:, foot]):
            if solution.residual[a:b, foot].max() > FLAT_MISS:
                tilted[:, foot] |= middle[:, foot] == middle[a, foot]
    if tilted.any():
        resting = resting_tilt(soles[middle.clip(0), np.arange(soles.shape[1])])
        rest[tilted] = resting[tilted]
        solution = solved(lifting_rest(rest, soles, lift, off))
    out = dataclasses.replace(
        trajectory,
        joint_positions=solution.joints,
        joint_velocities=corrected_velocities(
            trajectory.joint_velocities, solution.joints - raw_joints, dt
        ),
        contacts=None,
        attrs={
            **trajectory.attrs,
            "consistent": "post",
            "consistent_residual_max_m": float(np.where(held_frames, solution.residual, 0.0).max()),
        },
    )
    out.contacts = own_contacts(out, solver, contact_params)
    return Consistent(out, weights, solution.residual, contacts, lift)


class InLoopHold:
    """The hold inside the batched generator: one frame of B rollouts at a time, after the
    network's step and the contact rule, before the state is fed back."""

    def __init__(
        self,
        robot: Robot,
        rows: int,
        params: ConsistentParams,
        contact_params: ContactParams,
        dt: float,
    ):
        self.solver = LegSolver(robot, params)
        self.holder = SoleHolder(rows, params, contact_params, dt)
        self.dt = dt
        self.correction = np.zeros((rows, len(LEG_JOINTS)))  # q - q_network of the legs
        self.residual = np.zeros(rows)  # m, largest held-sole residual so far
        self.weights = np.zeros((rows, 2, 2))  # the last frame's hold weights

    def apply(
        self,
        position: np.ndarray,
        rotation: np.ndarray,
        joints: np.ndarray,
        joint_velocities: np.ndarray,
        contacts: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """(joints, joint velocities) of B rows with their held legs re-solved."""
        base = homogeneous(position, rotation)
        soles = base[:, None] @ self.solver.soles(joints)
        targets, weights = self.holder.step(soles, contacts)
        self.weights = weights
        held = weights.min(axis=-1) >= 1.0
        active = weights.max(axis=-1) > 0.0
        solution = self.solver.solve(
            joints,
            inverse(base)[:, None] @ targets,
            active,
            active,
            weights[..., 1] < weights[..., 0],
        )
        correction = (solution.joints - joints)[:, LEG_JOINTS]
        velocities = np.array(joint_velocities, dtype=float)
        velocities[:, LEG_JOINTS] += (correction - self.correction) / self.dt
        self.correction = correction
        self.residual = np.maximum(self.residual, np.where(held, solution.residual, 0.0).max(1))
        return solution.joints, velocities


def own_contacts(
    trajectory: Trajectory, solver: LegSolver, contact_params: ContactParams
) -> np.ndarray:
    """(T, 2) the rule's contacts on a rollout's own soles (both down at the start)."""
    _, soles = world_soles(solver, trajectory)
    return rollout_contacts(lowest_heights(soles), frame_period(trajectory), contact_params)
