"""What the sliding metrics (pimann.evaluate.metrics) are built from: the feet's motion.

One module for one concept, kept apart from the metrics, their aggregation and the contact
rule so that metrics.py stays readable:

- Sole velocities as the authors' evaluation takes them (paper Sec. V): the joints move at the
  given joint velocities and the base moves so that the foot whose sole corner is lowest stays
  still, J_s,B v_B + J_s,s sdot = 0 for that foot s. Its twist is then zero, and the other
  sole's is its motion relative to the support sole: what the joint velocities alone make the
  feet do. The trajectory's own base motion (odometry, IK) does not enter (the metrics'
  velocity level).
- Sole velocities as the authors' rollout computes them, step by step (BLF
  VelMANNAutoregressive::advance): the support foot, its Jacobian and the base that holds it
  still are taken at the previous state q_{i-1} with the new joint velocities sdot_i (the base
  twist in the mixed representation: the base origin's velocity and the angular velocity in
  world axes); that twist and sdot_i are then set at the new state q_i and both soles'
  velocities read there. The support sole keeps a residual (the one-step lag), the other one
  moves relative to it. The support foot is the one with the lowest of the authors' sole
  corners (`AUTHORS_SOLE_CORNERS`, their config_mann.toml), the left on a tie.
- The velocity of each sole's lowest corner (the contact point): a sole pivoting on that
  corner has none, where its origin moves.
- Velocities of a configuration trajectory by finite differences on the configuration manifold:
  what a trajectory's poses alone say about how it moves (the metrics' position level, the data
  report's sole velocities).
- The foot-skating ratio of motion-generation work, beside the paper's sliding RMSE. Defined at
  20 fps: the trajectory's sole positions and lowest-corner heights are linearly interpolated
  to `skating_rate_hz`; a pair of adjacent frames skates when some foot is below
  `skating_height` in both and its sole origin moves more than `skating_speed_per_frame`
  horizontally between them; the ratio is the fraction of pairs that skate.
- Where in a stance the support feet slide: just after touchdown, mid-stance or before
  lift-off. A stance is a run of one foot's contact frames. Its first frames (`EDGE_S`) after a
  touchdown the trajectory shows are the touchdown window, its last ones before a lift-off it
  shows the lift-off window (lift-off wins where a short stance has both); the rest is
  mid-stance. A stance already under way at the first frame has no touchdown window, one still
  on at the last frame no lift-off window. The share of a sliding sum in each window tells a
  foot that drags before it lifts (lift-off share well above the window's share of the contact
  frames) from one that creeps while it bears weight (mid-stance).
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from pimann.core.contacts import FEET, FootKinematics, lowest_corner_heights
from pimann.core.params import EvaluateParams
from pimann.core.robot import Robot, corner_offsets
from pimann.core.rotations import quaternion_xyzw_matrices

# the sole corners of the authors' evaluation (BLF config_mann.toml), in the sole frame: its
# support-foot pick; the retargeting's larger soles are pimann.core.robot.SOLE_CORNERS
AUTHORS_SOLE_CORNERS = np.array([[x, y, 0.0] for x in (0.08, -0.08) for y in (0.03, -0.03)])
PHASES = ("touchdown", "mid", "liftoff")
EDGE_S = 0.1  # s: the touchdown and lift-off windows (5 frames at 50 Hz)
SHARE_METRICS = ("linear", "linear_position")  # the pimann.evaluate.metrics.SLIDING names split
_NONE, _TOUCHDOWN, _MID, _LIFTOFF = range(4)


def stance_phases(contacts: np.ndarray, edge_frames: int) -> np.ndarray:
    """(T, F) labels of (T, F) contacts: 0 no contact, 1 touchdown, 2 mid-stance, 3 lift-off."""
    contacts = np.asarray(contacts, dtype=bool)
    frames = len(contacts)
    index = np.broadcast_to(np.arange(frames)[:, None], contacts.shape)
    # the last frame without contact at or before each frame, the first one at or after it
    last_free = np.maximum.accumulate(np.where(contacts, -1, index), axis=0)
    next_free = np.minimum.accumulate(np.where(contacts, frames, index)[::-1], axis=0)[::-1]
    touchdown = contacts & (last_free >= 0) & (index - last_free <= edge_frames)
    liftoff = contacts & (next_free < frames) & (next_free - index <= edge_frames)
    labels = np.where(contacts, _MID, _NONE)
    labels[touchdown] = _TOUCHDOWN
    labels[liftoff] = _LIFTOFF
    return labels


def _counted_labels(contacts: np.ndarray, rate_hz: float, counted: np.ndarray | None) -> np.ndarray:
    """`stance_phases` at `EDGE_S`, frames outside `counted` relabelled as not in contact."""
    labels = stance_phases(contacts, max(1, round(EDGE_S * rate_hz)))
    if counted is None:
        return labels
    return np.where(np.asarray(counted, dtype=bool)[:, None], labels, _NONE)


def _shares(per_frame: np.ndarray, labels: np.ndarray) -> dict[str, float | None]:
    values = np.where(labels != _NONE, np.asarray(per_frame, dtype=float), 0.0)
    total, in_contact = values.sum(), int((labels != _NONE).sum())
    shares: dict[str, float | None] = {}
    for label, phase in enumerate(PHASES, start=_TOUCHDOWN):
        mask = labels == label
        shares[phase] = float(values[mask].sum() / total) if total > 0 else None
        shares[f"{phase}_frames"] = float(mask.sum() / in_contact) if in_contact else None
    return shares


def phase_shares(
    per_frame: np.ndarray,
    contacts: np.ndarray,
    rate_hz: float,
    counted: np.ndarray | None = None,
) -> dict[str, float | None]:
    """{phase: share of the contact-masked sum of `per_frame` (T, F)} (None: nothing slides),
    and {phase}_frames: the phase's share of the contact frames (what an even spread gives).

    `counted` (T,) bool: only these frames are summed (the phases still come from the whole
    trajectory, so a class boundary is no touchdown).
    """
    return _shares(per_frame, _counted_labels(contacts, rate_hz, counted))


def phase_share_metrics(
    per_frame: dict[str, np.ndarray],
    contacts: np.ndarray,
    rate_hz: float,
    counted: np.ndarray | None = None,
) -> dict[str, float | None]:
    """`support_rmse_<name>_<phase>_share` of each sliding metric's (T, F) per-frame RMS, and
    `contact_<phase>_frames_share`, as pimann.evaluate.metrics and pimann.evaluate.data_reference
    report them:
    the phases labelled once for all the metrics."""
    labels = _counted_labels(contacts, rate_hz, counted)
    out: dict[str, float | None] = {}
    for name, values in per_frame.items():
        shares = _shares(values, labels)
        out.update({f"support_rmse_{name}_{phase}_share": shares[phase] for phase in PHASES})
    out.update({f"contact_{phase}_frames_share": shares[f"{phase}_frames"] for phase in PHASES})
    return out


def sole_jacobians(robot: Robot, configurations: np.ndarray) -> np.ndarray:
    """(T, 2, 6, nv) LOCAL_WORLD_ALIGNED sole Jacobians, columns as `FEET`; one pinocchio
    Jacobian pass per frame, shared by both velocity levels."""
    model = robot.model
    data = model.createData()  # private: the cached Robot's data may be in use elsewhere
    frame_ids = [robot.frame_id(name) for name in FEET]
    jacobians = np.empty((len(configurations), 2, 6, model.nv))
    for k, q in enumerate(configurations):
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        for f, frame_id in enumerate(frame_ids):
            jacobians[k, f] = pin.getFrameJacobian(model, data, frame_id, pin.LOCAL_WORLD_ALIGNED)
    return jacobians


def support_foot_velocities(
    robot: Robot, jacobians: np.ndarray, joint_velocities: np.ndarray, heights: np.ndarray
) -> np.ndarray:
    """(T, 2, 6) sole twists [linear, angular], LOCAL_WORLD_ALIGNED, columns as `FEET`.

    jacobians (T, 2, 6, nv) from `sole_jacobians`; joint_velocities (T, 26), the study's joint
    order; heights (T, 2): each sole's lowest corner (pimann.core.contacts.FootKinematics
    .heights), the lower one is the support foot (the left on a tie).
    """
    base = robot.velocity_order[:6]  # the free flyer's columns
    support = np.argmin(np.asarray(heights), axis=1)
    n = len(jacobians)
    joint_part = np.einsum("tfij,tj->tfi", jacobians[..., robot.v_index], joint_velocities)
    held = jacobians[np.arange(n), support][..., base]  # (T, 6, 6) the support sole's base block
    base_twist = -np.linalg.solve(held, joint_part[np.arange(n), support][..., None])[..., 0]
    return np.einsum("tfij,tj->tfi", jacobians[..., base], base_twist) + joint_part


def authors_sole_velocities(
    robot: Robot,
    configurations: np.ndarray,
    jacobians: np.ndarray,
    joint_velocities: np.ndarray,
    feet: FootKinematics,
) -> np.ndarray:
    """(T, 2, 6) sole twists [linear, angular] LOCAL_WORLD_ALIGNED at q_i, as the authors' step
    from q_{i-1} to q_i makes them (module docstring); frame 0, which has no previous state, NaN.

    configurations (T, nq); jacobians (T, 2, 6, nv) from `sole_jacobians`; joint_velocities
    (T, 26) the study's order, row i the step's sdot_i; feet: the soles' placements (the
    support pick's corners hang from them).
    """
    base, joints = robot.velocity_order[:6], robot.v_index
    heights = lowest_corner_heights(feet.positions, feet.rotations, AUTHORS_SOLE_CORNERS)
    n = len(configurations)
    previous, current = np.arange(n - 1), np.arange(1, n)
    support = (heights[:-1, 1] < heights[:-1, 0]).astype(int)  # the left on a tie
    held = jacobians[previous, support]  # (T-1, 6, nv) at q_{i-1}
    base_rotation = quaternion_xyzw_matrices(configurations[:, 3:7])  # (T, 3, 3)
    # mixed base twist [p_dot; omega] in world axes -> the free flyer's body twist: R^T each part
    to_body = np.zeros((n, 6, 6))
    to_body[:, :3, :3] = to_body[:, 3:, 3:] = np.swapaxes(base_rotation, 1, 2)
    sdot = np.asarray(joint_velocities, dtype=float)[1:]
    mixed_block = held[..., base] @ to_body[:-1]
    joint_twist = np.einsum("tij,tj->ti", held[..., joints], sdot)
    mixed_twist = -np.linalg.solve(mixed_block, joint_twist[..., None])[..., 0]
    body_twist = np.einsum("tij,tj->ti", to_body[1:], mixed_twist)  # set at q_i
    new = jacobians[current]  # (T-1, 2, 6, nv)
    out = np.full((n, 2, 6), np.nan)
    out[1:] = np.einsum("tfij,tj->tfi", new[..., base], body_twist) + np.einsum(
        "tfij,tj->tfi", new[..., joints], sdot
    )
    return out


def contact_point_velocities(
    velocities: np.ndarray, rotations: np.ndarray, corners: np.ndarray
) -> np.ndarray:
    """(T, 2, 6) the twists of (T, 2, 6) LOCAL_WORLD_ALIGNED sole twists moved to each sole's
    lowest corner (its linear part v + omega x R c, the angular part unchanged)."""
    offsets = corner_offsets(rotations, corners)  # (T, 2, C, 3)
    lowest = np.take_along_axis(
        offsets, np.argmin(offsets[..., 2], axis=-1)[..., None, None], axis=-2
    )[..., 0, :]
    out = velocities.copy()
    out[..., :3] += np.cross(velocities[..., 3:], lowest)
    return out


def manifold_velocities(model: pin.Model, configurations: np.ndarray, time: np.ndarray):
    """(T, nv) velocities by finite differences of q on the manifold (base twist in body frame).

    Second order everywhere (also for uneven time steps): interior frames combine the tangent
    vectors at q_k towards q_{k-1} and q_{k+1}; the ends use the three-point one-sided formula
    (tangents at the end frame towards its two neighbours). Two frames: a plain difference.
    """
    n = len(configurations)

    def towards(k: int, j: int) -> np.ndarray:
        return pin.difference(model, configurations[k], configurations[j])

    forward = np.array([towards(k, k + 1) for k in range(n - 1)])
    backward = np.array([towards(k, k - 1) for k in range(1, n)])
    steps = np.diff(time)
    velocities = np.empty((n, model.nv))
    if n == 2:
        velocities[0] = forward[0] / steps[0]
        velocities[1] = -backward[0] / steps[0]
        return velocities
    h_b, h_f = steps[:-1, None], steps[1:, None]
    ahead = forward[1:] / h_f  # slope towards k+1, at frames 1..n-2
    behind = -backward[:-1] / h_b  # slope from k-1
    velocities[1:-1] = (h_b * ahead + h_f * behind) / (h_b + h_f)

    def one_sided(near: np.ndarray, far: np.ndarray, a: float, b: float) -> np.ndarray:
        # slope at 0 of the parabola through (0, 0), (a, near), (b, far)
        return (near * b * b - far * a * a) / (a * b * (b - a))

    first, last = steps[0], steps[-1]
    velocities[0] = one_sided(forward[0], towards(0, 2), first, first + steps[1])
    velocities[-1] = -one_sided(backward[-1], towards(n - 1, n - 3), last, last + steps[-2])
    return velocities


def skating_ratio(
    time: np.ndarray, positions: np.ndarray, heights: np.ndarray, params: EvaluateParams
) -> float:
    """Fraction of adjacent frame pairs (at `skating_rate_hz`) in which some foot skates.

    positions (T, 2, 3) sole origins, heights (T, 2) lowest-corner heights.
    """
    grid = np.arange(time[0], time[-1] + 1e-9, 1.0 / params.skating_rate_hz)
    if len(grid) < 2:
        return math.nan
    feet = range(positions.shape[1])
    xy = np.stack(
        [np.stack([np.interp(grid, time, positions[:, f, a]) for a in (0, 1)], -1) for f in feet],
        axis=1,
    )  # (G, 2, 2)
    low = np.stack([np.interp(grid, time, heights[:, f]) for f in feet], 1) < params.skating_height
    moved = np.linalg.norm(np.diff(xy, axis=0), axis=-1) > params.skating_speed_per_frame
    skates = low[:-1] & low[1:] & moved
    return float(np.mean(skates.any(axis=1)))
