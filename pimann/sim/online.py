"""The online controller's reference layer: the centroidal MPC replanned every `mpc.dt`.

Between solves the centroidal dynamics are integrated with the first knot's forces (constant
over the period: the CoM's acceleration is g + sum f / m), which gives the whole-body layer
its CoM and CoM velocity; the desired ZMP is those forces' centre of pressure. The MPC's
adjusted footsteps are written into the footstep plan the swing planner reads, so the IK and
the feedback are the offline controller's (`pimann.sim.closed_loop.simulate_plan`).
"""

from __future__ import annotations

import copy
import dataclasses

import mujoco
import numpy as np

from pimann.core.params import SimulateParams
from pimann.sim.centroidal_mpc import (
    GRAVITY,
    CentroidalMPC,
    MpcProblem,
    MpcSolution,
    horizon_problem,
    knot_count,
)
from pimann.sim.dcm import DCMPlan
from pimann.sim.footsteps import FootstepPlan
from pimann.sim.model import SimModel
from pimann.sim.wbc import SOLE_HEIGHT


@dataclasses.dataclass(frozen=True)
class Push:
    """An external force on the base (world frame, N) over [start, start + duration) s."""

    force: np.ndarray
    start: float
    duration: float

    def at(self, t: float) -> np.ndarray:
        active = self.start <= t < self.start + self.duration
        return np.asarray(self.force, dtype=float) if active else np.zeros(3)


def centroidal_state(sim: SimModel, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray]:
    """Measured CoM velocity (3,) and angular momentum about the CoM per unit mass (3,)."""
    mujoco.mj_subtreeVel(sim.model, data)
    mass = float(sim.model.body_subtreemass[0])
    return data.subtree_linvel[0].copy(), data.subtree_angmom[0].copy() / mass


class OnlineReference:
    """CoM, CoM velocity and ZMP references from the MPC, with `at(t)` like a DCMPlan."""

    def __init__(self, plan: FootstepPlan, guide: DCMPlan, params: SimulateParams):
        self.params = params
        self.mpc_params = params.mpc
        self.plan = copy.deepcopy(plan)  # the swing planner's plan: its footsteps get adjusted
        self.nominal = tuple(f.positions.copy() for f in plan.feet)
        self.guide = guide  # the CoM reference along the horizon (height held at com_height)
        self.mpc = CentroidalMPC(params.mpc)
        self.solved_at: float | None = None
        self.problem: MpcProblem | None = None
        self.solution: MpcSolution | None = None
        self.solve_times: list[float] = []
        self.horizons: list[MpcProblem] = []  # in order: a replay with another solver

    def due(self, t: float) -> bool:
        return self.solved_at is None or t >= self.solved_at + self.mpc_params.dt - 1e-9

    def update(
        self, t: float, com: np.ndarray, com_velocity: np.ndarray, angular_momentum: np.ndarray
    ) -> None:
        """Replan from the measured state (in the plan's world) and adjust the footsteps."""
        n = knot_count(self.mpc_params)
        knots = t + np.arange(n + 1) * self.mpc_params.dt
        reference = np.array([self.guide.at(u)[0] for u in knots])
        reference[:, 2] = self.params.com_height
        problem = horizon_problem(
            self.plan,
            self.nominal,
            t,
            self.mpc_params,
            com,
            com_velocity,
            angular_momentum,
            reference,
            -SOLE_HEIGHT,
        )
        solution = self.mpc.solve(problem)
        self.problem, self.solution, self.solved_at = problem, solution, t
        self.solve_times.append(solution.solve_s)
        self.horizons.append(problem)
        self._adjust_footsteps(t, problem, solution)

    def _adjust_footsteps(self, t: float, problem: MpcProblem, solution: MpcSolution) -> None:
        """Write each movable landing the MPC chose into the plan (the swing planner's target)."""
        times = np.clip(
            t + np.arange(len(problem.landing[0])) * self.mpc_params.dt, 0.0, self.plan.duration
        )
        for side in (0, 1):
            for k in np.flatnonzero(problem.landing[side]):
                m = self.plan.stance_index(side, times[k])
                if m is not None:
                    self.plan.feet[side].positions[m] = solution.feet[side, k, :2]

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """CoM, CoM velocity and ZMP at t from the last solve's first-knot forces."""
        if self.solution is None or self.problem is None or self.solved_at is None:
            return self.guide.at(t)
        tau = max(t - self.solved_at, 0.0)
        solution = self.solution
        acceleration = GRAVITY + solution.forces[:, :, 0].sum(axis=(0, 1))
        com = solution.com[0] + solution.com_velocity[0] * tau + 0.5 * acceleration * tau**2
        velocity = solution.com_velocity[0] + acceleration * tau
        com[2] = self.params.com_height
        velocity[2] = 0.0
        return com, velocity, solution.zmp(self.problem, self.mpc_params, 0)
