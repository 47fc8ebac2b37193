"""Evaluation: seed statistics, results and provenance, and the rollout -> evaluate
path end to end on tiny real models (real MANN, generate, pinocchio)."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pandas as pd
import pytest
from builders import (
    REFERENCE,
    SCENARIO,
    benchmark_collection,
    crafted_metrics,
    tiny_models,  # noqa: F401
)

from pimann.core.errors import PimannError
from pimann.core.params import load_params
from pimann.core.rollout_files import BASELINE, read_script, select_rows
from pimann.core.trajectory import read_trajectory
from pimann.evaluate.claims import claims_markdown
from pimann.evaluate.command_following_measures import summarise_following
from pimann.evaluate.evaluation import (
    evaluate_all,
    provenance,
    representative_seed,
    summarise,
    write_results,
)
from pimann.evaluate.evaluation_results import read_metrics
from pimann.evaluate.metrics import trajectory_metrics
from pimann.generate.rollouts import run_rollouts
from pimann.report.key_metrics import following_metrics


@pytest.fixture(scope="module")
def params():
    return load_params()


def test_summary_matches_numpy_on_crafted_data():
    rng = np.random.default_rng(7)
    frame = crafted_metrics()
    frame["support_rmse_linear_total"] = rng.uniform(1, 30, len(frame))
    summary = summarise(frame)
    for (model, steering), group in frame.groupby(["model", "steering"]):
        label = "steering" if steering else "nosteering"
        stats = summary[SCENARIO][label][model]["metrics"]["support_rmse_linear_total"]
        values = group["support_rmse_linear_total"].to_numpy()
        q1, q3 = np.percentile(values, [25, 75])
        assert stats["median"] == pytest.approx(np.median(values))
        assert stats["iqr"] == pytest.approx(q3 - q1)
        assert stats["min"] == pytest.approx(values.min())
        assert stats["max"] == pytest.approx(values.max())
        assert stats["n"] == 5
        walks = summary[SCENARIO][label][model]["metrics"]["walks"]
        assert walks["mean"] == pytest.approx(group["walks"].mean())


def test_representative_seed_is_the_median_one():
    frame = crafted_metrics()
    rows = (frame["model"] == "w10") & ~frame["steering"]
    frame.loc[rows, "support_rmse_paper_linear_total"] = [5.0, 1.0, 9.0, 4.0, 3.0]
    assert representative_seed(frame, "w10", SCENARIO, False) == 3  # seed 3: 4.0, the median
    assert representative_seed(frame, "nope", SCENARIO, False) is None


def test_results_record_provenance(params, tmp_path):
    info = provenance(params)
    claims = write_results(crafted_metrics(), tmp_path, params, info, None, REFERENCE)
    summary = json.loads((tmp_path / "metrics_summary.json").read_text())
    assert summary["data_reference"] == REFERENCE
    assert summary["provenance"]["profile"] == params.profile
    assert summary["provenance"]["params"]["evaluate"]["pi_weight"] == params.evaluate.pi_weight
    text = (tmp_path / "claims.md").read_text()
    assert f"Profile **{params.profile}**" in text and '"profile": ' in text.splitlines()[1]
    assert text.count("| C") == len(claims) and "**holds**" in text
    back = read_metrics(tmp_path / "metrics.csv")
    assert set(back["profile"]) == {params.profile} and len(back) == len(crafted_metrics())
    assert back["steering"].dtype == bool and back["steering"].sum() == len(back) // 2
    assert claims_markdown(claims, info, REFERENCE) == text and "| D | data" in text
    for metric in ("support_rmse_linear_world_total", "support_rmse_linear_position_total"):
        assert metric in summary["summary"][SCENARIO]["nosteering"]["w10"]["metrics"]


def test_rollout_and_evaluate_end_to_end(params, tmp_path):
    from pimann.core.params import MotionSegment

    # the data's level: one clip at 0.5 m/s (5 s of forward walking), one standing; the test
    # clips (benchmark scripts): a 2 s walk at 0.4 m/s and its 'mirror'; the training clips'
    # benchmark: one per class, a 2 s walk (d; a is longer than any script run) and the stand (b)
    data = benchmark_collection(tmp_path / "walking.h5")
    short = dataclasses.replace(
        params,
        features=dataclasses.replace(params.features, input=str(data), split_seed=0),
        rollout=dataclasses.replace(
            params.rollout,
            scenarios={"short": [MotionSegment(0.6, 0.5, 0.0, 0.0)]},
            scenario_names=["short"],
            benchmark_clips=True,
            benchmark_train_clips=1,
            protocols={},  # tests/test_rollouts.py rolls a protocol out
        ),
        evaluate=dataclasses.replace(params.evaluate, scenario="short"),
    )
    tiny_models(tmp_path / "models" / "w10", 10.0, "full", [0, 1])
    tiny_models(tmp_path / "models" / "baseline", 0.0, "ground_projected", [0])
    rollouts = tmp_path / "rollouts"
    for name in ("w10", "baseline"):
        written = run_rollouts(tmp_path / "models" / name, rollouts / name, short, workers=1)
        # (short + 2 test clips + 2 training clips) x steering per seed
        assert len(written) == 2 * 5 * (2 if name == "w10" else 1)
    first = read_trajectory(rollouts / "w10" / "1" / "short-steering.h5")
    assert first.attrs["seed"] == 1 and first.attrs["pi_weight"] == 10.0
    assert read_script(first) == short.rollout.scenarios["short"]
    clip = read_trajectory(rollouts / "baseline" / "0" / "clip_c_mirror-nosteering.h5")
    script = read_script(clip)
    assert clip.attrs["scenario"] == "clip_c_mirror" and len(clip) == 100
    assert script[0].vx == pytest.approx(0.4, abs=0.01)

    results = tmp_path / "results"
    claims = evaluate_all(rollouts, results, short, workers=1, data=data)
    frame = read_metrics(results / "metrics.csv")
    assert len(frame) == 30 and set(frame["model"]) == {"w10", BASELINE}
    assert frame["model"].iloc[0] == BASELINE  # baseline rows first
    row = select_rows(frame, "short", True, model="w10", seed=1).iloc[0]
    expected = trajectory_metrics(first, None, short.evaluate, short.contacts)
    for metric in ("support_rmse_linear_total", "support_rmse_paper_linear_total"):
        assert row[metric] == pytest.approx(expected[metric], rel=1e-5)
    assert set(frame["variant"]) == {"full", "ground_projected"}
    assert row["gait_cadence"] == pytest.approx(expected["gait_cadence"])  # every row's gait
    assert frame["gait_glide_share"].notna().all() and frame["gait_command_speed"].notna().all()
    assert (frame["data_gait_windows"] == 0).all()  # the data's clips glide, never step
    assert (frame["data_gait_windows_at_speed"] == 0).all()  # nor at the speeds achieved
    assert frame["gait_in_data_range"].isna().all()
    names = sorted(p.stem for p in (results / "timeseries").glob("*.csv"))
    assert names == ["base_baseline", "base_pi", "base_pi_steering", "feet_w10"]
    base = pd.read_csv(results / "timeseries" / "base_pi.csv")
    assert list(base.columns)[:4] == ["time", "base_x", "base_y", "base_z"] and len(base) == 31
    summary = json.loads((results / "metrics_summary.json").read_text())
    assert list(summary["summary"]) == ["short"]  # the clips' rollouts: metrics.csv only
    assert summary["provenance"]["clips"] == 3 and summary["provenance"]["epochs"] == 3
    assert summary["timeseries"]["base_pi"]["model"] == "w10"
    reference = summary["data_reference"]
    assert reference["collection"] == str(data) and reference["all"]["used"] == 1
    levels = reference["all"]["metrics"]  # a glide with still joints: the position level only
    assert levels["support_rmse_linear_position_total"]["median"] == pytest.approx(
        500 * 0.5 / np.sqrt(3), rel=1e-6
    )
    assert levels["support_rmse_linear_total"]["median"] == pytest.approx(0.0, abs=1e-9)
    assert "| D | data (retargeted, forward walking)" in (results / "claims.md").read_text()
    assert {c.id for c in claims} >= {"C1", "C2", "C14"}

    following = pd.read_csv(results / "command_following.csv")
    assert len(following) == 30 + 4  # one segment per rollout, and the four clips' own
    data_rows = following[following["model"] == "data"]
    assert set(data_rows["scenario"]) == {"clip_c", "clip_c_mirror", "train_d", "train_b"}
    assert not data_rows["steering"].any() and set(data_rows["seed"]) == {0}
    walks = data_rows[~data_rows["stand"]]
    assert walks["speed_ratio"].to_numpy() == pytest.approx(1.0, abs=0.02)
    assert set(following["kind"]) == {"scenario", "clip"}
    assert set(following.loc[following["scenario"] == "short", "kind"]) == {"scenario"}
    # the training clips' scripts on the training split, the rest (test clips, named) held out
    training = following["scenario"].str.startswith("train_")
    assert set(following.loc[training, "split"]) == {"training"}
    assert set(following.loc[~training, "split"]) == {"held_out"}
    assert set(following.loc[training, "model"]) == {"data", "w10", BASELINE}
    summary = summarise_following(following)
    w10 = summary[(summary["model"] == "w10") & ~summary["steering"]]
    assert set(zip(w10["split"], w10["class"], strict=True)) == {
        ("held_out", "forward"),
        ("training", "forward"),
        ("training", "standing"),
    }
    trained = w10[(w10["split"] == "training") & (w10["class"] == "forward")].iloc[0]
    runs = following[(following["model"] == "w10") & (following["scenario"] == "train_d")]
    assert trained["seeds"] == 2 and trained["speed_ratio"] == pytest.approx(
        runs.loc[~runs["steering"], "speed_ratio"].median()
    )
    held_only = following[~training].drop(columns="split")  # the key numbers: held out only
    assert following_metrics(following) == following_metrics(held_only)
    text = (results / "command_following.md").read_text()
    assert "Profile **" in text and "| data | held_out | nosteering | forward |" in text
    assert "| data | training | nosteering | standing |" in text
    assert "| w10 (w=10) | training | steering | forward |" in text
    assert "## Named scenarios" in text and "| w10 (w=10) | steering | short |" in text
    assert (results / "command_following.png").read_bytes()[:4] == b"\x89PNG"


def test_worker_errors_reach_the_caller_with_file_and_frame(params, tmp_path):
    """A PimannError raised in a spawned worker comes back as a PimannError, not a crash."""
    from pimann.core.parallel import pool_map
    from pimann.evaluate.evaluation import _metrics_job

    missing = tmp_path / "nope.h5"
    with pytest.raises(PimannError, match="nope.h5: file not found"):
        pool_map(_metrics_job, [(missing, params.evaluate, params.contacts)] * 2, 2, "metrics")


def test_a_seed_whose_rollouts_fail_is_recorded_and_the_rest_written(params, tmp_path):
    from pimann.core.params import MotionSegment

    short = dataclasses.replace(
        params,
        rollout=dataclasses.replace(
            params.rollout,
            scenarios={"short": [MotionSegment(0.4, 0.5, 0.0, 0.0)]},
            scenario_names=["short"],
            benchmark_clips=False,
            benchmark_train_clips=0,
            protocols={},
        ),
    )
    models = tmp_path / "models" / "w10"
    tiny_models(models, 10.0, "full", [0, 1])
    broken = models / "1" / "model.pt"
    broken.write_bytes(broken.read_bytes()[:100])  # truncated
    out = tmp_path / "rollouts" / "w10"
    written = run_rollouts(models, out, short, workers=1)
    assert [p.relative_to(out).parts[0] for p in written] == ["0", "0"]  # short x 2 steering
    record = json.loads((out / "models.json").read_text())
    assert list(record["failed"]) == ["1"] and str(broken) in record["failed"]["1"]
    assert not (out / "1").exists()
    seed_zero = models / "0" / "model.pt"
    seed_zero.write_bytes(seed_zero.read_bytes()[:100])
    with pytest.raises(PimannError, match="every seed failed"):
        run_rollouts(models, tmp_path / "rollouts" / "again", short, workers=1)
    assert not (tmp_path / "rollouts" / "again").exists()
