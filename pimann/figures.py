"""The paper's figures, from results/ alone (metrics.csv, metrics_summary.json, timeseries/, sim/).

One function per figure, each returning a matplotlib Figure (None when its data is missing;
pyplot-free, so no global state or GUI backend);
`make_figures` saves them as PDF and PNG. One style for all (`STYLE`, single IEEE column:
3.5 in wide, 8 pt), one colour per PI weight everywhere (`weight_colours`). Every file records
its provenance (profile, epochs, clips) in its metadata, and a figure made from anything but
the `paper` profile says so in a small footer.
"""

from __future__ import annotations

import dataclasses
import json
import logging
from collections.abc import Callable
from pathlib import Path
from typing import Any

import h5py
import matplotlib
import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from pimann.atomic import atomic_path
from pimann.errors import PimannError
from pimann.evaluate import read_metrics
from pimann.params import FiguresParams
from pimann.robot import JOINT_NAMES
from pimann.rollouts import BASELINE, pi_models, weight_label

log = logging.getLogger(__name__)

FORMATS = ("pdf", "png")
BASELINE_COLOUR = "0.45"
DATA_COLOUR = "tab:green"  # the retargeted data's own level
CONDITIONS = {  # drift figures: (title, colour, line style)
    "base_baseline": ("Baseline", BASELINE_COLOUR, "-"),
    "base_pi": ("PI, no steering", "tab:red", "--"),
    "base_pi_steering": ("PI, steering", "tab:blue", "-"),
}
AXIS_COLOURS = ("tab:blue", "tab:orange", "tab:green")  # x y z / roll pitch yaw
SIDE_COLOURS = {"left": "tab:blue", "right": "tab:orange"}
TRACKED_JOINTS = ("torso_yaw", "neck_yaw", "l_shoulder_pitch", "r_elbow")


def style(figures: FiguresParams) -> dict[str, Any]:
    """The one rc of every figure: legible at a single column's width."""
    size = figures.font_pt
    return {
        "font.size": size,
        "axes.titlesize": size,
        "axes.labelsize": size,
        "legend.fontsize": size - 1,
        "xtick.labelsize": size - 1,
        "ytick.labelsize": size - 1,
        "axes.linewidth": 0.6,
        "lines.linewidth": 1.0,
        "grid.linewidth": 0.4,
        "grid.alpha": 0.5,
        "axes.grid": True,
        "axes.spines.top": False,
        "axes.spines.right": False,
        "legend.frameon": False,
        "legend.handlelength": 1.5,
        "figure.dpi": 100,
        "savefig.dpi": figures.dpi,
        "pdf.fonttype": 42,  # TrueType: editable text in the PDF
        "svg.hashsalt": "pimann",
    }


def weight_colours(weights) -> dict[float, tuple]:
    """The same colour for the same w in every figure (viridis by rank, light end cut)."""
    ordered = sorted({float(w) for w in weights})
    cmap = matplotlib.colormaps["viridis"]
    positions = np.linspace(0.0, 0.85, max(len(ordered), 2))
    return {w: cmap(p) for w, p in zip(ordered, positions, strict=False)}


@dataclasses.dataclass
class Results:
    """What the figures read: the evaluate stage's outputs (and the simulate stage's, if any)."""

    root: Path
    metrics: pd.DataFrame
    summary: dict[str, Any]
    timeseries: dict[str, pd.DataFrame]

    @property
    def provenance(self) -> dict[str, Any]:
        return self.summary.get("provenance", {})

    @property
    def weights(self) -> list[float]:
        """Every PI weight of the study (for colours), from the provenance or the data."""
        listed = self.provenance.get("pi_weights") or []
        return sorted({float(w) for w in listed} | set(pi_models(self.metrics)))

    def data_level(self, metric: str) -> float | None:
        """The retargeted data's own level of a sliding metric (median over all clips)."""
        subset = self.summary.get("data_reference", {}).get("all") or {}
        return (subset.get("metrics", {}).get(metric) or {}).get("median")

    def model_weight(self, series: str) -> float | None:
        """The PI weight of the rollout a time series came from."""
        model = self.summary.get("timeseries", {}).get(series, {}).get("model")
        rows = self.metrics[self.metrics["model"] == model]
        return float(rows["pi_weight"].iloc[0]) if len(rows) else None


def load_results(results_dir: str | Path) -> Results:
    root = Path(results_dir)
    summary_path = root / "metrics_summary.json"
    try:
        summary = json.loads(summary_path.read_text())
    except FileNotFoundError:
        raise PimannError(summary_path, "file not found (run `dvc repro evaluate`)") from None
    except json.JSONDecodeError as error:
        raise PimannError(summary_path, f"not valid JSON ({error})") from None
    timeseries = {}
    for path in sorted((root / "timeseries").glob("*.csv")):
        table = pd.read_csv(path)
        if "time" not in table:
            raise PimannError(path, "lacks column 'time'")
        timeseries[path.stem] = table
    return Results(root, read_metrics(root / "metrics.csv"), summary, timeseries)


def _footer(fig: Figure, provenance: dict[str, Any]) -> None:
    profile = provenance.get("profile")
    if profile != "paper":
        fig.text(
            0.005, 0.005, f"profile: {profile}", fontsize=5, color="0.4", ha="left", va="bottom"
        )


def _figure(figures: FiguresParams, height: float, rows: int = 1, cols: int = 1, **kwargs):
    fig = Figure(figsize=(figures.width_in, height), layout="constrained")
    return fig, fig.subplots(rows, cols, **kwargs)


# ----------------------------------------------------------------------------- the figures


def fig_pi_weight_comparison(results: Results, figures: FiguresParams) -> Figure | None:
    """Fig. pi_weight_comparison_plot: support-foot RMSE per w (boxes over seeds), baseline line.

    Unsteered forward walking as in the paper; medians orange, means black diamonds; the
    retargeted data's own level (forward walking, metrics_summary.json) as a line, "data".
    """
    frame = results.metrics
    frame = frame[(frame["scenario"] == figures.scenario) & ~frame["steering"]]
    models = pi_models(frame)
    weights = [w for w in figures.box_weights if float(w) in models]
    if not weights:
        log.info(
            "pi_weight_comparison: no %s rollouts of %s", figures.scenario, figures.box_weights
        )
        return None
    colours = weight_colours(results.weights)
    fig, axes = _figure(figures, 2.0, 1, 2)
    for ax, kind, unit in zip(axes, ("linear", "angular"), ("m/s", "rad/s"), strict=True):
        metric = f"support_rmse_{kind}_total"
        data = [frame.loc[frame["model"] == models[float(w)], metric].dropna() for w in weights]
        boxes = ax.boxplot(
            data,
            tick_labels=[weight_label(w) for w in weights],
            patch_artist=True,
            showmeans=True,
            widths=0.6,
            medianprops={"color": "tab:orange", "linewidth": 1.2},
            meanprops={"marker": "D", "markerfacecolor": "black", "markeredgecolor": "black",
                       "markersize": 3},
            flierprops={"markersize": 2},
            boxprops={"linewidth": 0.6},
            whiskerprops={"linewidth": 0.6},
            capprops={"linewidth": 0.6},
        )  # fmt: skip
        for patch, w in zip(boxes["boxes"], weights, strict=True):
            patch.set_facecolor((*colours[float(w)][:3], 0.35))
        baseline = frame.loc[frame["model"] == BASELINE, metric].dropna()
        if len(baseline):
            ax.axhline(baseline.median(), color=BASELINE_COLOUR, ls="--", lw=1.0, label="baseline")
        if (level := results.data_level(metric)) is not None:
            ax.axhline(level, color=DATA_COLOUR, ls=":", lw=1.0, label="data")
        if ax.get_legend_handles_labels()[0]:
            ax.legend(loc="upper right")
        ax.set_xlabel("PI weight $w$")
        ax.set_title(f"{kind} ({unit})")
        ax.set_ylim(bottom=0)
    axes[0].set_ylabel("support-foot total RMSE")
    return fig


def _base_series(results: Results) -> dict[str, pd.DataFrame]:
    return {name: results.timeseries[name] for name in CONDITIONS if name in results.timeseries}


def _condition_title(results: Results, name: str) -> str:
    title = CONDITIONS[name][0]
    weight = results.model_weight(name)
    return title if name == "base_baseline" or weight is None else f"{title} ($w$={weight:g})"


def fig_base_displacement(results: Results, figures: FiguresParams) -> Figure | None:
    """Fig. base_displacement_pid_ablation: base x y z (top) and roll pitch yaw (bottom) vs time."""
    series = _base_series(results)
    if not series:
        log.info("base_displacement: no base_*.csv time series")
        return None
    fig, axes = _figure(figures, 3.0, 2, len(series), sharex=True, sharey="row", squeeze=False)
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
    axes[0, -1].legend(loc="upper left", fontsize="small")
    axes[1, -1].legend(loc="upper left", fontsize="small")
    return fig


def fig_ground_projection(results: Results, figures: FiguresParams) -> Figure | None:
    """Fig. ground_projection: base path on the ground for the three conditions."""
    series = _base_series(results)
    if not series:
        log.info("ground_projection: no base_*.csv time series")
        return None
    fig, ax = _figure(figures, 2.2)
    ax.axhline(0.0, color="black", lw=0.6, ls=":", label="desired direction")
    for name, table in series.items():
        _, colour, line = CONDITIONS[name]
        ax.plot(table["base_x"], table["base_y"], color=colour, ls=line,
                label=_condition_title(results, name))  # fmt: skip
        ax.plot(table["base_x"].iloc[-1], table["base_y"].iloc[-1], "o", color=colour, ms=2.5)
    ax.set_xlabel("$x$ (m)")
    ax.set_ylabel("$y$ (m)")
    ax.legend(loc="best")
    return fig


def _feet_series(results: Results) -> dict[float, pd.DataFrame]:
    return dict(
        sorted(
            (float(name.removeprefix("feet_w")), table)
            for name, table in results.timeseries.items()
            if name.startswith("feet_w")
        )
    )


def fig_foot_rotations(results: Results, figures: FiguresParams) -> Figure | None:
    """Fig. foot_rotations: left and right sole pitch vs time, one line per w."""
    feet = _feet_series(results)
    if not feet:
        log.info("foot_rotations: no feet_w*.csv time series")
        return None
    colours = weight_colours(results.weights)
    fig, axes = _figure(figures, 2.8, 2, 1, sharex=True, sharey=True)
    for ax, side in zip(axes, ("left", "right"), strict=True):
        for weight, table in feet.items():
            ax.plot(table["time"], np.degrees(table[f"{side}_sole_pitch"]),
                    color=colours[weight], label=f"$w$={weight:g}", lw=0.8)  # fmt: skip
        ax.set_ylabel(f"{side} foot pitch (deg)")
    axes[-1].set_xlabel("time (s)")
    axes[0].legend(ncols=min(len(feet), 5), loc="lower left", bbox_to_anchor=(0, 1.0),
                   columnspacing=0.8, handlelength=1.0)  # fmt: skip
    return fig


def fig_foot_heights(results: Results, figures: FiguresParams) -> Figure | None:
    """Fig. pi_ablation_foot_z_plot: foot heights for w=0 (top) and w=10 (bottom)."""
    feet = _feet_series(results)
    weights = [float(w) for w in figures.foot_height_weights if float(w) in feet]
    if not weights:
        log.info("foot_heights: no feet time series for w in %s", figures.foot_height_weights)
        return None
    fig, axes = _figure(figures, 1.2 + 1.0 * len(weights), len(weights), 1, sharex=True,
                        sharey=True, squeeze=False)  # fmt: skip
    for ax, weight in zip(axes[:, 0], weights, strict=True):
        table = feet[weight]
        for side, colour in SIDE_COLOURS.items():
            ax.plot(table["time"], 100 * table[f"{side}_foot_height"], color=colour, label=side)
            contact = table[f"{side}_contact"].to_numpy(bool)
            ax.fill_between(table["time"], 0, 1, where=contact, color=colour, alpha=0.12, lw=0,
                            transform=ax.get_xaxis_transform())  # fmt: skip
        ax.set_title(f"$w$={weight:g}", fontsize="small")
        ax.set_ylabel("foot height (cm)")
    axes[-1, 0].set_xlabel("time (s)")
    axes[0, 0].legend(loc="lower right", bbox_to_anchor=(1.0, 1.0), ncols=2)
    return fig


def _read_sim(path: Path) -> dict[str, np.ndarray] | None:
    """time, joints_reference, joints_measured (and joints_generated) of a simulation file."""
    if path.suffix == ".h5":
        with h5py.File(path, "r") as file:
            if not {"time", "joints_reference", "joints_measured"} <= set(file):
                return None
            names = [str(n) for n in file.attrs.get("joint_names", JOINT_NAMES)]
            out = {k: file[k][()] for k in ("time", "joints_reference", "joints_measured",
                                            "joints_generated") if k in file}  # fmt: skip
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


def fig_joint_tracking(results: Results, figures: FiguresParams) -> Figure | None:
    """Fig. joint_plots: selected upper-body joints, generated / reference / measured, in sim."""
    files = sorted((results.root / "sim").glob("*.h5")) + sorted(
        (results.root / "sim").glob("*.csv")
    )
    runs = [(p, d) for p in files if (d := _read_sim(p)) is not None]
    if not runs:
        log.info("joint_tracking: no simulation traces under %s, skipped", results.root / "sim")
        return None
    # the paper's run: the featured PI model's steered mixed scenario, else any mixed run
    featured = f"w{figures.pi_weight:g}-"
    mixed = [(p, d) for p, d in runs if "mixed" in p.stem]
    path, data = next(
        (
            (p, d)
            for p, d in mixed
            if p.stem.startswith(featured) and p.stem.endswith("mixed-steering")
        ),
        (mixed or runs)[0],
    )
    names = list(data["names"])
    joints = [j for j in TRACKED_JOINTS if j in names] or names[:4]
    fig, axes = _figure(figures, 2.8, 2, 2, sharex=True, squeeze=False)
    for ax, joint in zip(axes.flat, joints, strict=False):
        k = names.index(joint)
        for kind, colour, line in (("generated", "0.5", ":"), ("reference", "tab:blue", "--"),
                                   ("measured", "tab:orange", "-")):  # fmt: skip
            if f"joints_{kind}" in data:
                ax.plot(data["time"], np.degrees(data[f"joints_{kind}"][:, k]), color=colour,
                        ls=line, label=kind, lw=0.8)  # fmt: skip
        ax.set_title(joint.replace("_", " "), fontsize="small")
    for ax in axes[-1]:
        ax.set_xlabel("time (s)")
    for ax in axes[:, 0]:
        ax.set_ylabel("angle (deg)")
    axes[0, 0].legend(loc="best", fontsize="small")
    fig.suptitle(f"MuJoCo, offline controller ({path.stem})", fontsize="small")
    return fig


FIGURES: dict[str, Callable[[Results, FiguresParams], Figure | None]] = {
    "pi_weight_comparison": fig_pi_weight_comparison,
    "base_displacement": fig_base_displacement,
    "ground_projection": fig_ground_projection,
    "foot_rotations": fig_foot_rotations,
    "foot_heights": fig_foot_heights,
    "joint_tracking": fig_joint_tracking,
}


def save_figure(
    fig: Figure,
    out_dir: str | Path,
    name: str,
    provenance: dict[str, Any],
    formats: tuple[str, ...] = FORMATS,
) -> list[Path]:
    """`name`.pdf and `name`.png (`formats`), atomically, with the provenance in their metadata."""
    _footer(fig, provenance)
    summary = json.dumps(
        {k: provenance.get(k) for k in ("profile", "epochs", "clips", "seeds", "scenario")},
        sort_keys=True,
    )
    profile = f"profile={provenance.get('profile')}"
    metadata = {
        "pdf": {"Title": name, "Subject": f"pimann {summary}", "Keywords": profile,
                "Creator": "pimann.figures", "CreationDate": None},
        "png": {"Title": name, "Description": f"pimann {summary}", "Software": "pimann.figures"},
    }  # fmt: skip
    paths = []
    for fmt in formats:
        target = Path(out_dir) / f"{name}.{fmt}"
        with atomic_path(target) as tmp:
            fig.savefig(tmp, format=fmt, metadata=metadata[fmt])
        paths.append(target)
    return paths


def make_figures(
    results_dir: str | Path, out_dir: str | Path, figures: FiguresParams
) -> dict[str, list[Path]]:
    """Every figure whose data exists under `results_dir`, into `out_dir` as PDF and PNG."""
    results = load_results(results_dir)
    written: dict[str, list[Path]] = {}
    with matplotlib.rc_context(style(figures)):
        for name, function in FIGURES.items():
            fig = function(results, figures)
            if fig is None:
                continue
            written[name] = save_figure(fig, out_dir, name, results.provenance)
            log.info("%s -> %s", name, ", ".join(str(p) for p in written[name]))
    return written
