"""Where the robot's feet go: the person's foot contacts and the robot's sole targets.

A robot copying a person's leg angles slides its feet: its legs are shorter, its soles are
rigid plates, and a flat-foot target glides along the floor at every touchdown
(docs/retargeting.md).
So the feet are planned first and the IK follows the plan (ik.py):

1. Contacts from the person's heel and toe (`HumanMotion.contact_points`): a point is down
   while it is low and slow, with hysteresis (it must rise higher, move faster or travel
   farther from where it came down to come up again); a foot is down while either point
   is. Short flickers are removed, double support is kept. A foot the person pivots on
   steps instead (a robot sole cannot turn on the floor without sliding).
2. Each contact run is one footstep: the robot's sole lies flat on the floor at one place
   and heading for the whole run: where the robot's own sole stands, on median, when its
   joints copy the person's (a first IK pass with the pelvis held; its legs are shorter, so
   the person's footprints scaled would not match its leg angles).
3. Between two footsteps the sole first rises vertically above the evaluation's contact
   height, travels on a minimum-jerk path at least `swing_clearance` high in mid-swing,
   and sinks vertically onto the next footstep: no sole point moves horizontally while it
   is at floor height (nor while a contact rule on its height would call it down).
   Off the floor the IK moves the sole's target, horizontally and in orientation, toward
   where the person's leg puts it relative to the robot's base (`SolePlan.leg_following`,
   fully at mid-swing): the robot's base is not where the person's scaled pelvis was.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from pimann.core.contacts import true_runs
from pimann.core.params import RetargetParams
from pimann.core.robot import SEGMENTS
from pimann.core.rotations import yaw_of
from pimann.mocap.human_motion import HumanMotion

# share of a swing at each end with no horizontal motion. Short, so the sole clears the
# evaluation's 2 cm contact height soon after lift-off and late before touchdown: with 0.2 and
# lift_height 0.025, ten Bandai walks had 0.32 double support under that rule (0.10 by their
# flags); with 0.12 and 0.04, 0.18, while their sliding under the rule rose from 13.5 to 15.9
# linear per 10 s (the vertical rise counts while below 2 cm)
SWING_VERTICAL = 0.12
DEFAULT_SWING_S = 0.4  # s, a swing's length when a clip has no whole swing to measure


def hysteresis(
    on: np.ndarray,
    off: np.ndarray,
    start: bool,
    positions: np.ndarray | None = None,
    max_travel: float = np.inf,
) -> np.ndarray:
    """(T,) bool: switches on where `on` holds, off where `off` holds, else keeps its state.
    With `positions` (T, 2), a point that is on also switches off once it has travelled
    more than `max_travel` from where it came down: a planted point does not wander (a
    shuffling foot that stays low and slow still steps)."""
    state, out = start, np.empty(len(on), bool)
    anchor = None if positions is None else positions[0]
    for t in range(len(on)):
        was = state
        state = (state and not off[t]) or bool(on[t])
        if positions is not None:
            if state and was and np.linalg.norm(positions[t] - anchor) > max_travel:
                state = False
            if state and not was:
                anchor = positions[t]
        out[t] = state
    return out


def debounce(flags: np.ndarray, min_on: int, min_off: int) -> np.ndarray:
    """Gaps shorter than `min_off` frames filled, then runs shorter than `min_on` dropped;
    runs touching the clip's ends are kept (they may be longer outside the clip)."""
    flags = flags.copy()
    for start, stop in true_runs(~flags):
        if stop - start < min_off and start > 0 and stop < len(flags):
            flags[start:stop] = True
    for start, stop in true_runs(flags):
        if stop - start < min_on and start > 0 and stop < len(flags):
            flags[start:stop] = False
    return flags


def human_contacts(motion: HumanMotion, params: RetargetParams) -> np.ndarray:
    """(T, 2) bool, left and right: the person's foot is on the floor (heel or toe down)."""
    points = motion.contact_points()  # (T, 2, P, 3)
    # each kind of point (heel, toe) has its own floor height: its low percentile in the take
    floor = np.percentile(points[..., 2], 2.0, axis=(0, 1))
    height = points[..., 2] - floor
    if motion.n_frames < 2:
        return (height < params.contact_height).any(axis=-1)
    speed = np.linalg.norm(np.gradient(points[..., :2], motion.time, axis=0), axis=-1)
    on = (height < params.contact_height) & (speed < params.contact_speed)
    off = (height > params.release_height) | (speed > params.release_speed)
    rate = motion.rate_hz
    min_on = max(1, round(params.min_contact_s * rate))
    min_off = max(1, round(params.min_swing_s * rate))
    contacts = np.empty((motion.n_frames, 2), bool)
    for side in range(2):
        down = np.stack(
            [
                hysteresis(
                    on[:, side, p],
                    off[:, side, p],
                    bool(on[0, side, p]),
                    points[:, side, p, :2],
                    params.release_travel,
                )
                for p in range(points.shape[2])
            ],
            axis=-1,
        ).any(axis=-1)
        contacts[:, side] = debounce(down, min_on, min_off)
    feet = [SEGMENTS.index("LeftFoot"), SEGMENTS.index("RightFoot")]
    headings = np.unwrap(yaw_of(motion.orientations[:, feet]), axis=0)
    step = max(1, round(params.pivot_step_s * rate))
    return bridge_flights(step_pivots(contacts, headings, params.release_turn, step))


def step_pivots(
    contacts: np.ndarray, headings: np.ndarray, max_turn: float, step: int
) -> np.ndarray:
    """(T, 2) contacts where a planted foot that turns (the person pivots on it) steps: once
    its heading (`headings` (T, 2), unwrapped) is more than `max_turn` from where it came
    down, it is lifted for `step` frames, if the other foot is down all that time (else
    when it is), and comes down again at its new heading: one footstep keeps one heading."""
    contacts = contacts.copy()
    anchors: list[float | None] = [None, None]
    for t in range(len(contacts)):
        for side in range(2):
            if not contacts[t, side]:
                anchors[side] = None
            elif anchors[side] is None:
                anchors[side] = headings[t, side]
            elif abs(headings[t, side] - anchors[side]) > max_turn:
                lifted = slice(t, t + step)
                if t + step < len(contacts) and contacts[lifted, 1 - side].all():
                    contacts[lifted, side] = False
                    anchors[side] = None
    return contacts


def bridge_flights(contacts: np.ndarray) -> np.ndarray:
    """(T, 2) contacts with no flight: where the person has no foot down (a jog's flight
    phase), the foot that left the floor last stays down until the other one lands. The
    robot walks; without a foot to stand on, its IK let the base sink 30 cm and a sole dip
    14 cm under the floor in the motion-matching take's 0.15 s flight at 72.6 s."""
    contacts = contacts.copy()
    for start, stop in true_runs(~contacts.any(axis=1)):
        if start > 0:  # the foot that was down last (the lower index when both left at once)
            side = int(np.argmax(contacts[start - 1]))
        elif stop < len(contacts):  # a clip opening in flight: the foot that lands first
            side = int(np.argmax(contacts[stop]))
        else:  # never a foot down: nothing to stand on, the plan follows the free soles
            continue
        contacts[start:stop, side] = True
    return contacts


def min_jerk(s: np.ndarray) -> np.ndarray:
    """Minimum-jerk progress 0 -> 1 with zero velocity and acceleration at both ends."""
    s = np.clip(s, 0.0, 1.0)
    return s**3 * (10.0 - 15.0 * s + 6.0 * s**2)


@dataclasses.dataclass
class SolePlan:
    """What the second IK pass asks of each sole, per frame and foot (left, right)."""

    positions: np.ndarray  # (T, 2, 3) m
    headings: np.ndarray  # (T, 2) rad, the soles lie flat
    weights: np.ndarray  # (T, 2) IK cost of the sole pose
    # (T, 2) in [0, 1]: how far a swinging sole's target (horizontal place and orientation)
    # moves from the plan to where the person's leg puts it relative to the robot's base
    # (0: planted or at a footstep's vertical lift or descent; 1: mid-swing)
    leg_following: np.ndarray


def plan_soles(
    soles: np.ndarray,
    sole_yaw: np.ndarray,
    contacts: np.ndarray,
    time: np.ndarray,
    params: RetargetParams,
) -> SolePlan:
    """The soles' plan from where the robot's soles go when its joints copy the person's
    (`soles` (T, 2, 3) and `sole_yaw` (T, 2), the first IK pass): each contact run becomes
    one footstep at the run's median place and heading, on the floor (the soles' own low
    percentile); swings between footsteps as in `swing_path`."""
    floor = np.percentile(soles[..., 2], 2.0)
    free = soles - [0.0, 0.0, floor]
    free[..., 2] = np.maximum(free[..., 2], 0.0)
    yaw = np.unwrap(sole_yaw, axis=0)
    plan = SolePlan(
        free.copy(), yaw.copy(), np.full(yaw.shape, params.stance_weight), np.zeros(yaw.shape)
    )
    for side in range(2):
        steps = []
        for start, stop in true_runs(contacts[:, side]):
            place = np.median(free[start:stop, side, :2], axis=0)
            heading = float(np.median(yaw[start:stop, side]))
            steps.append((start, stop, place, heading))
            plan.positions[start:stop, side] = [*place, 0.0]
            plan.headings[start:stop, side] = heading
        for before, after in zip(steps, steps[1:], strict=False):
            swing = slice(before[1], after[0])
            s = (time[swing] - time[before[1] - 1]) / (time[after[0]] - time[before[1] - 1])
            # the free sole's path from its last stance frame to its first one
            around = slice(before[1] - 1, after[0] + 1)
            path, heading, weight, following = swing_path(
                s, before[2:], after[2:], free[around, side], yaw[around, side], params
            )
            plan.positions[swing, side], plan.headings[swing, side] = path, heading
            plan.weights[swing, side], plan.leg_following[swing, side] = weight, following
        _open_ends(plan, side, steps, free[:, side], yaw[:, side], time, params)
    return plan


def swing_path(
    s: np.ndarray,
    start: tuple[np.ndarray, float],
    end: tuple[np.ndarray, float],
    free: np.ndarray,
    free_yaw: np.ndarray,
    params: RetargetParams,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Sole positions (n, 3), headings (n,), IK weights (n,) and leg following (n,), see
    SolePlan, of one swing at swing shares s in (0, 1) from footstep `start` (place,
    heading) to `end`. Over the first and last SWING_VERTICAL of the swing the sole only
    rises to (sinks from) `lift_height`, above the contact threshold of the evaluation. In
    between it travels a minimum-jerk path between the footsteps plus the free sole's
    departure from that path at the same time (`free` (n+2, 3), `free_yaw` (n+2,), from its
    last stance frame to its next first one), faded in and out, at least `swing_clearance`
    high at mid-swing or as high as the free sole goes: close to what the copied leg does,
    so the leg keeps its angles."""
    edge = np.minimum(s, 1.0 - s)  # share of the swing to the nearer footstep
    sigma = np.clip((s - SWING_VERTICAL) / (1.0 - 2.0 * SWING_VERTICAL), 0.0, 1.0)
    progress = min_jerk(sigma)
    fade = np.sin(np.pi * sigma) ** 2  # the free sole's share: 0 at the ends, 1 mid-swing
    # the free sole at the same point of its own swing, and its departure from the straight
    # (minimum-jerk) path between its ends
    own = np.linspace(0.0, 1.0, len(free))
    free_at = np.column_stack([np.interp(s, own, free[:, k]) for k in range(3)])
    chord = free[0] + progress[:, None] * (free[-1] - free[0])
    departure = (free_at - chord) * fade[:, None]
    place = start[0] + progress[:, None] * (end[0] - start[0]) + departure[:, :2]
    yaw_departure = np.interp(s, own, free_yaw) - (
        free_yaw[0] + progress * (free_yaw[-1] - free_yaw[0])
    )
    heading = start[1] + progress * (end[1] - start[1]) + yaw_departure * fade
    up = params.lift_height * min_jerk(edge / SWING_VERTICAL)
    high = np.maximum(params.swing_clearance * np.sin(np.pi * s), free_at[:, 2])
    height = up + np.maximum(high - params.lift_height, 0.0) * min_jerk(
        (edge - SWING_VERTICAL) / SWING_VERTICAL
    )
    weight = np.where(edge < SWING_VERTICAL, params.stance_weight, params.swing_weight)
    following = np.where(edge < SWING_VERTICAL, 0.0, fade)
    return np.column_stack([place, height]), heading, weight, following


def _open_ends(
    plan: SolePlan,
    side: int,
    steps: list[tuple[int, int, np.ndarray, float]],
    free: np.ndarray,
    free_yaw: np.ndarray,
    time: np.ndarray,
    params: RetargetParams,
) -> None:
    """In place: a swing cut by the clip's start or end follows the free leg's sole, shifted
    to meet the footstep it touches, and leaves (reaches) that footstep vertically as a
    whole swing would; a foot never down follows the free sole."""
    if not steps:
        plan.weights[:, side] = params.swing_weight
        plan.leg_following[:, side] = 1.0
        return
    # the clip's median swing in seconds (frames times the frame period)
    swings = [b[0] - a[1] for a, b in zip(steps, steps[1:], strict=False)]
    swing_s = np.median(swings) * np.median(np.diff(time)) if swings else DEFAULT_SWING_S
    vertical = SWING_VERTICAL * swing_s
    first, last = steps[0], steps[-1]
    if first[0] > 0:
        head = slice(0, first[0] + 1)
        _open_swing(plan, side, head, first[0], first[2:], free, free_yaw, time, vertical, params)
    if last[1] < len(free):
        tail = slice(last[1] - 1, None)
        _open_swing(plan, side, tail, last[1] - 1, last[2:], free, free_yaw, time, vertical, params)


def _open_swing(
    plan: SolePlan,
    side: int,
    frames: slice,
    anchor: int,
    footstep: tuple[np.ndarray, float],
    free: np.ndarray,
    free_yaw: np.ndarray,
    time: np.ndarray,
    vertical: float,
    params: RetargetParams,
) -> None:
    """The frames of one open swing, `anchor` being its frame on the footstep."""
    away = np.abs(time[frames] - time[anchor])  # s from the footstep
    up = params.lift_height * min_jerk(away / vertical)
    ramp = min_jerk((away - vertical) / vertical)
    shift = free[frames] - free[anchor]
    plan.positions[frames, side, :2] = footstep[0] + ramp[:, None] * shift[:, :2]
    plan.positions[frames, side, 2] = up + ramp * np.maximum(
        free[frames, 2] - params.lift_height, 0
    )
    plan.headings[frames, side] = footstep[1] + ramp * (free_yaw[frames] - free_yaw[anchor])
    plan.weights[frames, side] = np.where(
        away < vertical, params.stance_weight, params.swing_weight
    )
    plan.leg_following[frames, side] = ramp
    plan.positions[anchor, side] = [*footstep[0], 0.0]
    plan.headings[anchor, side] = footstep[1]
    plan.weights[anchor, side] = params.stance_weight
    plan.leg_following[anchor, side] = 0.0
