"""diagnostics.consistent_tables: the variants' medians beside their raw twins."""

from __future__ import annotations

import pandas as pd

from diagnostics.consistent_tables import sim_table, variant_tables


def _row(model, seed, scenario, variant, sliding, **extra):
    return {
        "model": model,
        "seed": seed,
        "scenario": scenario if variant == "raw" else f"{scenario}+{variant}",
        "steering": False,
        "rollout_variant": variant,
        "support_rmse_linear_position_total": sliding,
        "support_rmse_paper_linear_total": 2 * sliding,
        "gait_travel": 3.0,
        "walks": True,
        "gait_step_length": 0.2,
        "joint_distance_rms_rad": float("nan") if variant == "raw" else 0.05,
        "leg_joint_speed_max_rad_s": 8.0,
        "consistent_residual_max_m": float("nan") if variant == "raw" else 0.01,
        **extra,
    }


def test_tables_give_each_models_seed_medians_per_variant_and_skip_raw_only_scenarios():
    rows = [
        _row("w10", 0, "authors", "raw", 40.0),
        _row("w10", 1, "authors", "raw", 44.0),
        _row("w10", 0, "authors", "post", 10.0),
        _row("w10", 1, "authors", "post", 12.0),
        _row("w10", 0, "authors", "loop", 20.0),
        _row("w10", 0, "clip", "raw", 99.0),  # no variant: no table
    ]
    table = variant_tables(pd.DataFrame(rows))
    assert "`authors`, unsteered" in table and "`clip`" not in table
    line = next(row for row in table.splitlines() if row.startswith("| w=10"))
    assert "| 42.0 / 11.0 / 20.0 |" in line  # the medians over seeds, per variant
    assert "| 2 / 1 |" in line  # rollouts that walk: two raw seeds, one loop


def test_sim_table_pairs_a_variant_run_with_its_raw_twin():
    run = {
        "model": "w10",
        "seed": 0,
        "steering": True,
        "controller": "offline",
        "fallen": False,
        "joint_rmse_rad": 0.005,
        "foot_slip_m": 0.004,
        "com_error_max_m": 0.01,
        "zmp_error_rms_m": 0.02,
    }
    runs = {
        "raw": {**run, "scenario": "forward", "variant": "raw"},
        "post": {**run, "scenario": "forward+post", "variant": "post", "foot_slip_m": 0.006},
    }
    table = sim_table({"runs": runs})
    assert "| w10 seed 0 forward+post, steered | offline | no -> no |" in table
    assert "4.0 -> 6.0" in table
