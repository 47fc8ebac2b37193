"""The paper's figures, from results/ alone (metrics.csv, metrics_summary.json, timeseries/, sim/).

One function per figure, each returning a matplotlib Figure (None when its data is missing;
pyplot-free, so no global state or GUI backend);
`make_figures` saves them as PDF and PNG. One style for all (pimann.evaluate.figure_style: single
IEEE column, 3.5 in wide, 8 pt), one colour per PI weight everywhere (`weight_colours`), legends
above the axes (never over the data). Every file records its provenance (profile, epochs,
clips) in its metadata, and a figure made from anything but the `paper` profile says so in a
small footer.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from pathlib import Path

import h5py
import matplotlib
import numpy as np
import pandas as pd
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from pimann.core.params import EvaluateParams, FiguresParams
from pimann.core.robot import JOINT_NAMES
from pimann.core.rollout_files import paper_baseline, pi_models, weight_label
from pimann.evaluate.evaluation_results import Results, load_results
from pimann.evaluate.figure_style import (
    BASELINE_COLOUR,
    DATA_COLOUR,
    new_figure,
    save_figure,
    style,
    weight_colours,
)
from pimann.evaluate.metrics import PAPER_BASELINE_RMSE

log = logging.getLogger(__name__)
CONDITIONS = {  # drift figures: (title, colour, line style)
    "base_baseline": ("Baseline", BASELINE_COLOUR, "-"),
    "base_pi": ("PI, no steering", "tab:red", "--"),
    "base_pi_steering": ("PI, steering", "tab:blue", "-"),
}
AXIS_COLOURS = ("tab:blue", "tab:orange", "tab:green")  # x y z / roll pitch yaw
SIDE_COLOURS = {"left": "tab:blue", "right": "tab:orange"}
CONTACT_ALPHA = 0.15  # the contact shading of the foot-height figure (both feet: mixed)
# joint tracking: (trace, colour, line style, width, zorder); the reference dashed over the
# measured (wide, light) so both show where they coincide, the generated dotted
JOINT_TRACES = (
    ("measured", "tab:orange", "-", 2.0, 2),
    ("generated", "0.45", ":", 0.9, 3),
    ("reference", "tab:blue", "--", 0.8, 4),
)
TRACKED_JOINTS = ("torso_yaw", "neck_yaw", "l_shoulder_pitch", "r_elbow")


# ----------------------------------------------------------------------------- the figures


def fig_pi_weight_comparison(
    results: Results, figures: FiguresParams, evaluate: EvaluateParams
) -> Figure | None:
    """Fig. pi_weight_comparison_plot: support-foot RMSE per w (boxes over seeds), baseline line.

    The authors' metric (`support_rmse_paper_*`) on their unsteered test (evaluate.scenario);
    medians orange, means black diamonds; our baseline (ADHERENT where trained), the paper's
    baseline numbers (22.88, 17.74) and the retargeted data's own level under the same metric
    (forward walking, metrics_summary.json) as lines.
    """
    frame = results.metrics
    frame = frame[(frame["scenario"] == evaluate.scenario) & ~frame["steering"]]
    models = pi_models(frame)
    weights = [w for w in evaluate.box_weights if float(w) in models]
    if not weights:
        log.info(
            "pi_weight_comparison: no %s rollouts of %s", evaluate.scenario, evaluate.box_weights
        )
        return None
    colours = weight_colours(results.weights)
    fig, axes = new_figure(figures, 2.2, 1, 2)
    for ax, kind, unit in zip(axes, ("linear", "angular"), ("m/s", "rad/s"), strict=True):
        metric = f"support_rmse_paper_{kind}_total"
        data = [frame.loc[frame["model"] == models[float(w)], metric].dropna() for w in weights]
        boxes = ax.boxplot(
            data,
            tick_labels=[weight_label(w) for w in weights],
            patch_artist=True,
            showmeans=True,
            widths=0.6,
            medianprops={"color": "tab:orange", "linewidth": 1.2},
            meanprops={
                "marker": "D",
                "markerfacecolor": "black",
                "markeredgecolor": "black",
                "markersize": 3,
            },
            flierprops={"markersize": 2},
            boxprops={"linewidth": 0.6},
            whiskerprops={"linewidth": 0.6},
            capprops={"linewidth": 0.6},
        )
        for patch, w in zip(boxes["boxes"], weights, strict=True):
            patch.set_facecolor((*colours[float(w)][:3], 0.35))
        name = paper_baseline(frame)
        baseline = frame.loc[frame["model"] == name, metric].dropna()
        if len(baseline):
            ax.axhline(baseline.median(), color=BASELINE_COLOUR, ls="--", lw=1.0, label=name)
        if (level := results.data_level(metric)) is not None:
            ax.axhline(level, color=DATA_COLOUR, ls=":", lw=1.0, label="data")
        ax.axhline(
            PAPER_BASELINE_RMSE[kind],
            color=BASELINE_COLOUR,
            ls="-.",
            lw=0.8,
            label="paper's baseline",
        )
        ax.set_xlabel("PI weight $w$")
        ax.set_title(f"{kind} ({unit}, summed)")
        ax.set_ylim(bottom=0)
    # a sum over the steps (frame i-1 to i) of each step's RMS: a number that grows with them
    frames = frame["frames"].median() if "frames" in frame else float("nan")
    over = f"over {frames - 1:.0f} steps" if np.isfinite(frames) else "over the steps"
    axes[0].set_ylabel(f"total RMSE: sum of per-step\nRMS {over}")
    handles, labels = axes[0].get_legend_handles_labels()
    handles += [
        Line2D([], [], color="tab:orange", lw=1.2),
        Line2D([], [], ls="none", marker="D", color="black", markersize=3),
    ]
    labels += ["median (seeds)", "mean"]
    fig.legend(handles, labels, loc="outside upper center", ncols=3)  # 3 fit a column
    return fig


def _base_series(results: Results) -> dict[str, pd.DataFrame]:
    return {name: results.timeseries[name] for name in CONDITIONS if name in results.timeseries}


def _condition_title(results: Results, name: str) -> str:
    title = CONDITIONS[name][0]
    weight = results.model_weight(name)
    return title if name == "base_baseline" or weight is None else f"{title} ($w$={weight:g})"


def fig_base_displacement(
    results: Results, figures: FiguresParams, evaluate: EvaluateParams
) -> Figure | None:
    """Fig. base_displacement_pid_ablation: base x y z (top) and roll pitch yaw (bottom) vs time."""
    series = _base_series(results)
    if not series:
        log.info("base_displacement: no base_*.csv time series")
        return None
    fig, axes = new_figure(figures, 3.0, 2, len(series), sharex=True, sharey="row", squeeze=False)
    for col, (name, table) in enumerate(series.items()):
        top, bottom = axes[0, col], axes[1, col]
        for k, axis in enumerate("xyz"):
            top.plot(table["time"], table[f"base_{axis}"], color=AXIS_COLOURS[k], label=axis)
        for k, angle in enumerate(("roll", "pitch", "yaw")):
            bottom.plot(table["time"], table[f"base_{angle}"], color=AXIS_COLOURS[k], label=angle)
        top.set_title(_condition_title(results, name).replace(", ", ",\n"), fontsize="small")
        bottom.set_xlabel("time (s)")
    axes[0, 0].set_ylabel("position (m)")
    axes[1, 0].set_ylabel("orientation (rad)")
    handles = [Line2D([], [], color=c) for c in AXIS_COLOURS]
    labels = ["$x$ / roll", "$y$ / pitch", "$z$ / yaw"]
    fig.legend(handles, labels, loc="outside upper center", ncols=3)
    return fig


def fig_ground_projection(
    results: Results, figures: FiguresParams, evaluate: EvaluateParams
) -> Figure | None:
    """Fig. ground_projection: base path on the ground for the three conditions."""
    series = _base_series(results)
    if not series:
        log.info("ground_projection: no base_*.csv time series")
        return None
    fig, ax = new_figure(figures, 2.6)
    ax.axhline(0.0, color="black", lw=0.6, ls=":", label="desired direction")
    for name, table in series.items():
        _, colour, line = CONDITIONS[name]
        ax.plot(
            table["base_x"],
            table["base_y"],
            color=colour,
            ls=line,
            label=_condition_title(results, name),
        )
        ax.plot(table["base_x"].iloc[-1], table["base_y"].iloc[-1], "o", color=colour, ms=2.5)
    ax.set_xlabel("$x$ (m)")
    ax.set_ylabel("$y$ (m)")
    fig.legend(loc="outside upper center", ncols=2)
    return fig


def _feet_series(results: Results) -> dict[float, pd.DataFrame]:
    return dict(
        sorted(
            (float(name.removeprefix("feet_w")), table)
            for name, table in results.timeseries.items()
            if name.startswith("feet_w")
        )
    )


def fig_foot_rotations(
    results: Results, figures: FiguresParams, evaluate: EvaluateParams
) -> Figure | None:
    """Fig. foot_rotations: left and right sole pitch vs time, one line per w."""
    feet = _feet_series(results)
    if not feet:
        log.info("foot_rotations: no feet_w*.csv time series")
        return None
    colours = weight_colours(results.weights)
    fig, axes = new_figure(figures, 2.8, 2, 1, sharex=True, sharey=True)
    for ax, side in zip(axes, ("left", "right"), strict=True):
        for weight, table in feet.items():
            ax.plot(
                table["time"],
                np.degrees(table[f"{side}_sole_pitch"]),
                color=colours[weight],
                label=f"$w$={weight:g}",
                lw=0.8,
            )
        ax.set_title(f"{side} foot", fontsize="small", pad=2)
    fig.supylabel("sole pitch (deg)", fontsize=figures.font_pt)
    axes[-1].set_xlabel("time (s)")
    fig.legend(
        *axes[0].get_legend_handles_labels(),
        loc="outside upper center",
        ncols=min(len(feet), 5),
        columnspacing=0.8,
        handlelength=1.0,
    )
    return fig


def fig_foot_heights(
    results: Results, figures: FiguresParams, evaluate: EvaluateParams
) -> Figure | None:
    """Fig. pi_ablation_foot_z_plot: foot heights for w=0 (top) and w=10 (bottom)."""
    feet = _feet_series(results)
    weights = [float(w) for w in evaluate.foot_height_weights if float(w) in feet]
    if not weights:
        log.info("foot_heights: no feet time series for w in %s", evaluate.foot_height_weights)
        return None
    fig, axes = new_figure(
        figures, 1.2 + 1.0 * len(weights), len(weights), 1, sharex=True, sharey=True, squeeze=False
    )
    for ax, weight in zip(axes[:, 0], weights, strict=True):
        table = feet[weight]
        for side, colour in SIDE_COLOURS.items():
            ax.plot(table["time"], 100 * table[f"{side}_foot_height"], color=colour, label=side)
            contact = table[f"{side}_contact"].to_numpy(bool)
            ax.fill_between(
                table["time"],
                0,
                1,
                where=contact,
                color=colour,
                alpha=CONTACT_ALPHA,
                lw=0,
                transform=ax.get_xaxis_transform(),
            )
        ax.set_title(f"$w$={weight:g}", fontsize="small", pad=2)
        ax.set_ylabel("foot height (cm)")
    axes[-1, 0].set_xlabel("time (s)")
    handles = [Line2D([], [], color=c) for c in SIDE_COLOURS.values()]
    handles += [Patch(color=c, alpha=CONTACT_ALPHA, lw=0) for c in SIDE_COLOURS.values()]
    labels = [*SIDE_COLOURS, *(f"{side} in contact" for side in SIDE_COLOURS)]
    fig.legend(handles, labels, loc="outside upper center", ncols=4, columnspacing=1.0)
    return fig


def _read_sim(path: Path) -> dict[str, np.ndarray] | None:
    """time, joints_reference, joints_measured (and joints_generated) of a simulation file."""
    if path.suffix == ".h5":
        with h5py.File(path, "r") as file:
            if not {"time", "joints_reference", "joints_measured"} <= set(file):
                return None
            names = [str(n) for n in file.attrs.get("joint_names", JOINT_NAMES)]
            out = {
                k: file[k][()]
                for k in ("time", "joints_reference", "joints_measured", "joints_generated")
                if k in file
            }
    else:
        table = pd.read_csv(path)
        names = [c.removesuffix("_measured") for c in table if c.endswith("_measured")]
        if "time" not in table or not names:
            return None
        out = {"time": table["time"].to_numpy()}
        for kind in ("reference", "measured", "generated"):
            if all(f"{n}_{kind}" in table for n in names):
                out[f"joints_{kind}"] = table[[f"{n}_{kind}" for n in names]].to_numpy()
    out["names"] = np.array(names)
    return out


def fig_joint_tracking(
    results: Results, figures: FiguresParams, evaluate: EvaluateParams
) -> Figure | None:
    """Fig. joint_plots: selected upper-body joints, generated / reference / measured, in sim."""
    files = sorted((results.root / "sim").glob("*.h5")) + sorted(
        (results.root / "sim").glob("*.csv")
    )
    runs = [(p, d) for p in files if (d := _read_sim(p)) is not None]
    if not runs:
        log.info("joint_tracking: no simulation traces under %s, skipped", results.root / "sim")
        return None
    # the paper's run: the featured PI model's steered mixed scenario, else any mixed run,
    # under the offline controller; its online twin (`<name>-online`) beside it if there is one
    offline = [(p, d) for p, d in runs if not p.stem.endswith("-online")] or runs
    featured = f"w{evaluate.pi_weight:g}-"
    mixed = [(p, d) for p, d in offline if "mixed" in p.stem]
    path, data = next(
        (
            (p, d)
            for p, d in mixed
            if p.stem.startswith(featured) and p.stem.endswith("mixed-steering")
        ),
        (mixed or offline)[0],
    )
    shown = [("offline", path, data)]
    shown += [("online", p, d) for p, d in runs if p.stem == f"{path.stem}-online"]
    names = list(data["names"])
    joints = [j for j in TRACKED_JOINTS if j in names] or names[:4]
    if len(shown) == 1:
        fig, axes = new_figure(figures, 2.8, 2, 2, sharex=True, squeeze=False)
        panels = [(ax, joint, shown[0]) for ax, joint in zip(axes.flat, joints, strict=False)]
    else:  # a row per joint, a column per controller
        fig, axes = new_figure(
            figures, 1.3 * len(joints) + 0.6, len(joints), 2, sharex=True, squeeze=False
        )
        panels = [(axes[r, c], joint, shown[c]) for r, joint in enumerate(joints) for c in (0, 1)]
    for ax, joint, (controller, _, run) in panels:
        k = list(run["names"]).index(joint)
        for kind, colour, line, width, z in JOINT_TRACES:
            if f"joints_{kind}" in run:
                ax.plot(
                    run["time"],
                    np.degrees(run[f"joints_{kind}"][:, k]),
                    color=colour,
                    ls=line,
                    label=kind,
                    lw=width,
                    zorder=z,
                    alpha=0.6 if kind == "measured" else 1.0,
                )
        title = joint.replace("_", " ")
        ax.set_title(
            title if len(shown) == 1 else f"{title}, {controller}", fontsize="small", pad=2
        )
    for ax in axes[-1]:
        ax.set_xlabel("time (s)")
    for ax in axes[:, 0]:
        ax.set_ylabel("angle (deg)")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    order = [labels.index(k) for k in ("generated", "reference", "measured") if k in labels]
    fig.legend(
        [handles[i] for i in order], [labels[i] for i in order], loc="outside lower center", ncols=3
    )  # below: the title is above
    which = " and online controllers" if len(shown) > 1 else " controller"
    fig.suptitle(f"MuJoCo, offline{which} ({path.stem})", fontsize="small")
    return fig


# (results, figures: the style, evaluate: what they show): the pi_weight_comparison figure on
# evaluate.scenario and box_weights, the foot heights of foot_height_weights, the joint-tracking
# figure the featured PI model's run (evaluate.pi_weight)
FIGURES: dict[str, Callable[..., Figure | None]] = {
    "pi_weight_comparison": fig_pi_weight_comparison,
    "base_displacement": fig_base_displacement,
    "ground_projection": fig_ground_projection,
    "foot_rotations": fig_foot_rotations,
    "foot_heights": fig_foot_heights,
    "joint_tracking": fig_joint_tracking,
}


def draw(
    name: str, results: Results, figures: FiguresParams, evaluate: EvaluateParams
) -> Figure | None:
    """The figure `name` of FIGURES, in the style `figures`, showing what `evaluate` selects."""
    return FIGURES[name](results, figures, evaluate)


def make_figures(
    results_dir: str | Path, out_dir: str | Path, figures: FiguresParams, evaluate: EvaluateParams
) -> dict[str, list[Path]]:
    """Every figure whose data exists under `results_dir`, into `out_dir` as PDF and PNG;
    `figures`: the style, `evaluate`: what they show (scenario, weights, the featured PI
    model)."""
    results = load_results(results_dir)
    written: dict[str, list[Path]] = {}
    with matplotlib.rc_context(style(figures)):
        for name in FIGURES:
            fig = draw(name, results, figures, evaluate)
            if fig is None:
                continue
            written[name] = save_figure(fig, out_dir, name, results.provenance)
            log.debug("%s -> %s", name, ", ".join(str(p) for p in written[name]))
    return written
