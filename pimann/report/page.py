"""The study on one page, results/report.html: what a researcher opens first.

Self-contained, so that it can be mailed, archived or opened from a DVC cache without the rest
of the repository and without a network: every image and video is embedded as a data: URI,
the style is inline, there is no script. From the pipeline's outputs alone (the report stage
runs after evaluate, figures, simulate and data_report):

- at a glance, first: the headline figures (`HEADLINE_FIGURES`) and a compact claims table
  (each claim's status as a coloured mark, its reason folded under it), from results/claims.md;
- the key numbers (pimann.report.key_metrics, also results/metrics.json);
- the claims table (results/claims.md);
- every figure of paper_figures/*.png;
- command following (results/command_following.md and .png);
- the MuJoCo runs (sim_summary.json) and their videos (results/sim/*.mp4, .gif);
- the data the models learn from (results/data_report.md and .png);
- the time budget: every stage's wall time (results/stage_times/, pimann.core.stage_times), also
  gathered into results/stage_times.json;
- the profile and every parameter, collapsed.

Markdown is rendered by markdown-it-py (tables on, raw HTML off: the files are ours, but a
stray `<` must not break the page). A missing input leaves its section saying which stage
makes it.
"""

from __future__ import annotations

import base64
import html
import json
import re
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import yaml

REPORT_FILE = "report.html"
MEDIA_TYPES = {".png": "image/png", ".gif": "image/gif", ".mp4": "video/mp4"}
VIDEO_SUFFIXES = (".mp4", ".gif")
HEADLINE_FIGURES = ("pi_weight_comparison", "base_displacement")  # sliding by w; drift, steering
CLAIM_MARKS = {  # claims.md status: (mark, CSS class)
    "holds": ("\u2714", "holds"), "holds within seed spread": ("\u2248", "spread"),
    "holds (model stands still)": ("\u25d0", "still"), "does not hold": ("\u2718", "fails"),
    "not comparable": ("\u2013", "na"), "reference": ("\u25cf", "reference"),
}  # fmt: skip
SIM_COLUMNS = (  # sim_summary.json run fields shown in the simulation table
    "model",
    "seed",
    "scenario",
    "steering",
    "controller",
    "success",
    "fallen",
    "fall_time_s",
    "simulated_s",
    "distance_walked_m",
    "steps",
    "foot_slip_m",
    "joint_rmse_rad",
    "zmp_error_rms_m",
)
STYLE = """
body { font-family: system-ui, sans-serif; margin: 1.5em auto; max-width: 1400px;
       padding: 0 1em; color: #222; line-height: 1.4; }
h1 { font-size: 1.6em; } h2 { border-bottom: 1px solid #ccc; margin-top: 2em; }
nav a { margin-right: 1em; }
table { border-collapse: collapse; font-size: 0.85em; display: block; overflow-x: auto;
        margin: 0.5em 0; }
th, td { border: 1px solid #ddd; padding: 2px 6px; text-align: left; vertical-align: top; }
th { background: #f3f3f3; }
.figures { display: flex; flex-wrap: wrap; gap: 1em; }
figure { margin: 0; max-width: 540px; }
figure img, figure video { width: 100%; height: auto; border: 1px solid #eee; }
figcaption { font-size: 0.85em; color: #555; }
.missing { color: #a33; }
.mark { font-weight: bold; font-size: 1.1em; } .holds { color: #1a7f37; }
.spread, .still { color: #b35900; } .fails { color: #c62828; } .na, .reference { color: #666; }
.claims td details summary { cursor: pointer; }
pre { background: #f7f7f7; padding: 0.5em; overflow-x: auto; font-size: 0.8em; }
"""


def data_uri(path: Path) -> str:
    """The file as a data: URI, by its suffix's media type."""
    media = MEDIA_TYPES[path.suffix.lower()]
    return f"data:{media};base64,{base64.b64encode(path.read_bytes()).decode('ascii')}"


def markdown_html(text: str) -> str:
    """Markdown (with GFM tables) to HTML; HTML comments (provenance lines) dropped first."""
    from markdown_it import MarkdownIt

    text = re.sub(r"<!--.*?-->", "", text, flags=re.DOTALL)
    return MarkdownIt("commonmark", {"html": False}).enable("table").render(text)


def _missing(what: str, stage: str) -> str:
    return (
        f'<p class="missing">{html.escape(what)} not found: run <code>dvc repro {stage}</code>.</p>'
    )


def _markdown_file(path: Path, stage: str, drop_title: bool = True) -> str:
    if not path.is_file():
        return _missing(path.name, stage)
    text = path.read_text()
    if drop_title:  # the section has its own heading
        text = re.sub(r"^# .*$", "", text, count=1, flags=re.MULTILINE)
    return markdown_html(text)


def _figure(path: Path, caption: str | None = None) -> str:
    caption = html.escape(caption or path.stem.replace("_", " "))
    if path.suffix.lower() == ".mp4":
        media = f'<video controls muted preload="metadata" src="{data_uri(path)}"></video>'
    else:
        media = f'<img alt="{caption}" src="{data_uri(path)}">'
    return f"<figure>{media}<figcaption>{caption}</figcaption></figure>"


def _figures(paths: Iterable[Path]) -> str:
    return '<div class="figures">' + "".join(_figure(p) for p in paths) + "</div>"


def _cell(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    return html.escape("–" if value is None else str(value))


def _table(header: list[str], rows: list[list[Any]]) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{_cell(v)}</td>" for v in row) + "</tr>" for row in rows)
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def _per_model(metrics: dict[str, Any]) -> tuple[list[str], list[list[Any]]]:
    """The per-model keys of the key numbers as one row per model: `<scenario>.<model>.<m>`
    (headline medians) and `following.<model>.<steering>` (pass shares)."""
    from pimann.report.key_metrics import HEADLINE

    rows: dict[str, dict[str, Any]] = {}
    scenario = ""
    for key, value in metrics.items():
        parts = key.split(".")
        if len(parts) == 3 and parts[2] in HEADLINE:
            scenario = parts[0]
            rows.setdefault(parts[1], {})[parts[2]] = value
        elif len(parts) == 3 and parts[0] == "following":
            rows.setdefault(parts[1], {})[f"following {parts[2]}"] = value
    columns = [*HEADLINE, "following nosteering", "following steering"]
    header = ["model", *(f"{scenario} {c}" if c in HEADLINE else c for c in columns)]
    return header, [[model, *(row.get(c) for c in columns)] for model, row in rows.items()]


def _gait(metrics: dict[str, Any]) -> str:
    """The gait per model (`<scenario>.<model>.gait_*`) with the data's level at the commanded
    speed (`data.gait_*`) as the last row; empty where the key numbers have none."""
    from pimann.report.key_metrics import DATA_GAIT, GAIT, GAIT_SHARES

    keys = [*GAIT, *GAIT_SHARES]
    rows: dict[str, dict[str, Any]] = {}
    for key, value in metrics.items():
        parts = key.split(".")
        if len(parts) == 3 and parts[2] in keys:
            rows.setdefault(parts[1], {})[parts[2]] = value
    if not rows:
        return ""
    rows["data at the commanded speed"] = {k: metrics.get(f"data.{k}") for k in DATA_GAIT}
    header = ["model", *(key.removeprefix("gait_").replace("_", " ") for key in keys)]
    return (
        "<p>The gait over the last seconds of the same test (pimann.evaluate.gait, "
        "docs/metrics.md): speed along the command over the commanded speed, swings a second "
        "(both feet), step length (m), the share of time a foot glides near the floor, the "
        "share of seeds whose cadence and step length both lie inside the data's range at the "
        "speed they achieved; the last row the retargeted data's forward walking near the "
        "commanded speed.</p>"
        + _table(header, [[model, *(row.get(k) for k in keys)] for model, row in rows.items()])
    )


def _key_numbers(metrics: dict[str, Any]) -> str:
    from pimann.report.key_metrics import STATUS_CODES

    codes = ", ".join(f"{v:g} {k}" for k, v in STATUS_CODES.items())
    header, rows = _per_model(metrics)
    others = {k: v for k, v in metrics.items() if k.startswith(("data.", "sim."))}
    return (
        "<p>Medians over the seeds, unsteered. Sliding: support-foot total RMSE, a sum over "
        "the steps; <b>sliding_linear and sliding_angular are the paper's</b> (the authors' "
        "metric, docs/metrics.md); sliding_lowest_corner, sliding_position and "
        "sliding_contact_point are ours beside it, each with the data's level (data.*). "
        "Walks: the share of seeds that walk; following: the share of motion classes passing "
        "every criterion.</p>"
        + _table(header, rows)
        + _gait(metrics)
        + "<p>"
        + ", ".join(f"{html.escape(k)} {_cell(v)}" for k, v in others.items())
        + "</p><details><summary>every key number: results/metrics.json (<code>dvc metrics "
        f"show</code>); claim status codes: {html.escape(codes)}</summary>"
        + _table(["key", "value"], [[k, v] for k, v in metrics.items()])
        + "</details>"
    )


def _simulation(results: Path) -> str:
    summary_path = results / "sim_summary.json"
    if not summary_path.is_file():
        return _missing("sim_summary.json", "simulate")
    summary = json.loads(summary_path.read_text())
    runs = summary.get("runs", {})
    rows = [[name, *(run.get(c) for c in SIM_COLUMNS[1:])] for name, run in runs.items()]
    videos = sorted(p for p in (results / "sim").glob("*") if p.suffix.lower() in VIDEO_SUFFIXES)
    table = _table(["run", *SIM_COLUMNS[1:]], rows)
    pushes = [  # per rollout, controller and direction: the largest push survived (N)
        [name, controller, direction, force]
        for name, study in (summary.get("pushes") or {}).items()
        if "failed" not in study
        for controller, row in study.items()
        for direction, force in row.items()
    ]
    if pushes:
        table += "<p>Push recovery: the largest 0.1 s push on the base survived (N).</p>"
        table += _table(["rollout", "controller", "direction", "largest push (N)"], pushes)
    if not videos:
        return table + "<p>No videos (simulate.runs marks the runs that get one).</p>"
    return table + _figures(videos)


def _stage_times(summary: dict[str, Any]) -> str:
    if not summary["stages"]:
        return (
            '<p class="missing">No stage times in results/stage_times/: <code>dvc repro</code> '
            "records every stage it runs.</p>"
        )
    rows = [
        [
            r["stage"],
            r["wall_s"] / 60.0,
            r.get("started"),
            r.get("profile"),
            r.get("cpus"),
            r.get("torch_device"),
        ]
        for r in summary["stages"]
    ]
    rows.append(["total", summary["total_wall_s"] / 60.0, None, None, None, None])
    return (
        "<p>Wall time of each stage in the run that made its outputs (a stage DVC skipped "
        "keeps its earlier record); the report stage itself is not counted.</p>"
        + _table(["stage", "wall (min)", "started (UTC)", "profile", "cores", "torch"], rows)
    )


def _params(params: Any, profile: str) -> str:
    from pimann.core.params import as_dict

    text = yaml.safe_dump(as_dict(params), sort_keys=False, default_flow_style=None, width=100)
    return (
        f"<details><summary>profile <b>{html.escape(profile)}</b>: every parameter, the "
        f"profile's overrides applied (params.yaml)</summary><pre>{html.escape(text)}</pre>"
        "</details>"
    )


def _header(summary: dict[str, Any], metrics: dict[str, Any]) -> str:
    info = summary.get("provenance") or {}
    facts = [
        f"profile <b>{html.escape(str(info.get('profile')))}</b>",
        f"{info.get('epochs')} epochs",
        f"{info.get('clips')} clips",
        f"seeds {html.escape(str(info.get('seeds')))}",
        f"scenario <code>{html.escape(str(info.get('scenario')))}</code>",
    ]
    if "claims.holding" in metrics:
        facts.append(f"<b>{metrics['claims.holding']} of {metrics['claims.total']} claims hold</b>")
    return "<p>" + ", ".join(facts) + ".</p>"


def claim_rows(text: str) -> list[dict[str, str]]:
    """The rows of results/claims.md's table as {column: cell}, `\\|` unescaped, `**` dropped."""
    rows, header = [], None
    for line in text.splitlines():
        if not line.startswith("|"):
            continue
        cells = [c.strip().replace("\\|", "|") for c in re.split(r"(?<!\\)\|", line)[1:-1]]
        if header is None:
            header = cells
        elif not set("".join(cells)) <= set("-: "):
            rows.append(dict(zip(header, (c.strip("*") for c in cells), strict=False)))
    return rows


def _claims_glance(results: Path) -> str:
    path = results / "claims.md"
    if not path.is_file():
        return _missing(path.name, "evaluate")
    body = []
    for row in claim_rows(path.read_text()):
        status = row.get("status", "")
        mark, css = CLAIM_MARKS.get(status, ("?", "na"))
        why = html.escape(row.get("why", ""))
        body.append(
            f"<tr><td>{html.escape(row.get('id', ''))}</td>"
            f"<td>{html.escape(row.get('claim (paper)', ''))}</td>"
            f'<td class="status"><span class="mark {css}" title="{html.escape(status)}">{mark}'
            f"</span> <details><summary>{html.escape(status)}</summary>{why}</details></td></tr>"
        )
    head = "<tr><th>id</th><th>claim (paper)</th><th>status (why: unfold)</th></tr>"
    return f'<table class="claims"><thead>{head}</thead><tbody>{"".join(body)}</tbody></table>'


def _glance(results: Path, figures: Path) -> str:
    """The headline figures and the compact claims table."""
    paths = [figures / f"{name}.png" for name in HEADLINE_FIGURES]
    found = [p for p in paths if p.is_file()]
    shown = _figures(found) if found else _missing("the headline figures", "figures")
    note = "<p>Each claim's status; unfold it for the reason (the numbers: further down).</p>"
    return shown + note + _claims_glance(results)


SECTIONS = (
    ("glance", "At a glance"), ("numbers", "Key numbers"), ("claims", "The paper's claims"),
    ("figures", "Figures"),
    ("following", "Command following"), ("simulation", "MuJoCo"), ("data", "The data"),
    ("time", "Time budget"), ("params", "Parameters"),
)  # fmt: skip


def build_report(
    results_dir: str | Path,
    figures_dir: str | Path,
    params: Any,
    metrics: dict[str, Any],
    stage_times: dict[str, Any] | None = None,
) -> str:
    """The whole page as one HTML string (module docstring); `metrics`: pimann.report.key_metrics,
    `stage_times`: pimann.core.stage_times.gather (default: gathered from results/stage_times/)."""
    from pimann.core.stage_times import TIMES_FOLDER, gather

    results, figures = Path(results_dir), Path(figures_dir)
    if stage_times is None:
        stage_times = gather(results / TIMES_FOLDER)
    summary_path = results / "metrics_summary.json"
    summary = json.loads(summary_path.read_text()) if summary_path.is_file() else {}
    following_png = results / "command_following.png"
    data_png = results / "data_report.png"
    paper = sorted(figures.glob("*.png"))
    others = [p for p in paper if p.stem not in HEADLINE_FIGURES]  # the headline ones lead
    bodies = {
        "glance": _glance(results, figures),
        "numbers": _key_numbers(metrics),
        "claims": _markdown_file(results / "claims.md", "evaluate"),
        "figures": (_figures(others) if others else "<p>The headline figures above.</p>")
        if paper
        else _missing("paper_figures/*.png", "figures"),
        "following": (_figures([following_png]) if following_png.is_file() else "")
        + _markdown_file(results / "command_following.md", "evaluate"),
        "simulation": _simulation(results),
        "data": _markdown_file(results / "data_report.md", "data_report")
        + (_figures([data_png]) if data_png.is_file() else ""),
        "time": _stage_times(stage_times),
        "params": _params(params, str(getattr(params, "profile", "?"))),
    }
    nav = "".join(f'<a href="#{key}">{html.escape(title)}</a>' for key, title in SECTIONS)
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        "<title>pimann study report</title>",
        f"<style>{STYLE}</style></head><body>",
        "<h1>pimann: the study on one page</h1>",
        "<!-- generated by `dvc repro report` (pimann.report.page); do not edit -->",
        _header(summary, metrics),
        f"<nav>{nav}</nav>",
    ]
    for key, title in SECTIONS:
        parts.append(f'<section id="{key}"><h2>{html.escape(title)}</h2>{bodies[key]}</section>')
    parts.append("</body></html>")
    return "\n".join(parts) + "\n"


def write_report(
    results_dir: str | Path, figures_dir: str | Path, params: Any, out: str | Path | None = None
) -> tuple[Path, Path]:
    """results/metrics.json, results/stage_times.json and results/report.html (atomic each);
    the paths of the first and the last."""
    from pimann.core.atomic import write_text_atomic
    from pimann.core.stage_times import SUMMARY_FILE, TIMES_FOLDER, write_summary
    from pimann.report.key_metrics import METRICS_FILE, key_metrics, write_key_metrics

    results = Path(results_dir)
    metrics = key_metrics(results, params)
    metrics_path = write_key_metrics(metrics, results / METRICS_FILE)
    stage_times = write_summary(results / TIMES_FOLDER, results / SUMMARY_FILE)
    report_path = Path(out) if out is not None else results / REPORT_FILE
    page = build_report(results, figures_dir, params, metrics, stage_times)
    write_text_atomic(report_path, page)
    return metrics_path, report_path
