"""The README's results block: rewritten from results/metrics.json by the report stage."""

from __future__ import annotations

import json

import pytest

from pimann.core.errors import PimannError
from pimann.core.paths import PACKAGE_CHECKOUT
from pimann.report.readme_results import (
    RESULTS_BEGIN,
    RESULTS_END,
    replace_block,
    results_block,
    write_readme_results,
)

METRICS = {
    "epochs": 70.0,
    "claims.holding": 1,
    "claims.total": 14,
    "forward.baseline.sliding_linear": 46.5,
    "forward.baseline.sliding_angular": 12.25,
    "forward.baseline.walks": 0.5,
    "forward.w10.sliding_linear": 26.29,
    "forward.w10.sliding_angular": 8.843,
    "forward.w10.walks": 0.5,
    "forward.w10.sliding_lowest_corner": 20.1,
    "forward.w1.sliding_linear": 47.92,
    "forward.w1.sliding_angular": 10.84,
    "forward.w1.walks": 1.0,
    "data.sliding_linear": 13.2,
    "data.sliding_angular": 1.45,
    "data.sliding_contact_point": 14.6,
    "following.data": 0.0,
    "following.w10.nosteering": 0.1667,
    "following.w10.steering": 0.1667,
    "sim.runs": 13,
    "sim.success_share": 0.9231,
}
README = f"# title\n\nbefore\n\n{RESULTS_BEGIN}\nold table\n{RESULTS_END}\n\nafter\n"


def test_block_is_a_table_of_the_numbers_one_row_per_model():
    block = results_block(METRICS)
    rows = [line for line in block.splitlines() if line.startswith("| ")]
    assert [r.split("|")[1].strip() for r in rows[2:]] == [
        "baseline",
        "w1",
        "w10",
        "retargeted data",
    ]
    assert "| w10 | 26.3 | 8.84 | 20.1 | – | – | 0.5 | 0.167 | 0.167 |" in rows
    assert "| w1 | 47.9 | 10.8 | – | – | – | 1 | – | – |" in rows  # no key: a dash
    assert "| retargeted data | 13.2 | 1.45 | – | – | 14.6 | – | – | – |" in rows
    assert "1 of 14 claims hold" in block and "92% of 13 runs" in block


def test_rewrite_replaces_only_the_block_and_is_idempotent(tmp_path):
    readme = tmp_path / "README.md"
    readme.write_text(README)
    assert write_readme_results(readme, METRICS)
    once = readme.read_text()
    before, rest = once.split(RESULTS_BEGIN)
    inside, after = rest.split(RESULTS_END)
    assert before == "# title\n\nbefore\n\n" and after == "\n\nafter\n"
    assert "old table" not in inside and inside.strip() == results_block(METRICS)
    assert not write_readme_results(readme, METRICS)  # same numbers: nothing to write
    assert readme.read_text() == once
    assert replace_block(once, results_block(METRICS)) == once
    changed = dict(METRICS, **{"forward.w10.sliding_linear": 99.0})
    assert write_readme_results(readme, changed)
    assert "| w10 | 99 |" in readme.read_text()
    assert readme.read_text().split(RESULTS_BEGIN)[0] == before
    assert [p.name for p in tmp_path.iterdir()] == ["README.md"]  # no temporary left


@pytest.mark.parametrize(
    "text",
    [
        "# no markers\n",
        f"{RESULTS_BEGIN}\nno end\n",
        f"{RESULTS_END}\nend first\n{RESULTS_BEGIN}\n",
    ],
)
def test_missing_markers_are_a_one_line_error(tmp_path, text):
    readme = tmp_path / "README.md"
    readme.write_text(text)
    with pytest.raises(PimannError) as error:
        write_readme_results(readme, METRICS)
    message = str(error.value)
    assert "\n" not in message and str(readme) in message and "results markers" in message
    assert readme.read_text() == text  # untouched


def test_the_committed_readme_holds_the_block_of_the_committed_metrics():
    readme = (PACKAGE_CHECKOUT / "README.md").read_text()
    metrics = json.loads((PACKAGE_CHECKOUT / "results" / "metrics.json").read_text())
    assert readme.count(RESULTS_BEGIN) == 1 and readme.count(RESULTS_END) == 1
    assert replace_block(readme, results_block(metrics)) == readme
