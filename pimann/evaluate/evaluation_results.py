"""Reading the evaluate stage's results back: metrics.csv, metrics_summary.json and the time
series, for the report's figures and key metrics.

Below pimann.report so that the figures read results without importing the evaluate stage's
runner (which draws command_following.png with pimann.evaluate.figure_style): no circle.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import pandas as pd

from pimann.core.errors import PimannError
from pimann.core.rollout_files import pi_models

KEY_COLUMNS = ["model", "variant", "pi_weight", "seed", "scenario", "steering"]


def read_metrics(path: str | Path) -> pd.DataFrame:
    """metrics.csv back into a frame."""
    path = Path(path)
    if not path.is_file():
        raise PimannError(path, "file not found (run `dvc repro evaluate`)")
    frame = pd.read_csv(path)
    missing = [c for c in KEY_COLUMNS if c not in frame]
    if missing:
        raise PimannError(path, f"lacks column {missing[0]!r}")
    frame["steering"] = frame["steering"].astype(str).str.lower() == "true"
    return frame


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
