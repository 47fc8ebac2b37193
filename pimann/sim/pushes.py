"""Push recovery: the largest short push on the base each controller survives (bisected).

The push (`simulate.pushes.duration_s`, on the base through MuJoCo's `xfrc_applied`) is
centred on the middle of the first single support; lateral pushes point to the swing foot's
side (where the landing box lets the online controller step out), forward ones along the
stance foot's heading. A trial survives when the base stays above `fall_height` until
`recovery_s` after the push (the rest of the walk is not simulated). An MPC that finds no
solution after the push counts as a fall.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from pimann.core.errors import PimannError
from pimann.core.params import SimulateParams
from pimann.core.robot import load_robot
from pimann.core.rotations import rot_z
from pimann.core.trajectory import Trajectory
from pimann.sim.closed_loop import simulate_trajectory
from pimann.sim.footsteps import FootstepPlan, extract_footsteps
from pimann.sim.online import Push
from pimann.sim.synthetic import standing_feet
from pimann.sim.wbc import standing_pose

DIRECTIONS = ("lateral", "forward")
log = logging.getLogger(__name__)


def largest_survived(survives: Callable[[float], bool], high: float, tolerance: float) -> float:
    """Bisection on [0, high]: the largest force that survives, to within `tolerance`.

    Assumes one threshold (survives below it, falls above); `high` itself is tried first.
    """
    if survives(high):
        return high
    low = 0.0
    while high - low > tolerance:
        middle = 0.5 * (low + high)
        if survives(middle):
            low = middle
        else:
            high = middle
    return low


def push_at_mid_single_support(
    plan: FootstepPlan, direction: str, force: float, duration: float
) -> Push:
    """A push of `force` N centred on the first single support's middle, in `direction`."""
    if direction not in DIRECTIONS:
        raise ValueError(f"push direction must be one of {DIRECTIONS}, not {direction!r}")
    lifts = [plan.feet[s].t_off[0] if len(plan.feet[s]) > 1 else np.inf for s in (0, 1)]
    swing = int(np.argmin(lifts))
    if not np.isfinite(lifts[swing]):
        raise ValueError("the plan never lifts a foot: no single support to push in")
    middle = 0.5 * (plan.feet[swing].t_off[0] + plan.feet[swing].t_on[1])
    heading = float(plan.feet[1 - swing].yaws[0])
    local = (
        np.array([1.0, 0.0, 0.0])
        if direction == "forward"
        else np.array([0.0, 1.0 if swing == 0 else -1.0, 0.0])
    )
    return Push(force * (rot_z(heading) @ local), middle - 0.5 * duration, duration)


def push_recovery(
    trajectory: Trajectory, params: SimulateParams, controllers: list[str]
) -> dict[str, dict[str, float]]:
    """Per controller and direction, the largest push survived (N)."""
    settings = params.pushes
    robot = load_robot("simulation")
    plan = extract_footsteps(
        robot, trajectory, params, standing_feet(robot, standing_pose(robot, params))
    )
    table: dict[str, dict[str, float]] = {}
    for controller in controllers:
        table[controller] = {}
        for direction in settings.directions:

            def survives(force: float, controller: str = controller, direction: str = direction):
                push = push_at_mid_single_support(plan, direction, force, settings.duration_s)
                until = push.start + push.duration + settings.recovery_s
                try:
                    result = simulate_trajectory(trajectory, params, until, controller, push)
                except PimannError as error:  # the MPC found no way to recover: a fall
                    log.debug("%s %s %.0f N: %s", controller, direction, force, error.problem)
                    return False
                log.debug(
                    "%s %s %.0f N: %s",
                    controller,
                    direction,
                    force,
                    "fell" if result.fallen else "survived",
                )
                return not result.fallen

            table[controller][direction] = largest_survived(
                survives, settings.max_force, settings.tolerance
            )
    return table


def plot_push_recovery(table: dict[str, dict[str, float]], path: str | Path) -> None:
    """Bars: the largest push survived per direction, one bar per controller."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    controllers = list(table)
    directions = sorted({d for row in table.values() for d in row}, key=DIRECTIONS.index)
    figure, axis = plt.subplots(figsize=(3.5, 2.4))
    width = 0.8 / max(len(controllers), 1)
    for k, controller in enumerate(controllers):
        x = np.arange(len(directions)) + (k - 0.5 * (len(controllers) - 1)) * width
        axis.bar(x, [table[controller].get(d, np.nan) for d in directions], width, label=controller)
    axis.set_xticks(np.arange(len(directions)), directions)
    axis.set_ylabel("largest push survived (N)")
    axis.legend(frameon=False)
    figure.tight_layout()
    figure.savefig(path, dpi=200)
    plt.close(figure)


def push_records(tables: dict[str, dict[str, dict[str, float]]]) -> list[dict[str, Any]]:
    """Rows (rollout, controller, direction, force) for the summary JSON."""
    return [
        {"rollout": name, "controller": c, "direction": d, "largest_survived_n": force}
        for name, table in tables.items()
        for c, row in table.items()
        for d, force in row.items()
    ]
