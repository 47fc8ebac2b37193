"""The simulate stage's work: chosen rollouts walked in MuJoCo, one result file each, a summary.

results/sim/<model>-<seed>-<scenario>[+<variant>]-<steering|nosteering>[-online].h5
                                            (simulation_files; the variant when not raw)
results/sim/<same name>.mp4                                       (runs marked `video`)
results/sim/pushes.png                                            (simulate.pushes, if any)
summary JSON: per run the summary figures, per push study the largest push survived per
controller and direction (N), plus the profile and the params used
"""

from __future__ import annotations

import json
import logging
import math
from pathlib import Path
from typing import Any

from pimann.core.atomic import atomic_path, write_text_atomic
from pimann.core.errors import PimannError, about
from pimann.core.params import Params, SimulateRun, as_dict
from pimann.core.paths import repo_relative
from pimann.core.progress import track
from pimann.core.rollout_files import STEERING_LABEL, RolloutKey, rollout_path, variant_scenario
from pimann.core.trajectory import read_trajectory
from pimann.sim.closed_loop import simulate_trajectory
from pimann.sim.pushes import plot_push_recovery, push_records, push_recovery
from pimann.sim.simulation_files import write_simulation
from pimann.sim.video import render_simulation

log = logging.getLogger(__name__)


def run_key(run: SimulateRun) -> RolloutKey:
    """The rollout a run walks: the raw one, or its contact-consistent variant (`variant`)."""
    return RolloutKey(
        run.model, run.seed, variant_scenario(run.scenario, run.variant), run.steering
    )


def run_name(run: SimulateRun) -> str:
    """The offline controller's raw runs keep their names; a variant's scenario gains
    `+<variant>`, the online controller's runs `-online`."""
    key = run_key(run)
    name = f"{key.model}-{key.seed}-{key.scenario}-{STEERING_LABEL[key.steering]}"
    return name if run.controller == "offline" else f"{name}-{run.controller}"


def _json_ready(value: Any) -> Any:
    """NaN and infinities as null (strict JSON), numpy scalars as Python numbers."""
    if isinstance(value, dict):
        return {k: _json_ready(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_json_ready(v) for v in value]
    if hasattr(value, "item"):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def simulate_runs(
    rollouts_dir: str | Path, out_dir: str | Path, summary_path: str | Path, params: Params
) -> dict[str, Any]:
    """Walk every run of `params.simulate.runs`; write `out_dir` (whole) and the summary JSON.

    Every rollout is checked to exist before minutes of simulation start.
    """
    sim = params.simulate
    if not sim.runs:
        raise PimannError(None, "simulate.runs is empty: nothing to simulate")
    jobs = []
    consistent = params.rollout.consistent
    for run in sim.runs:
        path = rollout_path(rollouts_dir, run_key(run))
        if run.variant != "raw" and not (
            run.variant in consistent.variants and run.scenario in consistent.scenarios
        ):
            raise PimannError(
                "params.yaml",
                f"simulate.runs: {run_name(run)} needs rollout.consistent to make the "
                f"{run.variant!r} variant of {run.scenario!r}",
            )
        if not path.is_file():
            raise PimannError(path, "rollout not found (run the rollout stage first)")
        jobs.append((run, path))
    push_jobs = []
    for rollout in sim.pushes.rollouts:
        key = RolloutKey(rollout.model, rollout.seed, rollout.scenario, rollout.steering)
        path = rollout_path(rollouts_dir, key)
        if not path.is_file():
            raise PimannError(path, "rollout not found (run the rollout stage first)")
        push_jobs.append(
            (f"{key.model}-{key.seed}-{key.scenario}-{STEERING_LABEL[key.steering]}", path)
        )
    runs: dict[str, Any] = {}
    pushes: dict[str, Any] = {}
    with atomic_path(out_dir) as tmp:
        tmp.mkdir()
        for run, path in track(jobs, "simulate", "runs", logger=log):
            name = run_name(run)
            provenance = {
                "model": run.model,
                "seed": run.seed,
                "scenario": run_key(run).scenario,  # <scenario>+<variant> for a variant
                "steering": run.steering,
                "controller": run.controller,
                "variant": run.variant,
                "rollout": repo_relative(path),
            }
            try:
                with about(path, f"simulate run {name}"):
                    trajectory = read_trajectory(path)
                    log.debug("%s: %.1f s generated", name, trajectory.time[-1])
                    result = simulate_trajectory(trajectory, sim, controller=run.controller)
            except PimannError as error:  # recorded, the other runs go on
                log.warning("%s", error)
                runs[name] = {**provenance, "success": False, "failed": str(error)}
                continue
            summary = write_simulation(
                tmp / f"{name}.h5",
                result,
                sim,
                source=repo_relative(path),
                rate_hz=sim.output_rate_hz,
                attrs=provenance,
            )
            log.debug(
                "%s: success %s, %d steps, walked %.2f m of %.2f m, joint RMSE %.4f rad, ZMP "
                "outside %.3f m, slip %.4f m, RTF %.1fx",
                name,
                summary["success"],
                summary["steps"],
                summary["distance_walked_m"],
                summary["distance_planned_m"],
                summary["joint_rmse_rad"],
                summary["zmp_outside_max_m"] or 0.0,
                summary["foot_slip_m"],
                summary["real_time_factor"],
            )
            if run.video:
                render_simulation(
                    read_trajectory(tmp / f"{name}.h5"),
                    tmp / f"{name}.mp4",
                    sim,
                    every_n_frames=sim.video_every_n,
                    width=sim.video_width,
                    height=sim.video_height,
                )
            runs[name] = {**provenance, **summary}
        for name, path in track(push_jobs, "simulate", "push studies", logger=log):
            try:
                with about(path, f"push recovery {name}"):
                    pushes[name] = push_recovery(
                        read_trajectory(path), sim, list(sim.pushes.controllers)
                    )
            except PimannError as error:  # recorded, the other studies go on
                log.warning("%s", error)
                pushes[name] = {"failed": str(error)}
        tables = {name: table for name, table in pushes.items() if "failed" not in table}
        if tables:
            plot_push_recovery(next(iter(tables.values())), tmp / "pushes.png")
            for row in push_records(tables):
                log.info(
                    "push recovery %s, %s, %s: %.0f N",
                    row["rollout"],
                    row["controller"],
                    row["direction"],
                    row["largest_survived_n"],
                )
    failed = sorted(name for name, run in runs.items() if "failed" in run)
    if failed:
        log.warning("%d of %d runs failed: %s", len(failed), len(runs), ", ".join(failed))
    fell = [
        f"{name} at {run['fall_time_s']:.1f} s"
        for name, run in runs.items()
        if run.get("fall_time_s") is not None
    ]
    log.info(
        "%d of %d runs succeeded; fell: %s",
        sum(bool(run.get("success")) for run in runs.values()),
        len(runs),
        ", ".join(fell) or "none",
    )
    record = {
        "profile": params.profile,
        "failed_runs": failed,
        "runs": runs,
        "pushes": pushes,
        "params": {"simulate": as_dict(sim)},
    }
    record = _json_ready(record)
    write_text_atomic(summary_path, json.dumps(record, indent=2) + "\n")
    return record
