"""What every figure shares (pimann.evaluate.figure_style): style, colours, footer, atomic
saving with the provenance in the files' metadata."""

from __future__ import annotations

import matplotlib
import numpy as np
import pytest
from PIL import Image

from pimann.core.params import load_params
from pimann.evaluate.figure_style import (
    FORMATS,
    footer,
    new_figure,
    save_figure,
    style,
    weight_colours,
)

PROVENANCE = {
    "profile": "quick",
    "epochs": 70,
    "clips": 71,
    "seeds": [0, 1],
    "scenario": "forward",
    "other": "not recorded",
}


@pytest.fixture(scope="module")
def figures():
    return load_params().figures


def test_style_follows_the_params_font_and_dpi(figures):
    rc = style(figures)
    assert rc["font.size"] == figures.font_pt and rc["legend.fontsize"] == figures.font_pt - 1
    assert rc["savefig.dpi"] == figures.dpi and rc["pdf.fonttype"] == 42
    with matplotlib.rc_context(rc):  # every key is one matplotlib knows
        assert matplotlib.rcParams["axes.spines.top"] is False


def test_a_weight_keeps_its_colour_whatever_the_other_weights_order():
    a = weight_colours([10, 0, 100, 1, 20])
    b = weight_colours([0.0, 1.0, 10.0, 20.0, 100.0])
    assert a == b and list(a) == [0.0, 1.0, 10.0, 20.0, 100.0]
    viridis = matplotlib.colormaps["viridis"]
    assert np.allclose(a[0.0], viridis(0.0)) and np.allclose(a[100.0], viridis(0.85))
    assert len({tuple(c) for c in a.values()}) == 5  # all distinct
    single = weight_colours([10])
    assert np.allclose(single[10.0], viridis(0.0))


def test_new_figure_is_a_column_wide(figures):
    fig, axes = new_figure(figures, 2.5, 2, 3)
    assert fig.get_size_inches() == pytest.approx((figures.width_in, 2.5))
    assert axes.shape == (2, 3) and fig.get_layout_engine() is not None


def test_the_footer_names_a_profile_other_than_the_papers(figures):
    fig, _ = new_figure(figures, 2.0)
    footer(fig, {"profile": "paper"})
    assert fig.texts == []
    footer(fig, {"profile": "quick"})
    assert [t.get_text() for t in fig.texts] == ["profile: quick"]


def test_saved_files_carry_the_provenance_and_appear_atomically(figures, tmp_path):
    with matplotlib.rc_context(style(figures)):  # as the figures stage saves
        fig, ax = new_figure(figures, 2.0)
        ax.plot([0, 1], [0, 1])
        paths = save_figure(fig, tmp_path, "line", PROVENANCE)
    assert [p.name for p in paths] == [f"line.{fmt}" for fmt in FORMATS]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["line.pdf", "line.png"]
    with Image.open(tmp_path / "line.png") as png:
        assert png.text["Title"] == "line" and png.text["Software"] == "pimann.report.figures"
        described = png.text["Description"]
        assert '"epochs": 70' in described and '"profile": "quick"' in described
        assert "not recorded" not in described  # only the five provenance keys
        width_px = png.size[0]
    assert width_px == pytest.approx(figures.width_in * figures.dpi, abs=2)
    pdf = (tmp_path / "line.pdf").read_bytes()
    assert pdf.startswith(b"%PDF") and b"profile=quick" in pdf
    assert "profile: quick" in [t.get_text() for t in fig.texts]
