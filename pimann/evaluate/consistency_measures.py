"""What a contact-consistent rollout changes (docs/consistent.md): metrics.csv's columns beside
the sliding measures, for every rollout (raw ones too, where they apply).

- `rollout_variant`: raw, post or loop (the scenario's suffix, pimann.core.rollout_files);
- `penetration_max_m`: how far the lowest sole corner goes below the floor (0: never; measured
  by pimann.evaluate.metrics.trajectory_metrics on the soles of its pass);
- `joint_distance_rms_rad`, `joint_distance_max_rad`: the joints' distance to the raw twin
  (the same model, seed, scenario and steering), RMS and largest over every frame and joint;
  empty for a raw rollout;
- `leg_joint_speed_max_rad_s`: the legs' largest joint speed, from the joints' first
  differences (every rollout; pimann.evaluate.metrics.leg_joint_speed_max, measured by
  `trajectory_metrics`' pass like the penetration): a hold that straightens a leg by the end
  of a stance folds it fast at the release;
- `consistent_residual_max_m`: the largest distance of a held sole from its target that the
  leg IK left (the file's attrs; empty for a raw rollout).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pimann.core.parallel import pool_map
from pimann.core.rollout_files import RAW, RolloutKey, rollout_path, split_variant

COLUMNS = (
    "rollout_variant",
    "penetration_max_m",
    "joint_distance_rms_rad",
    "joint_distance_max_rad",
    "leg_joint_speed_max_rad_s",
    "consistent_residual_max_m",
)


def _measures(job: tuple[Path, RolloutKey]) -> dict[str, Any]:
    """The columns of one rollout but the penetration and the leg joint speed (`trajectory_
    metrics`' pass reads them): a variant read with its raw twin; a raw rollout is not read."""
    from pimann.core.trajectory import read_trajectory

    root, key = job
    scenario, variant = split_variant(key.scenario)
    out: dict[str, Any] = {
        "rollout_variant": variant,
        "joint_distance_rms_rad": None,
        "joint_distance_max_rad": None,
        "consistent_residual_max_m": None,
    }
    if variant == RAW:
        return out
    trajectory = read_trajectory(rollout_path(root, key))
    out["consistent_residual_max_m"] = trajectory.attrs.get("consistent_residual_max_m")
    twin = rollout_path(root, dataclasses.replace(key, scenario=scenario))
    if twin.is_file():
        rms, largest = joint_distance(
            read_trajectory(twin).joint_positions, trajectory.joint_positions
        )
        out["joint_distance_rms_rad"], out["joint_distance_max_rad"] = rms, largest
    return out


def joint_distance(raw: np.ndarray, variant: np.ndarray) -> tuple[float, float]:
    """(RMS, largest) distance of a variant's joints (T, nj) to the raw ones over every frame
    (the shorter's) and joint."""
    frames = min(len(raw), len(variant))
    distance = np.asarray(variant[:frames], float) - np.asarray(raw[:frames], float)
    return float(np.sqrt(np.mean(distance**2))), float(np.abs(distance).max())


def with_consistency_columns(
    frame: pd.DataFrame, root: str | Path, keys: list[RolloutKey], workers: int = 1
) -> pd.DataFrame:
    """`frame` (one row per rollout of `keys` under `root`, in order, with `trajectory_metrics`'
    `penetration_max_m` and `leg_joint_speed_max_rad_s`) with `COLUMNS` last, in their order."""
    jobs = [(Path(root), key) for key in keys]
    rows = pd.DataFrame(pool_map(_measures, jobs, workers, "consistency measures"))
    frame = pd.concat([frame, rows.set_index(frame.index)], axis=1)
    return frame[[c for c in frame if c not in COLUMNS] + list(COLUMNS)]
