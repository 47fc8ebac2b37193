"""Figures from a crafted results/ folder: every figure is written as PDF and PNG,
records its provenance, and a figure whose data is missing is skipped."""

from __future__ import annotations

import dataclasses
import logging

import h5py
import numpy as np
import pytest
from builders import (
    REFERENCE,
    crafted_results,  # noqa: F401
)

from pimann.core.params import load_params
from pimann.core.robot import JOINT_NAMES
from pimann.report.figures import (
    FIGURES,
    draw,
    fig_foot_heights,
    load_results,
    make_figures,
    save_figure,
)


@pytest.fixture(scope="module")
def params():
    return load_params()


def test_every_figure_is_written_with_provenance(params, tmp_path):
    results = crafted_results(tmp_path / "results", params)
    out = tmp_path / "figures"
    written = make_figures(results, out, params.figures, params.evaluate)
    assert set(written) == set(FIGURES)
    for name in FIGURES:
        pdf, png = (out / f"{name}.{fmt}" for fmt in ("pdf", "png"))
        assert pdf.read_bytes().startswith(b"%PDF") and pdf.stat().st_size > 2000, name
        assert png.read_bytes().startswith(b"\x89PNG") and png.stat().st_size > 2000, name
        assert b"profile=quick" in pdf.read_bytes(), name  # PDF Info dictionary
        assert b"profile" in png.read_bytes(), name  # PNG text chunk
    assert not list(out.glob(".*"))  # no temporary left behind


def test_footer_only_when_not_the_paper_profile(params, tmp_path):
    with_quick = load_results(crafted_results(tmp_path / "quick", params, "quick"))
    with_paper = load_results(crafted_results(tmp_path / "paper", params, "paper"))
    for results, expected in ((with_quick, ["profile: quick"]), (with_paper, [])):
        fig = fig_foot_heights(results, params.figures, params.evaluate)
        save_figure(fig, tmp_path / f"out_{results.provenance['profile']}", "f", results.provenance)
        assert [t.get_text() for t in fig.texts] == expected
        assert fig.get_size_inches()[0] == pytest.approx(params.figures.width_in)


def test_missing_data_skips_the_figure(params, tmp_path, caplog):
    results = crafted_results(tmp_path / "results", params, sim=False)
    for path in (results / "timeseries").glob("feet_*.csv"):
        path.unlink()
    caplog.set_level(logging.INFO, logger="pimann.report.figures")
    written = make_figures(results, tmp_path / "out", params.figures, params.evaluate)
    assert set(written) == set(FIGURES) - {"joint_tracking", "foot_rotations", "foot_heights"}
    assert "joint_tracking: no simulation traces" in caplog.text


def test_box_plot_shows_each_weight_and_the_baseline(params, tmp_path):
    results = load_results(crafted_results(tmp_path / "results", params))
    fig = FIGURES["pi_weight_comparison"](results, params.figures, params.evaluate)
    linear = fig.axes[0]
    labels = [t.get_text() for t in linear.get_xticklabels()]
    assert labels == [f"{w:g}" for w in params.evaluate.box_weights]
    baseline = [line for line in linear.get_lines() if line.get_label() == "baseline"]
    frame = results.metrics
    rows = (frame["model"] == "baseline") & ~frame["steering"]
    expected = np.median(frame.loc[rows, "support_rmse_paper_linear_total"])
    assert baseline and baseline[0].get_ydata()[0] == pytest.approx(expected)


def test_box_plot_shows_the_data_level(params, tmp_path):
    results = load_results(crafted_results(tmp_path / "results", params))
    fig = FIGURES["pi_weight_comparison"](results, params.figures, params.evaluate)
    for ax, paper in zip(fig.axes, (22.88, 17.74), strict=True):  # the paper's baseline
        lines = [line for line in ax.get_lines() if line.get_label() == "paper's baseline"]
        assert len(lines) == 1 and lines[0].get_ydata()[0] == paper
    for ax, metric in zip(fig.axes, ("linear", "angular"), strict=True):
        lines = [line for line in ax.get_lines() if line.get_label() == "data"]
        expected = REFERENCE["all"]["metrics"][f"support_rmse_paper_{metric}_total"]["median"]
        assert len(lines) == 1 and lines[0].get_ydata()[0] == pytest.approx(expected)
    assert "data" in [t.get_text() for t in fig.legends[0].get_texts()]
    results = load_results(crafted_results(tmp_path / "bare", params, data=False))
    fig = FIGURES["pi_weight_comparison"](results, params.figures, params.evaluate)
    assert not [line for line in fig.axes[0].get_lines() if line.get_label() == "data"]


def test_figures_follow_params(params, tmp_path):
    results = load_results(crafted_results(tmp_path / "results", params))
    wide = dataclasses.replace(params.figures, width_in=7.0)
    one = dataclasses.replace(params.evaluate, foot_height_weights=[1.0])
    fig = fig_foot_heights(results, wide, one)
    assert fig.get_size_inches()[0] == pytest.approx(7.0) and len(fig.axes) == 1


def test_legends_sit_outside_the_axes(params, tmp_path):
    """No legend inside an axes (they covered the data); one figure legend each instead."""
    results = load_results(crafted_results(tmp_path / "results", params))
    for name in FIGURES:
        fig = draw(name, results, params.figures, params.evaluate)
        assert all(ax.get_legend() is None for ax in fig.axes), name
        assert len(fig.legends) == 1, name


def test_rmse_axis_says_what_is_summed(params, tmp_path):
    results = load_results(crafted_results(tmp_path / "results", params))
    results.metrics["frames"] = 501  # metrics.csv's column: 10 s at 50 Hz, both ends
    fig = FIGURES["pi_weight_comparison"](results, params.figures, params.evaluate)
    label = fig.axes[0].get_ylabel().replace("\n", " ")
    assert label == "total RMSE: sum of per-step RMS over 500 steps"
    assert [ax.get_title() for ax in fig.axes] == [
        "linear (m/s, summed)",
        "angular (rad/s, summed)",
    ]


def test_contact_shading_and_reference_trace_are_visible(params, tmp_path):
    results = load_results(crafted_results(tmp_path / "results", params))
    heights = FIGURES["foot_heights"](results, params.figures, params.evaluate)
    labels = [t.get_text() for t in heights.legends[0].get_texts()]
    assert labels == ["left", "right", "left in contact", "right in contact"]
    tracking = FIGURES["joint_tracking"](results, params.figures, params.evaluate)
    order = {line.get_label(): line.get_zorder() for line in tracking.axes[0].get_lines()}
    assert order["reference"] > order["measured"]  # the reference is drawn over the measured


def test_foot_rotation_labels_do_not_collide(params, tmp_path):
    results = load_results(crafted_results(tmp_path / "results", params))
    fig = FIGURES["foot_rotations"](results, params.figures, params.evaluate)
    assert [ax.get_ylabel() for ax in fig.axes] == ["", ""]
    assert [ax.get_title() for ax in fig.axes] == ["left foot", "right foot"]


def test_joint_tracking_sets_the_online_run_beside_the_offline_one(params, tmp_path):
    import shutil

    root = crafted_results(tmp_path / "results", params)
    sim = root / "sim"
    shutil.copy(sim / "mixed.h5", sim / "w10-0-mixed-steering.h5")
    with (
        h5py.File(sim / "mixed.h5", "r") as source,
        h5py.File(sim / "w10-0-mixed-steering-online.h5", "w") as file,
    ):
        for key in ("time", "joints_reference", "joints_generated"):
            file[key] = source[key][()]
        file["joints_measured"] = source["joints_reference"][()] + 0.05  # tracks worse
        file.attrs["joint_names"] = list(JOINT_NAMES)
    fig = FIGURES["joint_tracking"](load_results(root), params.figures, params.evaluate)
    titles = [ax.get_title() for ax in fig.axes]
    assert len(titles) == 8 and titles[0].endswith(", offline") and titles[1].endswith(", online")
    assert "offline and online" in fig._suptitle.get_text()
    measured = [line for line in fig.axes[1].get_lines() if line.get_label() == "measured"][0]
    reference = [line for line in fig.axes[1].get_lines() if line.get_label() == "reference"][0]
    gap = np.abs(measured.get_ydata() - reference.get_ydata()).max()
    assert gap == pytest.approx(np.degrees(0.05), rel=1e-6)  # the online run's own traces


# --- what the paper's figures draw: series, labels and data read back from the artists ------


def test_box_plot_draws_one_box_per_weight_at_the_seed_median(params, tmp_path):
    results = load_results(crafted_results(tmp_path / "results", params))
    fig = FIGURES["pi_weight_comparison"](results, params.figures, params.evaluate)
    frame = results.metrics
    unsteered = frame[(frame["scenario"] == params.evaluate.scenario) & ~frame["steering"]]
    for ax, kind in zip(fig.axes, ("linear", "angular"), strict=True):
        medians = [line for line in ax.get_lines() if line.get_color() == "tab:orange"]
        assert len(medians) == len(params.evaluate.box_weights) == len(ax.patches)
        for line, weight in zip(medians, params.evaluate.box_weights, strict=True):
            model = unsteered["model"] == f"w{weight:g}"  # not the baseline (its w is 0 too)
            seeds = unsteered.loc[model, f"support_rmse_paper_{kind}_total"]
            assert line.get_ydata()[0] == pytest.approx(np.median(seeds))
        assert ax.get_xlabel() == "PI weight $w$" and ax.get_ylim()[0] == 0


def test_base_displacement_draws_three_axes_per_condition_from_the_time_series(params, tmp_path):
    results = load_results(crafted_results(tmp_path / "results", params))
    fig = FIGURES["base_displacement"](results, params.figures, params.evaluate)
    names = ("base_baseline", "base_pi", "base_pi_steering")
    assert len(fig.axes) == 2 * len(names)  # positions on top, orientations below
    top, bottom = fig.axes[: len(names)], fig.axes[len(names) :]
    # subplots come row by row: axes[k] is condition k's positions, axes[3 + k] its angles
    assert top[0].get_ylabel() == "position (m)" and bottom[0].get_ylabel() == "orientation (rad)"
    assert all(ax.get_xlabel() == "time (s)" for ax in bottom)
    for k, name in enumerate(names):
        table = results.timeseries[name]
        lines = {line.get_label(): line for line in top[k].get_lines()}
        angles = {line.get_label(): line for line in bottom[k].get_lines()}
        assert sorted(lines) == ["x", "y", "z"] and sorted(angles) == ["pitch", "roll", "yaw"]
        assert np.allclose(lines["y"].get_xdata(), table["time"])
        assert np.allclose(lines["y"].get_ydata(), table["base_y"])
        assert np.allclose(angles["yaw"].get_ydata(), table["base_yaw"])
    assert "($w$=10)" in top[1].get_title()  # the PI model's weight, from metrics.csv


def test_ground_projection_draws_each_conditions_path_and_the_desired_line(params, tmp_path):
    results = load_results(crafted_results(tmp_path / "results", params))
    fig = FIGURES["ground_projection"](results, params.figures, params.evaluate)
    (ax,) = fig.axes
    paths = [line for line in ax.get_lines() if not line.get_label().startswith("_")]
    assert len(paths) == 4  # the desired direction and three conditions (end dots unlabelled)
    desired = next(line for line in paths if line.get_label() == "desired direction")
    assert np.allclose(desired.get_ydata(), 0.0)
    drawn = sorted((line.get_xdata()[-1], line.get_ydata()[-1]) for line in paths[1:])
    tables = [results.timeseries[n] for n in ("base_baseline", "base_pi", "base_pi_steering")]
    expected = sorted((t["base_x"].iloc[-1], t["base_y"].iloc[-1]) for t in tables)
    assert np.allclose(drawn, expected)
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("$x$ (m)", "$y$ (m)")


def test_foot_figures_draw_degrees_and_centimetres_of_every_weight(params, tmp_path):
    results = load_results(crafted_results(tmp_path / "results", params))
    rotations = FIGURES["foot_rotations"](results, params.figures, params.evaluate)
    feet = {w: results.timeseries[f"feet_w{w}"] for w in (0, 1, 10, 20, 100)}
    for ax, side in zip(rotations.axes, ("left", "right"), strict=True):
        lines = ax.get_lines()
        assert [line.get_label() for line in lines] == [f"$w$={w:g}" for w in feet]
        for line, table in zip(lines, feet.values(), strict=True):
            assert np.allclose(line.get_ydata(), np.degrees(table[f"{side}_sole_pitch"]))
    # the crafted pitch is 0.002 w rad: the drawn peaks grow with w, at most 0.2 rad = 11.5 deg
    peaks = [np.abs(line.get_ydata()).max() for line in rotations.axes[0].get_lines()]
    assert peaks == sorted(peaks) and 11.0 < peaks[-1] <= np.degrees(0.2)
    heights = FIGURES["foot_heights"](results, params.figures, params.evaluate)
    weights = [float(w) for w in params.evaluate.foot_height_weights]
    assert [ax.get_title() for ax in heights.axes] == [f"$w$={w:g}" for w in weights]
    for ax, weight in zip(heights.axes, weights, strict=True):
        table = results.timeseries[f"feet_w{weight:g}"]
        left = next(line for line in ax.get_lines() if line.get_label() == "left")
        assert np.allclose(left.get_ydata(), 100 * table["left_foot_height"])  # cm
        assert len(ax.collections) == 2  # each foot's contact shading
        assert ax.get_ylabel() == "foot height (cm)"
