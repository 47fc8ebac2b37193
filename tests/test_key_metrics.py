"""The study's key numbers (pimann.report.key_metrics): results/metrics.json, the pipeline's only
DVC
metrics, flat and at most `MAX_VALUES` values, from a crafted results/ folder."""

from __future__ import annotations

import json

import pytest
import yaml
from builders import (
    AGREEING,
    REFERENCE,
    SCENARIO,
    SIM_SUMMARY,  # noqa: F401
    crafted_results,
    crafted_rows,
)

from pimann.core.errors import PimannError
from pimann.core.params import load_params
from pimann.core.paths import REPO_ROOT
from pimann.evaluate import command_following_measures as cf
from pimann.evaluate.claims import HOLDS, evaluate_claims
from pimann.evaluate.evaluation_results import read_metrics
from pimann.report.key_metrics import (
    MAX_VALUES,
    STATUS_CODES,
    key_metrics,
    sim_metrics,
    write_key_metrics,
)


@pytest.fixture(scope="module")
def params():
    return load_params()


@pytest.fixture(scope="module")
def results(params, tmp_path_factory):
    root = crafted_results(tmp_path_factory.mktemp("study") / "results", params)
    crafted_rows().to_csv(root / "command_following.csv", index=False)
    (root / "sim_summary.json").write_text(json.dumps(SIM_SUMMARY))
    return root


def test_key_metrics_are_flat_and_few(params, results, tmp_path):
    metrics = key_metrics(results, params)
    assert len(metrics) <= MAX_VALUES
    assert all(isinstance(k, str) for k in metrics)
    assert all(v is None or isinstance(v, int | float) for v in metrics.values())
    path = write_key_metrics(metrics, tmp_path / "metrics.json")
    assert json.loads(path.read_text()) == metrics  # strict JSON: no NaN


def test_key_metrics_values(params, results):
    metrics = key_metrics(results, params)
    claims = evaluate_claims(
        read_metrics(results / "metrics.csv"), params.evaluate, params.train.pi_gradient
    )
    assert metrics["claims.total"] == len(claims) == 14
    assert metrics["claims.holding"] == sum(c.status == HOLDS for c in claims) > 0
    for claim in claims:
        assert metrics[f"claim.{claim.id}"] == STATUS_CODES[claim.status]
    for model in ("baseline", "w10"):  # crafted seeds: the median seed has the value itself
        for key, column in (
            ("sliding_linear", "paper_linear"),
            ("sliding_lowest_corner", "linear"),
        ):
            expected = AGREEING[f"support_rmse_{column}_total"][model]
            assert metrics[f"{SCENARIO}.{model}.{key}"] == pytest.approx(expected)
    assert metrics[f"{SCENARIO}.w100.walks"] == 0.0 and metrics[f"{SCENARIO}.w10.walks"] == 1.0
    assert metrics[f"{SCENARIO}.w10.steering.drift_yaw"] == pytest.approx(0.02)
    data = REFERENCE["all"]["metrics"]
    assert metrics["data.sliding_angular"] == pytest.approx(
        data["support_rmse_paper_angular_total"]["median"]
    )
    assert metrics["data.sliding_contact_point"] == pytest.approx(
        data["support_rmse_contact_point_total"]["median"]
    )
    summary = cf.summarise_following(crafted_rows())
    steered = summary[(summary["model"] == "w10") & summary["steering"]]
    assert metrics["following.w10.steering"] == pytest.approx(steered["passes"].mean())
    assert (metrics["sim.runs"], metrics["sim.success_share"], metrics["sim.fallen"]) == (2, 0.5, 1)


def test_missing_parts_are_left_out(params, results, tmp_path):
    assert sim_metrics(None) == {}
    bare = tmp_path / "bare"
    bare.mkdir()
    for name in ("metrics.csv", "metrics_summary.json"):
        (bare / name).write_bytes((results / name).read_bytes())
    metrics = key_metrics(bare, params)
    assert not any(k.startswith(("following.", "sim.")) for k in metrics)


def test_write_refuses_nesting_and_too_many(tmp_path):
    with pytest.raises(PimannError, match="flat"):
        write_key_metrics({"a": {"b": 1}}, tmp_path / "m.json")
    with pytest.raises(PimannError, match="flat"):
        write_key_metrics({f"k{i}": i for i in range(MAX_VALUES + 1)}, tmp_path / "m.json")


# ----------------------------------------------------------------------------- dvc.yaml


def _declared(kind: str) -> dict[str, list[str]]:
    """{stage: paths} declared under `kind` (metrics, plots) in dvc.yaml, top level as ''."""
    pipeline = yaml.safe_load((REPO_ROOT / "dvc.yaml").read_text())
    found: dict[str, list[str]] = {}
    for name, stage in pipeline["stages"].items():
        for entry in stage.get(kind) or []:
            found.setdefault(name, []).append(
                next(iter(entry)) if isinstance(entry, dict) else entry
            )
    for entry in pipeline.get(kind) or []:
        found.setdefault("", []).append(next(iter(entry)) if isinstance(entry, dict) else entry)
    return found


def test_no_stage_but_report_declares_metrics():
    assert _declared("metrics") == {"report": ["results/metrics.json"]}


def test_top_level_plots_name_their_axes():
    pipeline = yaml.safe_load((REPO_ROOT / "dvc.yaml").read_text())
    plots = pipeline["plots"]
    assert len(plots) >= 10
    for entry in plots:
        ((title, spec),) = entry.items()
        assert {"x", "y", "template", "x_label", "y_label"} <= set(spec), title
        assert isinstance(spec["y"], dict) and spec["y"], title  # file: column(s)
        for path in spec["y"]:
            assert path.startswith("results/"), (title, path)


def test_walks_is_the_share_of_the_seeds_not_their_median(params, results, tmp_path):
    """Two of three seeds walking is 2/3, where a median would say 1."""
    import shutil

    import pandas as pd

    crafted = shutil.copytree(results, tmp_path / "results")
    frame = read_metrics(crafted / "metrics.csv")
    w10 = (frame["model"] == "w10") & (frame["scenario"] == SCENARIO) & ~frame["steering"]
    first = frame[w10].iloc[[0]].assign(walks=True)
    more = first.iloc[[0, 0]].assign(seed=[90, 91], walks=[True, False])
    frame = pd.concat([frame[~w10], first, more], ignore_index=True)
    frame.to_csv(crafted / "metrics.csv", index=False)
    assert key_metrics(crafted, params)[f"{SCENARIO}.w10.walks"] == pytest.approx(2 / 3, abs=1e-3)
