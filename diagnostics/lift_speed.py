"""How fast a sole rises in the frames the contact rule still counts at its lift-off: the data
against the rollouts (docs/consistent.md, section "What the trained models show").

    python -m diagnostics.lift_speed [--every 4] [ROLLOUT.h5 ...]

The rule (pimann.core.contacts, params `contacts`) switches a foot off only once its lowest
sole corner has stayed above the off height for `switch_time`: the last frames of every stance
(2 at 50 Hz) already rise, and the position-level sliding counts their motion. Per lift-off
(a contact run of at least `MIN_STANCE` frames that ends before the trajectory does), the sole
origin's vertical velocity (central differences, as the position level takes it) averaged over
those counted frames; quartiles and the 90th percentile over the lift-offs, for every
`--every`-th retargeted clip (params `features.input`; contacts by the rule, as the evaluate
stage measures the data) and, as one group, the rollout files given (the rule with both feet
down at the start, as the generator runs it). Outside the pipeline: nothing imports this module.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from pimann.core.contacts import (
    SchmittTrigger,
    contacts_from_heights,
    frame_period,
    true_runs,
)
from pimann.core.errors import PimannError
from pimann.core.params import ContactParams, load_params
from pimann.core.paths import REPO_ROOT
from pimann.core.robot import Robot, load_robot
from pimann.core.trajectory import Trajectory, iter_collection, read_trajectory
from pimann.generate.contact_consistent import (
    LegSolver,
    lowest_heights,
    rollout_contacts,
    world_soles,
)

MIN_STANCE = 5  # frames: shorter contact runs are grazes, not stances
PERCENTILES = (25, 50, 75, 90)


def counted_frames(params: ContactParams, dt: float) -> int:
    """Frames the rule still counts a foot down after its lowest corner has risen past the off
    height: the trigger's delay (at least the last contact frame)."""
    return max(1, SchmittTrigger.from_params(params, dt).delay_samples)


def lift_speeds(
    trajectory: Trajectory,
    solver: LegSolver,
    params: ContactParams,
    rollout: bool = False,
) -> np.ndarray:
    """(L,) m/s: each lift-off's mean vertical sole-origin velocity over its counted frames;
    the rule as the evaluate stage runs it on the data, or with `rollout` as the generator
    runs it (both feet down at the start, `rollout_contacts`)."""
    dt = frame_period(trajectory)
    _, soles = world_soles(solver, trajectory)
    heights = lowest_heights(soles)
    if rollout:
        contacts = rollout_contacts(heights, dt, params)
    else:
        contacts = contacts_from_heights(heights, dt, params)
    rising = np.gradient(soles[..., 2, 3], dt, axis=0)
    last = counted_frames(params, dt)
    speeds = [
        rising[stop - last : stop, foot].mean()
        for foot in range(contacts.shape[1])
        for start, stop in true_runs(contacts[:, foot])
        if stop < len(contacts) and stop - start >= MIN_STANCE
    ]
    return np.asarray(speeds, dtype=float)


def describe(speeds: np.ndarray) -> str:
    """`n lift-offs, percentiles` of a group's lift speeds."""
    if not len(speeds):
        return "no lift-off"
    values = ", ".join(
        f"p{q} {v:.2f}"
        for q, v in zip(PERCENTILES, np.percentile(speeds, PERCENTILES), strict=True)
    )
    return f"{len(speeds)} lift-offs, m/s: {values}"


def data_speeds(
    collection: str | Path, every: int, solver: LegSolver, params: ContactParams
) -> np.ndarray:
    """Lift speeds of every `every`-th clip of a retargeted collection, pooled."""
    found = [
        lift_speeds(trajectory, solver, params)
        for k, (_, trajectory) in enumerate(iter_collection(collection))
        if k % every == 0
    ]
    return np.concatenate(found) if found else np.empty(0)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("rollouts", nargs="*", type=Path, help="rollout files, one group")
    parser.add_argument("--every", type=int, default=4, help="every n-th retargeted clip")
    parser.add_argument("--collection", type=Path, default=None)
    args = parser.parse_args(argv)
    params = load_params()
    robot: Robot = load_robot()
    solver = LegSolver(robot, params.rollout.consistent)
    collection = args.collection or REPO_ROOT / params.features.input
    try:
        data = data_speeds(collection, max(1, args.every), solver, params.contacts)
        print(f"data ({collection}, every {args.every}): {describe(data)}")
        if args.rollouts:
            rolled = [
                lift_speeds(read_trajectory(path), solver, params.contacts, rollout=True)
                for path in args.rollouts
            ]
            print(f"rollouts ({len(args.rollouts)} files): {describe(np.concatenate(rolled))}")
    except PimannError as error:
        print(f"lift_speed: {error}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
