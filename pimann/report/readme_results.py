"""The README's results at a glance: the block between `RESULTS_BEGIN` and `RESULTS_END` in
README.md, rewritten by the report stage from results/metrics.json (pimann.report.key_metrics).

Only the block changes, atomically (pimann.core.atomic); a rewrite from the same numbers is
byte-identical; a README without both markers, in order, is an error of one line. README.md
is tracked by git, so it is a side effect of the report stage, not one of its DVC outs.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from pimann.core.errors import PimannError

RESULTS_BEGIN = "<!-- results:begin (written by `dvc repro report` from results/metrics.json) -->"
RESULTS_END = "<!-- results:end -->"


def _value(value: Any, digits: int = 3) -> str:
    if value is None:
        return "–"
    if isinstance(value, float):
        return f"{value:.{digits}g}"
    return str(value)


# the sliding columns of the table, as the key metrics name them (pimann.report.key_metrics)
SLIDING = (
    "sliding_linear",
    "sliding_angular",
    "sliding_lowest_corner",
    "sliding_position",
    "sliding_contact_point",
)


def _models(metrics: dict[str, Any]) -> list[str]:
    """Model labels found in the keys: the baseline first, then the PI models by weight."""
    found: list[str] = []
    for key in metrics:
        parts = key.split(".")
        per_model = parts[0] == "following" or parts[-1] == "sliding_linear"
        if len(parts) == 3 and per_model and parts[1] not in found:
            found.append(parts[1])

    def order(model: str) -> tuple[int, float]:
        if model in ("adherent", "baseline"):
            return (0, float(model == "baseline"))
        try:
            return (1, float(model.lstrip("w")))
        except ValueError:
            return (2, 0.0)

    return sorted(found, key=order)


def results_block(metrics: dict[str, Any]) -> str:
    """The Markdown table (and its one-line summary) the README shows, without the markers."""
    scenario = next(
        (k.split(".")[0] for k in metrics if k.endswith(".sliding_linear") and k.count(".") == 2),
        "forward",
    )
    lines = [
        f"Median over the seeds of the `{scenario}` scenario, unsteered. Sliding: support-foot "
        "RMSE summed over the steps; **paper**: the authors' metric, linear / angular; ours "
        "beside (linear): the lowest-corner rule without the lag, the position level, the "
        "contact point. Walks: share of seeds that walk; following: share of motion classes "
        "whose every command-following criterion passes, held-out clips, unsteered / steered.",
        "",
        "| model | paper linear | paper angular | lowest corner | position | contact point "
        "| walks | following | following steered |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for model in _models(metrics):
        if model == "data":
            continue
        cells = [
            *(metrics.get(f"{scenario}.{model}.{key}") for key in SLIDING),
            metrics.get(f"{scenario}.{model}.walks"),
            metrics.get(f"following.{model}.nosteering"),
            metrics.get(f"following.{model}.steering"),
        ]
        lines.append(f"| {model} | " + " | ".join(_value(c) for c in cells) + " |")
    data = " | ".join(_value(metrics.get(f"data.{key}")) for key in SLIDING)
    lines.append(f"| retargeted data | {data} | – | – | – |")
    lines.append("")
    facts = []
    if "claims.holding" in metrics:
        facts.append(f"{metrics['claims.holding']} of {metrics.get('claims.total')} claims hold")
    share = metrics.get("sim.success_share")
    if "sim.runs" in metrics and isinstance(share, int | float):
        facts.append(f"MuJoCo: {share:.0%} of {_value(metrics['sim.runs'])} runs succeed")
    if "epochs" in metrics:
        facts.append(f"{_value(metrics['epochs'])} epochs")
    lines.append("; ".join(facts) + ".")
    return "\n".join(lines)


def replace_block(text: str, block: str, where: str = "README.md") -> str:
    """`text` with the lines between the markers replaced by `block`; the rest untouched."""
    begin, end = text.find(RESULTS_BEGIN), text.find(RESULTS_END)
    if begin < 0 or end < 0 or end < begin:
        raise PimannError(
            where,
            f"the results markers {RESULTS_BEGIN!r} ... {RESULTS_END!r} are missing or out "
            "of order",
        )
    head = text[: begin + len(RESULTS_BEGIN)]
    return f"{head}\n{block.strip()}\n{text[end:]}"


def write_readme_results(readme: str | Path, metrics: dict[str, Any]) -> bool:
    """Rewrite the README's results block from `metrics`, atomically; whether it changed."""
    from pimann.core.atomic import write_text_atomic

    readme = Path(readme)
    text = readme.read_text()
    new = replace_block(text, results_block(metrics), where=str(readme))
    if new == text:
        return False
    write_text_atomic(readme, new)
    return True
