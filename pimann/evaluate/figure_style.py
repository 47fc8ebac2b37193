"""What every figure shares: the style, the colours, the footer, saving.

Plotting alone, reading no results: the evaluate stage draws command_following.png and the
data report its figure with it, and the report's figures (pimann.report.figures) the rest.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import matplotlib
import numpy as np
from matplotlib.figure import Figure

from pimann.core.atomic import atomic_path
from pimann.core.params import FiguresParams

FORMATS = ("pdf", "png")
BASELINE_COLOUR = "0.45"
DATA_COLOUR = "tab:green"  # the retargeted data's own level


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


def footer(fig: Figure, provenance: dict[str, Any]) -> None:
    """A small "profile: ..." in the corner of any figure not made from the paper profile."""
    profile = provenance.get("profile")
    if profile != "paper":
        fig.text(
            0.005, 0.005, f"profile: {profile}", fontsize=5, color="0.4", ha="left", va="bottom"
        )


def new_figure(figures: FiguresParams, height: float, rows: int = 1, cols: int = 1, **kwargs):
    """A column-wide figure with constrained layout (legends may go `outside`) and its axes."""
    fig = Figure(figsize=(figures.width_in, height), layout="constrained")
    return fig, fig.subplots(rows, cols, **kwargs)


def save_figure(
    fig: Figure,
    out_dir: str | Path,
    name: str,
    provenance: dict[str, Any],
    formats: tuple[str, ...] = FORMATS,
) -> list[Path]:
    """`name`.pdf and `name`.png (`formats`), atomically, with the provenance in their metadata."""
    footer(fig, provenance)
    summary = json.dumps(
        {k: provenance.get(k) for k in ("profile", "epochs", "clips", "seeds", "scenario")},
        sort_keys=True,
    )
    profile = f"profile={provenance.get('profile')}"
    metadata = {
        "pdf": {
            "Title": name,
            "Subject": f"pimann {summary}",
            "Keywords": profile,
            "Creator": "pimann.report.figures",
            "CreationDate": None,
        },
        "png": {
            "Title": name,
            "Description": f"pimann {summary}",
            "Software": "pimann.report.figures",
        },
    }
    paths = []
    for fmt in formats:
        target = Path(out_dir) / f"{name}.{fmt}"
        with atomic_path(target) as tmp:
            fig.savefig(tmp, format=fmt, metadata=metadata[fmt])
        paths.append(target)
    return paths
