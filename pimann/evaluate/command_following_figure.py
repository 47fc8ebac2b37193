"""The command-following figure: commanded against achieved speed per motion class.

From `pimann.evaluate.command_following_measures.summarise_following`'s table alone. One panel per
steering condition (unsteered above), bars of the achieved speed along the command (median over
seeds) per model and class, the commanded speed as a black tick over each bar and the +-25%
criterion as a grey band behind it (whiskers of adjacent bars ran together into a comb). Turning in
place is left out (no planar command: its yaw rate is in the table), as is standing (the stand
criterion is a distance), and so is the training split where the table has one (the held-out split
is the benchmark; the table carries both). Single IEEE column, legend above the panels (the profile
footer sits in the lower corner).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from pimann.core.params import FiguresParams
from pimann.core.rollout_files import BASELINE, HELD_OUT, weight_label
from pimann.evaluate.command_following_measures import SPEED_TOLERANCE
from pimann.evaluate.figure_style import BASELINE_COLOUR, weight_colours
from pimann.learn.motion_classes import CLASSES

PLOTTED_CLASSES = tuple(c for c in CLASSES if c not in ("turning_in_place", "standing"))
STEERING_TITLES = {False: "no steering", True: "steering"}
BAND_COLOUR = "0.85"  # the +-25% speed criterion behind the bars


def _models(summary: pd.DataFrame) -> dict[str, tuple[str, object]]:
    """{model: (label, colour)}: the baseline first in grey, then PI models by weight (viridis,
    as every other figure), else in the table's order."""
    names = list(dict.fromkeys(summary["model"]))
    weights: dict[str, float] = {}
    if "pi_weight" in summary:
        for name, weight in zip(summary["model"], summary["pi_weight"], strict=True):
            if name != BASELINE and pd.notna(weight):
                weights[name] = float(weight)
    colours = weight_colours(weights.values()) if weights else {}
    others = [n for n in names if n != BASELINE and n not in weights]
    cycle = dict(zip(others, (f"C{k % 10}" for k in range(len(others))), strict=True))
    ordered = [n for n in names if n == BASELINE]
    ordered += sorted(weights, key=weights.get) + others
    out = {}
    for name in ordered:
        if name == BASELINE:
            out[name] = ("baseline", BASELINE_COLOUR)
        elif name in weights:
            out[name] = (f"$w$={weight_label(weights[name])}", colours[weights[name]])
        else:
            out[name] = (name, cycle[name])
    return out


def fig_command_following(summary: pd.DataFrame, figures: FiguresParams) -> Figure | None:
    """Commanded vs achieved speed per class and model, steered and not (None: nothing to plot).

    Draw it inside `matplotlib.rc_context(pimann.evaluate.figure_style.style(figures))` as the other
    figures.
    """
    table = summary[summary["class"].isin(PLOTTED_CLASSES)]
    if "split" in table:
        table = table[table["split"] == HELD_OUT]
    if table.empty:
        return None
    classes = [c for c in PLOTTED_CLASSES if c in set(table["class"])]
    conditions = [s for s in (False, True) if s in set(table["steering"])]
    models = _models(table)
    fig = Figure(figsize=(figures.width_in, 0.6 + 1.35 * len(conditions)), layout="constrained")
    axes = np.atleast_1d(fig.subplots(len(conditions), 1, sharex=True, sharey=True))
    width = 0.8 / len(models)
    x = np.arange(len(classes))
    for ax, steering in zip(axes, conditions, strict=True):
        part = table[table["steering"] == steering].set_index(["model", "class"])
        for k, (model, (label, colour)) in enumerate(models.items()):
            offsets = x - 0.4 + (k + 0.5) * width
            rows = [part.loc[(model, c)] if (model, c) in part.index else None for c in classes]
            achieved = [np.nan if r is None else r["achieved_speed"] for r in rows]
            commanded = np.array([np.nan if r is None else r["commanded_speed"] for r in rows])
            ax.bar(
                offsets,
                2 * SPEED_TOLERANCE * commanded,
                bottom=(1 - SPEED_TOLERANCE) * commanded,
                width=width,
                color=BAND_COLOUR,
                lw=0,
                zorder=0,
            )
            ax.bar(offsets, achieved, width=width * 0.8, color=colour, label=label, zorder=2)
            ax.plot(
                offsets,
                commanded,
                ls="none",
                marker="_",
                color="black",
                zorder=3,
                markersize=max(3.0, 72 * width * figures.width_in / len(classes) * 0.8),
                markeredgewidth=1.0,
            )
        ax.axhline(0.0, color="0.3", lw=0.5)
        ax.set_title(STEERING_TITLES[bool(steering)], pad=2)
        ax.set_ylabel("speed (m/s)")
    axes[-1].set_xticks(x, [c.replace("_", " ") for c in classes])
    handles = [Patch(color=colour, label=label) for label, colour in models.values()]
    handles += [
        Line2D([], [], color="black", marker="_", ls="none", markersize=6, label="commanded"),
        Patch(color=BAND_COLOUR, label=f"\u00b1{SPEED_TOLERANCE:.0%}"),
    ]
    fig.legend(
        handles=handles,
        loc="outside upper center",
        ncols=min(4, len(handles)),
        columnspacing=1.0,
        handlelength=1.2,
    )
    return fig
