"""The data report (pimann.evaluate.data_report) as files: JSON, Markdown tables and a figure."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import matplotlib
import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from pimann.core.atomic import atomic_path, write_text_atomic
from pimann.core.params import FiguresParams
from pimann.evaluate.data_report import (
    BELOW_FLOOR,
    CLASS_COLOURS,
    GLIDE_HEIGHT,
    GLIDE_PERCENTILE,
    GLIDE_TARGET,
    MIN_CLASS_FRAMES,
    PAPER_FRAMES,
    RULES,
    TOTAL,
)
from pimann.evaluate.figure_style import BASELINE_COLOUR, style
from pimann.learn.motion_classes import CLASSES, WINDOW_S


def _cell(value: float | None, digits: int = 1) -> str:
    return "-" if value is None or not math.isfinite(value) else f"{value:.{digits}f}"


def report_table(report: dict[str, Any]) -> str:
    """The report as Markdown tables: composition, then foot metrics."""
    sources = report["sources"]
    short = ["fwd", "back", "side", "diag", "turn", "turn@0", "stand"]
    lines = [
        f"# Data report: {report['collection']} (profile {report['profile']})",
        "",
        "Minutes per motion class of the original clips (per-frame classes from the base "
        f"velocity over {WINDOW_S:g} s), clip and frame counts with mirrors, start/stop "
        "transitions.",
        "",
        "| source | " + " | ".join(short) + " | total | clips (+mirrors) | frames (+mirrors) "
        "| starts | stops |",
        "|---" * (len(short) + 6) + "|",
    ]
    for name, s in sources.items():
        minutes = [_cell(s["minutes"][c]) for c in CLASSES]
        lines.append(
            f"| {name} | " + " | ".join(minutes) + f" | {_cell(s['minutes']['total'])} "
            f"| {s['clips']} ({s['clips_with_mirrors']}) | {s['frames']} "
            f"({s['frames_with_mirrors']}) | {s['starts']} | {s['stops']} |"
        )
    authors = report["authors"]
    a = authors["minutes"]
    lines.append(
        f"| authors (labels) | {a['forward']} | {a['backward']} | {a['side']} | {a['diagonal']} "
        f"| mixed {a['mixed']} | | | {sum(a.values()):.1f} | | {authors['samples']['originals']} "
        f"({authors['samples']['with_mirrors']}) | | |"
    )
    lines += ["", "Minutes per `content` label (original clips).", ""]
    labels = sorted({k for s in sources.values() for k in s["label_minutes"]})
    lines += ["| source | " + " | ".join(labels) + " |", "|---" * (len(labels) + 1) + "|"]
    for name, s in sources.items():
        cells = [_cell(s["label_minutes"].get(k, 0.0)) for k in labels]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    baseline = authors["baseline_model_sliding"]
    lines += [
        "",
        f"Foot metrics over all clips with mirrors. Sliding: total RMSE per {PAPER_FRAMES} "
        "frames (linear m/s, angular rad/s) at the evaluate stage's velocity level (the "
        "joints' differences move the feet, the lower one held), with its contact rule (rule) and "
        "the file's flags (file); fwd: forward-walking frames only. DS: double-support "
        f"fraction of walking frames. Glide: p{GLIDE_PERCENTILE:g} horizontal speed of sole "
        f"corners within {GLIDE_HEIGHT * 1000:g} mm of the floor (target <= {GLIDE_TARGET:g} "
        "m/s), and the share above the target. L_B: the data's own physics loss.",
        "",
        "| source | slide lin rule | ang rule | lin file | ang file | fwd lin rule | "
        "fwd ang rule | fwd lin file | fwd ang file | DS rule | DS file | glide p95 | "
        "glide > target | L_B lower_sole | L_B data_contacts |",
        "|---" * 15 + "|",
    ]
    for name, s in sources.items():
        cells = []
        for rule in RULES:
            values = s["sliding"][rule] or {}
            cells += [_cell(values.get("linear")), _cell(values.get("angular"))]
        for rule in RULES:
            forward = ((s["sliding"][rule] or {}).get("per_class") or {}).get("forward") or {}
            cells += [_cell(forward.get("linear")), _cell(forward.get("angular"))]
        cells += [_cell(s["double_support"][r], 3) for r in ("evaluate_rule", "file_contacts")]
        cells += [
            _cell(s["glides"]["p95_m_s"], 3),
            _cell(s["glides"]["fraction_above_target"], 3),
            _cell(s["l_b"]["lower_sole"]["mean"], 4),
            _cell(s["l_b"]["data_contacts"]["mean"], 4),
        ]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    lines.append(
        f"| authors' baseline model | {baseline['linear']} | {baseline['angular']} |" + " |" * 13
    )
    lines += [
        "",
        f"Sliding per motion class (frames of that class only, at least {MIN_CLASS_FRAMES}), "
        "in total; linear / angular; and the double-support fraction of those frames.",
        "",
        "| class | contact rule | file flags | DS rule | DS file |",
        "|---|---|---|---|---|",
    ]
    total = sources[TOTAL]["sliding"]
    for name in CLASSES:
        cells = []
        for rule in RULES:
            values = ((total[rule] or {}).get("per_class") or {}).get(name) or {}
            cells.append(f"{_cell(values.get('linear'))} / {_cell(values.get('angular'))}")
        for rule in RULES:
            values = ((total[rule] or {}).get("per_class") or {}).get(name) or {}
            cells.append(_cell(values.get("double_support"), 3))
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    lines += [
        "",
        "The floor, over all clips with mirrors: the lowest sole corner, the share of frames "
        f"with a corner more than {BELOW_FLOOR * 1000:g} mm under the floor, and of frames "
        "with no foot down by the file's flags (flight: the retargeted base has no foot to "
        "stand on).",
        "",
        "| source | lowest corner (m) | frames below the floor | flight frames |",
        "|---|---|---|---|",
    ]
    for name, s in sources.items():
        f = s["floor"]
        cells = [
            _cell(f["lowest_corner_m"], 3),
            _cell(f["below_floor_share"], 4),
            _cell(f["flight_share"], 4),
        ]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def report_figure(report: dict[str, Any], figures: FiguresParams) -> Figure:
    """Minutes per class per source (stacked, the authors' beside) and sliding per source."""
    sources = report["sources"]
    names = list(sources)
    small = figures.font_pt - 2
    fig = Figure(figsize=(figures.width_in, 4.8), layout="constrained")
    top, bottom = fig.subplots(2, 1, height_ratios=[1.0, 1.2])
    rows = ["authors", *names]
    left = np.zeros(len(rows))
    for name in (*CLASSES, "mixed"):
        widths = np.array(
            [report["authors"]["minutes"].get(name, 0.0)]
            + [sources[s]["minutes"].get(name, 0.0) for s in names]
        )
        if not widths.any():
            continue
        label = name.replace("_", " ")
        top.barh(rows, widths, left=left, color=CLASS_COLOURS[name], label=label, height=0.6)
        left += widths
    top.invert_yaxis()
    top.set_xlabel("minutes (original clips, before mirroring)")
    top.legend(ncols=4, loc="upper center", bbox_to_anchor=(0.5, -0.32), fontsize=small)
    x = np.arange(len(names))
    for k, (kind, colour) in enumerate((("linear", "tab:blue"), ("angular", "tab:orange"))):
        for rule, hatch in (("evaluate_rule", None), ("file_contacts", "///")):
            values = [(sources[s]["sliding"][rule] or {}).get(kind) for s in names]
            offset = (2 * k + (rule == "file_contacts")) * 0.2 - 0.3
            bottom.bar(
                x + offset,
                [np.nan if v is None else v for v in values],
                width=0.2,
                color=colour,
                alpha=1.0 if hatch is None else 0.45,
                hatch=hatch,
                label=f"{kind}, {'contact rule' if hatch is None else 'file flags'}",
            )
        baseline = report["authors"]["baseline_model_sliding"][kind]
        bottom.axhline(baseline, color=colour, ls="--", lw=0.8)
    handles, labels = bottom.get_legend_handles_labels()
    handles.append(Line2D([], [], color=BASELINE_COLOUR, ls="--", lw=0.8))
    labels.append("authors' baseline model")
    bottom.legend(
        handles, labels, ncols=2, loc="upper center", bbox_to_anchor=(0.5, -0.12), fontsize=small
    )
    bottom.set_xticks(x, names)
    bottom.set_ylabel(f"sliding per {PAPER_FRAMES} frames")
    if report["profile"] != "paper":
        fig.text(0.005, 0.005, f"profile: {report['profile']}", fontsize=5, color="0.4")
    return fig


def write_report(
    report: dict[str, Any],
    json_path: str | Path,
    table_path: str | Path,
    figure_path: str | Path,
    figures: FiguresParams,
) -> None:
    """The report as JSON, the Markdown table and the PNG figure, each written atomically."""
    write_text_atomic(json_path, json.dumps(report, indent=2) + "\n")
    write_text_atomic(table_path, report_table(report))
    with matplotlib.rc_context(style(figures)):
        fig = report_figure(report, figures)
        metadata = {"Title": "data_report", "Description": f"pimann profile={report['profile']}"}
        with atomic_path(figure_path) as tmp:
            fig.savefig(tmp, format="png", metadata=metadata)
