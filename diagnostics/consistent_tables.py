"""The contact-consistent variants beside their raw twins, as markdown tables (docs/consistent.md).

    python -m diagnostics.consistent_tables [--metrics results/metrics.csv]
        [--sim results/sim_summary.json]

Per scenario of `rollout.consistent.scenarios` and steering: for every model the medians over
its seeds of the position-level sliding and the authors' metric (raw / post / loop), the
travel over the gait window, the rollouts that walk, the step length (raw / loop: post keeps
the raw base and gait), the joints' RMS distance to the raw twin, the legs' largest joint
speed and the largest held-sole residual (post / loop); then the MuJoCo runs of a variant
beside the same run of its raw rollout. Reads the evaluate and simulate stages' outputs only.
Outside the pipeline: nothing imports this module.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from pimann.core.paths import REPO_ROOT

VARIANTS = ("raw", "post", "loop")
MODEL_ORDER = ("baseline", "w0", "w1", "w10", "w20", "w100", "adherent")
MODEL_NAMES = {"baseline": "baseline", "adherent": "ADHERENT"}


def _model_name(model: str) -> str:
    return MODEL_NAMES.get(model, f"w={model.removeprefix('w')}")


def _cell(values: dict[str, float], variants: Sequence[str], digits: int) -> str:
    return " / ".join(
        "-" if not np.isfinite(values.get(v, np.nan)) else f"{values[v]:.{digits}f}"
        for v in variants
    )


def variant_tables(metrics: pd.DataFrame) -> str:
    """One markdown table per (scenario, steering) that has a contact-consistent variant."""
    frame = metrics.copy().assign(base=metrics["scenario"].str.split("+").str[0])
    with_variants = frame.loc[frame["rollout_variant"] != "raw", "base"].unique()
    frame = frame[frame["base"].isin(with_variants)]
    columns = [
        ("position level: raw / post / loop", "support_rmse_linear_position_total", VARIANTS, 1),
        ("authors' metric: raw / post / loop", "support_rmse_paper_linear_total", VARIANTS, 1),
        ("travel (m): raw / loop", "gait_travel", ("raw", "loop"), 2),
        ("walks (of seeds): raw / loop", "walks", ("raw", "loop"), 0),
        ("step (m): raw / loop", "gait_step_length", ("raw", "loop"), 2),
        ("joints RMS (rad): post / loop", "joint_distance_rms_rad", ("post", "loop"), 3),
        (
            "leg joint speed, largest (rad/s): raw / post / loop",
            "leg_joint_speed_max_rad_s",
            VARIANTS,
            0,
        ),
        ("residual (m): post / loop", "consistent_residual_max_m", ("post", "loop"), 3),
    ]
    out = []
    for (base, steering), group in frame.groupby(["base", "steering"], sort=True):
        out.append(f"`{base}`, {'steered' if steering else 'unsteered'}:\n")
        out.append("| model | " + " | ".join(title for title, *_ in columns) + " |")
        out.append("| --- " * (len(columns) + 1) + "|")
        models = [m for m in MODEL_ORDER if m in set(group["model"])]
        for model in models:
            rows = group[group["model"] == model]
            cells = []
            for _, column, variants, digits in columns:
                by_variant = rows.groupby("rollout_variant")[column]
                values = (by_variant.sum() if column == "walks" else by_variant.median()).to_dict()
                cells.append(_cell(values, variants, digits))
            out.append(f"| {_model_name(model)} | " + " | ".join(cells) + " |")
        out.append("")
    return "\n".join(out)


def sim_table(summary: dict) -> str:
    """The MuJoCo runs of a contact-consistent variant beside the same run of the raw one."""
    runs = list(summary["runs"].values())
    key = ("model", "seed", "scenario", "steering", "controller")

    def twin_key(run: dict) -> tuple:
        return (*(run[k] for k in key if k != "scenario"), run["scenario"].split("+")[0])

    raw = {twin_key(r): r for r in runs if r.get("variant", "raw") == "raw"}
    lines = [
        "| rollout | controller | fell | joint tracking RMSE (rad) | foot slip (mm) "
        "| CoM error, largest (cm) | ZMP error RMS (cm) |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for run in runs:
        if run.get("variant", "raw") == "raw":
            continue
        twin = raw.get(twin_key(run))
        if twin is None:
            continue

        def pair(name: str, scale: float, digits: int, a=twin, b=run) -> str:
            return f"{a[name] * scale:.{digits}f} -> {b[name] * scale:.{digits}f}"

        fell = f"{'yes' if twin['fallen'] else 'no'} -> {'yes' if run['fallen'] else 'no'}"
        lines.append(
            f"| {run['model']} seed {run['seed']} {run['scenario']}, "
            f"{'steered' if run['steering'] else 'unsteered'} "
            f"| {run['controller']} | {fell} | {pair('joint_rmse_rad', 1, 4)} "
            f"| {pair('foot_slip_m', 1e3, 1)} | {pair('com_error_max_m', 1e2, 1)} "
            f"| {pair('zmp_error_rms_m', 1e2, 1)} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--metrics", type=Path, default=REPO_ROOT / "results/metrics.csv")
    parser.add_argument("--sim", type=Path, default=REPO_ROOT / "results/sim_summary.json")
    args = parser.parse_args(argv)
    print(variant_tables(pd.read_csv(args.metrics)))
    if args.sim.exists():
        print(sim_table(json.loads(args.sim.read_text())))


if __name__ == "__main__":
    main()
