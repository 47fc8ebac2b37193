"""Foot contact on generated trajectories: a Schmitt trigger on each sole's lowest corner.

Generated trajectories carry no contact forces, so contact is inferred from geometry:
the lowest of the four sole corners (`SOLE_CORNERS`, in the sole frame) is compared with an
on and an off height, and a switch happens only once its condition has held for
`switch_time` (params.yaml `contacts`), so a foot grazing the threshold does not chatter. The same
`SchmittTrigger` serves the autoregressive generator (one step at a time) and whole
trajectories (`contacts_from_heights`), so both always agree.

Timing follows the authors' trigger (bipedal-locomotion-framework `Math::SchmittTrigger`): the
switch happens at the first sample at which the condition has held continuously since a sample
at least `switch_time` earlier; at 50 Hz and 0.04 s that is the third consecutive sample
satisfying it (samples k, k+1, k+2 -> switch at k+2). Unlike that code, the timer restarts
whenever the condition breaks.

Here too the runs of True in a flag sequence (`true_runs`: contacts, swings, double support,
standing pauses), which the retargeting, the clip cutter and the simulation's footstep plan
read, and the touchdowns of contact flags.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pinocchio as pin

from pimann.core.errors import PimannError, require_finite
from pimann.core.params import ContactParams
from pimann.core.robot import LEFT_SOLE, RIGHT_SOLE, SOLE_CORNERS, Robot, corner_offsets
from pimann.core.trajectory import Trajectory

FEET = (LEFT_SOLE, RIGHT_SOLE)  # the column order of every (T, 2, ...) foot array


class SchmittTrigger:
    """Contact state from a height signal, with hysteresis and a switching delay.

    Works on a scalar height or on an array of heights (one independent trigger per element,
    e.g. both feet at once). `initial=None` takes the state from the first height (contact when
    at or below `on_height`); the generator starts from standing and passes `initial=True`.
    """

    def __init__(
        self,
        on_height: float,
        off_height: float,
        switch_time: float,
        dt: float,
        initial: bool | np.ndarray | None = None,
    ):
        if not off_height >= on_height:
            raise PimannError(
                None, f"contact off height {off_height} must not be below on height {on_height}"
            )
        if not (np.isfinite(dt) and dt > 0):
            raise PimannError(None, f"frame period must be positive, not {dt}")
        if not switch_time >= 0:
            raise PimannError(None, f"contact switch time must be >= 0, not {switch_time}")
        self.on_height = float(on_height)
        self.off_height = float(off_height)
        # samples the condition must hold beyond the first one (0.04 s at 50 Hz -> 2)
        self.delay_samples = int(np.ceil(switch_time / dt - 1e-9))
        self._state = None if initial is None else np.array(initial, dtype=bool)
        self._held = None if initial is None else np.zeros(np.shape(initial), dtype=int)
        self._started = False

    @classmethod
    def from_params(
        cls, params: ContactParams, dt: float, initial: bool | np.ndarray | None = None
    ) -> SchmittTrigger:
        return cls(params.on_height, params.off_height, params.switch_time, dt, initial)

    @property
    def state(self) -> bool | np.ndarray | None:
        if self._state is None:
            return None
        return bool(self._state) if self._state.ndim == 0 else self._state.copy()

    def update(self, height: float | np.ndarray) -> bool | np.ndarray:
        """Feed one sample's height(s) (m); return the contact state(s) after it."""
        height = np.asarray(height, dtype=float)
        started, self._started = self._started, True
        if self._state is None:
            self._state = height <= self.on_height
            self._held = np.zeros(height.shape, dtype=int)
            return self.state
        if self._state.ndim == 0 and height.ndim > 0 and not started:
            # a scalar initial state applies to every element of the first array of heights
            self._state = np.broadcast_to(self._state, height.shape).copy()
            self._held = np.zeros(height.shape, dtype=int)
        if height.shape != self._state.shape:
            raise PimannError(None, f"height shape {height.shape} != trigger {self._state.shape}")
        # the condition that would flip the current state
        flip = np.where(self._state, height > self.off_height, height <= self.on_height)
        self._held = np.where(flip, self._held + 1, 0)
        switch = self._held > self.delay_samples
        self._state = self._state ^ switch
        self._held[switch] = 0
        return self.state


def contacts_from_heights(
    heights: np.ndarray,
    dt: float,
    params: ContactParams,
    initial: bool | np.ndarray | None = None,
) -> np.ndarray:
    """Contact states (T, ...) bool from lowest-corner heights (T, ...), sample by sample."""
    heights = np.asarray(heights, dtype=float)
    require_finite("<heights>", "foot heights", heights)
    trigger = SchmittTrigger.from_params(params, dt, initial)
    out = np.empty(heights.shape, dtype=bool)
    for k, height in enumerate(heights):
        out[k] = trigger.update(height)
    return out


@dataclasses.dataclass
class FootKinematics:
    """Both soles over a trajectory: columns (left, right) as in `FEET`."""

    positions: np.ndarray  # (T, 2, 3) sole origins, world frame
    rotations: np.ndarray  # (T, 2, 3, 3) sole orientations, world frame
    velocities: np.ndarray | None = None  # (T, 2, 6) [linear, angular], LOCAL_WORLD_ALIGNED

    @property
    def heights(self) -> np.ndarray:
        """(T, 2) height of each sole's lowest corner."""
        return lowest_corner_heights(self.positions, self.rotations)

    @property
    def pitches(self) -> np.ndarray:
        """(T, 2) sole pitch (rad; Euler roll-pitch-yaw, R = Rz Ry Rx)."""
        return np.arcsin(np.clip(-self.rotations[..., 2, 0], -1.0, 1.0))


def lowest_corner_heights(
    positions: np.ndarray, rotations: np.ndarray, corners: np.ndarray = SOLE_CORNERS
) -> np.ndarray:
    """Height of the lowest corner: min over corners c of z(p + R c), vectorised over frames."""
    return positions[..., 2] + corner_offsets(rotations, corners)[..., 2].min(axis=-1)


def trajectory_configurations(robot: Robot, trajectory: Trajectory) -> np.ndarray:
    """(T, nq) pinocchio configurations of a trajectory (quaternions normalised)."""
    quaternions = np.asarray(trajectory.base_quaternion_xyzw, dtype=float)
    norms = np.linalg.norm(quaternions, axis=1, keepdims=True)
    if np.any(norms < 1e-9):
        frame = int(np.flatnonzero(norms[:, 0] < 1e-9)[0])
        raise PimannError(trajectory.source, "base quaternion is zero", frame=frame)
    q = np.zeros((len(trajectory), robot.model.nq))
    q[:, :3] = trajectory.base_position
    q[:, 3:7] = quaternions / norms
    q[:, robot.q_index] = trajectory.joint_positions
    return q


def foot_kinematics(
    robot: Robot,
    configurations: np.ndarray,
    velocities: np.ndarray | None = None,
    reference: pin.ReferenceFrame = pin.LOCAL_WORLD_ALIGNED,
) -> FootKinematics:
    """Sole placements (and, given v (T, nv), sole velocities in `reference`) per frame.

    LOCAL_WORLD_ALIGNED: the sole origin's velocity in world axes; WORLD: the inertial-fixed
    (spatial) velocity the authors' code used, whose linear part is that of the point at the
    world origin.

    One pinocchio forward pass per frame, updating only the two sole frames (~3 us a frame).
    """
    model = robot.model
    data = model.createData()  # private: the cached Robot's data may be in use elsewhere
    frame_ids = [robot.frame_id(name) for name in FEET]
    n = len(configurations)
    positions = np.empty((n, 2, 3))
    rotations = np.empty((n, 2, 3, 3))
    out_velocities = None if velocities is None else np.empty((n, 2, 6))
    for k, q in enumerate(configurations):
        if velocities is None:
            pin.forwardKinematics(model, data, q)
        else:
            pin.forwardKinematics(model, data, q, velocities[k])
        for f, frame_id in enumerate(frame_ids):
            placement = pin.updateFramePlacement(model, data, frame_id)
            positions[k, f] = placement.translation
            rotations[k, f] = placement.rotation
            if out_velocities is not None:
                out_velocities[k, f] = pin.getFrameVelocity(model, data, frame_id, reference).vector
    return FootKinematics(positions, rotations, out_velocities)


def frame_period(trajectory: Trajectory) -> float:
    """The trajectory's sampling period (s), from `rate_hz`, else from its time stamps."""
    rate = float(trajectory.rate_hz)
    if np.isfinite(rate) and rate > 0:
        return 1.0 / rate
    steps = np.diff(np.asarray(trajectory.time, dtype=float))
    if len(steps) == 0 or not np.all(steps > 0):
        raise PimannError(trajectory.source, "no usable rate_hz and time is not increasing")
    return float(np.median(steps))


def detect_contacts(robot: Robot, trajectory: Trajectory, params: ContactParams) -> np.ndarray:
    """(T, 2) bool contacts (left, right) of a trajectory, by the Schmitt trigger above."""
    kinematics = foot_kinematics(robot, trajectory_configurations(robot, trajectory))
    return contacts_from_heights(kinematics.heights, frame_period(trajectory), params)


def true_runs(flags: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) pairs of the maximal runs of True in a 1-D bool array, in order."""
    flags = np.asarray(flags, dtype=bool)
    if flags.ndim != 1:
        raise ValueError(f"flags must be 1-D, not of shape {flags.shape}")
    edges = np.flatnonzero(np.diff(np.concatenate([[0], flags.astype(np.int8), [0]])))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True))


def touchdowns(contacts: np.ndarray) -> np.ndarray:
    """(2,) touchdowns (a foot's contact switching on) per foot over (T, 2) contact flags."""
    contacts = np.asarray(contacts, dtype=bool)
    return np.sum(~contacts[:-1] & contacts[1:], axis=0)
