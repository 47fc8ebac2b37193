"""The study's time budget (pimann.core.stage_times): a stage run by DVC records its wall time, the
report gathers the records, sums them and shows them; dvc.yaml declares every record."""

from __future__ import annotations

import json
import time
from datetime import datetime

import pytest
import yaml

from pimann.core.errors import PimannError
from pimann.core.params import load_params
from pimann.core.paths import REPO_ROOT
from pimann.core.stage import stage_entry
from pimann.core.stage_times import (
    GATHERING_STAGE,
    STAGE_ENV,
    SUMMARY_FILE,
    TIMES_DIR,
    gather,
    stage_record,
    write_record,
    write_summary,
)
from pimann.report.page import build_report


def _napping(argv: list[str] | None) -> None:
    time.sleep(0.05)


def test_a_stage_records_its_wall_time(tmp_path, monkeypatch):
    monkeypatch.setenv(STAGE_ENV, "nap@10")
    main = stage_entry(times_dir=tmp_path)(_napping)
    before = time.time()
    assert main([]) == 0
    record = json.loads((tmp_path / "nap@10.json").read_text())
    assert record["stage"] == "nap@10"
    assert 0.05 <= record["wall_s"] < 5.0
    assert record["profile"] == load_params().profile
    assert record["cpus"] >= 1 and record["cpu_count"] >= record["cpus"]
    started, finished = (
        datetime.fromisoformat(record[k]).timestamp() for k in ("started", "finished")
    )
    assert int(before) - 1 <= started <= finished <= time.time() + 1


def test_no_record_by_hand_by_the_report_or_on_failure(tmp_path, monkeypatch):
    monkeypatch.delenv(STAGE_ENV, raising=False)
    assert stage_entry(times_dir=tmp_path)(_napping)([]) == 0
    assert list(tmp_path.iterdir()) == []  # not run by DVC: no record
    monkeypatch.setenv(STAGE_ENV, GATHERING_STAGE)
    assert stage_entry(times_dir=tmp_path)(_napping)([]) == 0
    assert list(tmp_path.iterdir()) == []  # it gathers the others: its own would be stale

    def failing(argv):
        raise PimannError("x.h5", "broken")

    monkeypatch.setenv(STAGE_ENV, "failing")
    assert stage_entry(times_dir=tmp_path)(failing)([]) == 1
    assert list(tmp_path.iterdir()) == []


def test_the_report_gathers_and_sums(tmp_path):
    folder = tmp_path / "results" / "stage_times"
    for stage, started, wall in (
        ("train@10", 2000.0, 600.5),
        ("retarget", 1000.0, 120.25),
        ("report_less", 3000.0, 0.25),
    ):
        write_record(folder, stage_record(stage, started, wall, "quick"))
    summary = write_summary(folder, tmp_path / "results" / SUMMARY_FILE)
    assert [r["stage"] for r in summary["stages"]] == ["retarget", "train@10", "report_less"]
    assert summary["total_wall_s"] == pytest.approx(721.0) and summary["count"] == 3
    assert json.loads((tmp_path / "results" / SUMMARY_FILE).read_text()) == summary
    page = build_report(tmp_path / "results", tmp_path / "no_figures", load_params(), {})
    assert 'id="time"' in page and "<td>train@10</td><td>10.01</td>" in page
    assert "<td>total</td><td>12.02</td>" in page  # minutes
    assert gather(tmp_path / "nothing")["total_wall_s"] == 0
    assert "No stage times" in build_report(tmp_path, tmp_path, load_params(), {})


def test_dvc_yaml_declares_every_record():
    stages = yaml.safe_load((REPO_ROOT / "dvc.yaml").read_text())["stages"]
    for name, stage in stages.items():
        outs = [next(iter(o)) if isinstance(o, dict) else o for o in stage["outs"]]
        if name == GATHERING_STAGE:
            assert TIMES_DIR in stage["deps"] and f"results/{SUMMARY_FILE}" in outs
            continue
        record = f"{name}@${{item.w}}" if "matrix" in stage else name
        assert f"{TIMES_DIR}/{record}.json" in outs, name
        if name.startswith("train"):  # cached, as every output of a training: the run-cache
            assert f"{TIMES_DIR}/{record}.json" in stage["outs"], name  # a plain entry
            continue
        (entry,) = [o for o in stage["outs"] if isinstance(o, dict) and TIMES_DIR in next(iter(o))]
        assert next(iter(entry.values())) == {"cache": False}  # plain: kept in git
