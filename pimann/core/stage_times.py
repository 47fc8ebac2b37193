"""The study's time budget: every stage's wall time of the run that made its outputs.

`pimann.core.stage.stage_entry` records each stage run by DVC (which names it in `DVC_STAGE`,
e.g. `train@10`) as results/stage_times/<stage>.json, a plain output of that stage, so a
stage DVC skips keeps the record of the run that made its outputs. The report stage gathers
them into results/stage_times.json and a table of the report page.
"""

from __future__ import annotations

import json
import os
import sys
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from pimann.core.atomic import write_text_atomic

STAGE_ENV = "DVC_STAGE"  # set by `dvc repro` for every stage command
TIMES_FOLDER = "stage_times"  # in results/: one <stage>.json per stage
TIMES_DIR = f"results/{TIMES_FOLDER}"
SUMMARY_FILE = "stage_times.json"  # in results/, written by the report stage
# the stage that gathers the records keeps none of its own: it would gather the previous
# run's (and write into its own dependency)
GATHERING_STAGE = "report"


# what a stage tells its record beyond the wall time (e.g. the training's precision)
_NOTES: dict[str, Any] = {}


def note(key: str, value: Any) -> None:
    """Add `key: value` to this process's stage-time record (the last value of a key wins)."""
    _NOTES[key] = value


def _iso(seconds: float) -> str:
    return datetime.fromtimestamp(seconds, UTC).isoformat(timespec="seconds")


def _torch_device() -> dict[str, Any]:
    """The device torch computed on, where the stage used torch at all (never imports it)."""
    torch = sys.modules.get("torch")
    if torch is None:
        return {}
    used_cuda = torch.cuda.is_initialized()
    device = f"cuda ({torch.cuda.get_device_name()})" if used_cuda else "cpu"
    return {"torch_device": device, "torch_threads": torch.get_num_threads()}


def stage_record(
    stage: str, started: float, wall_s: float, profile: str | None = None
) -> dict[str, Any]:
    """{stage, wall_s, started, finished, profile, cpus, ...}; `started`: time.time()."""
    usable = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return {
        "stage": stage,
        "wall_s": round(wall_s, 3),
        "started": _iso(started),
        "finished": _iso(started + wall_s),
        "profile": profile,
        "cpus": usable,  # the cores the stage could run on
        "cpu_count": os.cpu_count(),  # the machine's
        **_torch_device(),
        **_NOTES,
    }


def write_record(folder: Path, record: dict[str, Any]) -> Path:
    path = Path(folder) / f"{record['stage']}.json"
    write_text_atomic(path, json.dumps(record, indent=2) + "\n")
    return path


def gather(folder: Path) -> dict[str, Any]:
    """Every record of `folder`, in the order the stages started, and their total."""
    records = [json.loads(path.read_text()) for path in sorted(Path(folder).glob("*.json"))]
    records.sort(key=lambda record: (record.get("started") or "", record.get("stage") or ""))
    return {
        "stages": records,
        "count": len(records),
        "total_wall_s": round(sum(float(record["wall_s"]) for record in records), 3),
    }


def write_summary(folder: Path, out: Path) -> dict[str, Any]:
    """results/stage_times.json from the records of `folder`; the summary."""
    summary = gather(folder)
    write_text_atomic(out, json.dumps(summary, indent=2) + "\n")
    return summary
