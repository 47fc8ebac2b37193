"""What every figure shares: the style, the colours, the results they read, saving.

Split from pimann.report.figures so that the figure functions stay readable; pimann.report.figures
re-exports these names for the modules that import them from there.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import matplotlib
import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from pimann.core.atomic import atomic_path
from pimann.core.errors import PimannError
from pimann.core.params import FiguresParams
from pimann.evaluate.evaluation import read_metrics
from pimann.generate.rollout_layout import pi_models

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
        "pdf": {"Title": name, "Subject": f"pimann {summary}", "Keywords": profile,
                "Creator": "pimann.report.figures", "CreationDate": None},
        "png": {"Title": name, "Description": f"pimann {summary}", "Software":
        "pimann.report.figures"},
    }  # fmt: skip
    paths = []
    for fmt in formats:
        target = Path(out_dir) / f"{name}.{fmt}"
        with atomic_path(target) as tmp:
            fig.savefig(tmp, format=fmt, metadata=metadata[fmt])
        paths.append(target)
    return paths
