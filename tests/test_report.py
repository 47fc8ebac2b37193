"""The report page (pimann.report.page) from a crafted results/ folder: self-contained (every
image and video a data: URI, no http(s) address, no script), and, where a headless Chromium
is installed, every image and video loads in it."""

from __future__ import annotations

import html
import json
import re
import shutil
import subprocess
from html.parser import HTMLParser

import imageio.v2 as imageio
import numpy as np
import pytest
from builders import SIM_SUMMARY, crafted_results, crafted_rows

from pimann.core.params import load_params
from pimann.report.page import (
    CLAIM_MARKS,
    HEADLINE_FIGURES,
    build_report,
    claim_rows,
    markdown_html,
    write_report,
)

BROWSERS = (
    "chromium",
    "chromium-browser",
    "google-chrome",
    "google-chrome-stable",
    "chromium-headless-shell",
    "chrome-headless-shell",
)
INSTALL_HINT = (
    "no headless browser on PATH (looked for " + ", ".join(BROWSERS) + "); on Debian "
    "`apt-get install -y --no-install-recommends chromium` provides one"
)


class _Attributes(HTMLParser):
    """Every (tag, attribute, value) of a page."""

    def __init__(self) -> None:
        super().__init__()
        self.found: list[tuple[str, str, str]] = []

    def handle_starttag(self, tag, attrs):
        self.found += [(tag, name, value or "") for name, value in attrs]


def attributes(page: str) -> list[tuple[str, str, str]]:
    parser = _Attributes()
    parser.feed(page)
    return parser.found


@pytest.fixture(scope="module")
def params():
    return load_params()


@pytest.fixture(scope="module")
def study(params, tmp_path_factory):
    """results/ with every input of the report, paper_figures/ with two small PNGs."""
    root = tmp_path_factory.mktemp("study")
    results = crafted_results(root / "results", params)
    crafted_rows().to_csv(results / "command_following.csv", index=False)
    (results / "command_following.md").write_text(
        "<!-- generated -->\n# Command following\n\n| model | speed |\n|---|---|\n| w10 | 0.8 |\n"
    )
    (results / "data_report.md").write_text(
        "# Data report\n\n| source | fwd |\n|---|---|\n| a | 1 |\n"
    )
    (results / "sim_summary.json").write_text(json.dumps(SIM_SUMMARY))
    figures = root / "paper_figures"
    figures.mkdir()
    for k, path in enumerate(
        (
            figures / "a.png",
            figures / "b.png",
            results / "data_report.png",
            results / "command_following.png",
        )
    ):
        imageio.imwrite(path, np.full((40, 60 + k, 3), 40 * k, dtype=np.uint8))
    frames = [np.full((64, 96, 3), 20 * k, dtype=np.uint8) for k in range(10)]
    imageio.mimwrite(
        results / "sim" / "w10-0-mixed-steering.mp4",
        frames,
        fps=10,
        codec="libx264",
        macro_block_size=2,
    )
    return results, figures


def test_report_embeds_everything_and_reaches_nothing(study, params):
    results, figures = study
    metrics_path, report = write_report(results, figures, params)
    page = report.read_text()
    found = attributes(page)
    sources = [(tag, value) for tag, name, value in found if name == "src"]
    assert sorted(tag for tag, _ in sources) == ["img"] * 4 + ["video"]
    assert all(
        value.startswith(("data:image/png;base64,", "data:video/mp4;base64,"))
        for _, value in sources
    )
    links = [value for _, name, value in found if name in ("href", "src", "srcset", "poster")]
    assert not [v for v in links if re.match(r"\s*(https?:)?//", v, re.IGNORECASE)]
    assert "<script" not in page and "<link" not in page and "@import" not in page
    for section in ("claims", "figures", "following", "simulation", "data", "params"):
        assert f'id="{section}"' in page
    assert "<details>" in page and params.profile in page  # the params, collapsed
    assert "<table>" in page and "| model |" not in page  # Markdown tables rendered
    assert json.loads(metrics_path.read_text())["sim.runs"] == 2


def _sections(page: str) -> list[tuple[str, str]]:
    """(id, body) of every <section> of the page, in order."""
    return re.findall(r'<section id="([^"]+)">(.*?)</section>', page, re.DOTALL)


def test_the_page_leads_with_the_headline_figures_and_a_compact_claims_table(
    study, params, tmp_path
):
    results, _ = study
    figures = tmp_path / "paper_figures"
    figures.mkdir()
    for k, name in enumerate((*HEADLINE_FIGURES, "joint_tracking")):
        imageio.imwrite(figures / f"{name}.png", np.full((30, 40 + k, 3), 50, dtype=np.uint8))
    page = build_report(results, figures, params, {"claims.holding": 1, "claims.total": 14})
    sections = _sections(page)
    assert sections[0][0] == "glance" and page.index('id="glance"') < page.index('id="numbers"')
    glance, figures_body = sections[0][1], dict(sections)["figures"]
    shown = [value for tag, name, value in attributes(glance) if tag == "img" and name == "alt"]
    assert shown == [name.replace("_", " ") for name in HEADLINE_FIGURES]
    alts = [value for tag, name, value in attributes(figures_body) if name == "alt"]
    assert alts == ["joint tracking"]  # the headline figures are not repeated

    # one row per row of claims.md, each a coloured mark and its reason folded under it
    claims_md = (results / "claims.md").read_text()
    expected = [line for line in claims_md.splitlines() if re.match(r"\| (C\d+|D) \|", line)]
    table = re.search(r'<table class="claims">(.*?)</table>', glance, re.DOTALL).group(1)
    rows = re.findall(r"<tr><td>(.*?)</td>.*?</tr>", table, re.DOTALL)
    assert len(rows) == len(expected) > 0
    cells = re.findall(
        r'<span class="mark (\w+)" title="([^"]+)">(.)</span> '
        r"<details><summary>([^<]+)</summary>(.*?)</details>",
        table,
    )
    assert len(cells) == len(expected)
    for css, title, mark, summary, reason in cells:
        assert (mark, css) == CLAIM_MARKS[title] and summary == title and reason
    first = claim_rows(claims_md)[1]  # C1, after the data's row D
    assert first["id"] == "C1" and html.escape(first["why"]) in table


def test_claim_rows_read_escaped_pipes_and_bold_statuses():
    text = (
        "# t\n\n| id | claim (paper) | status | why |\n|---|---|---|---|\n"
        "| C9 | pitch \\|x\\| grows | **holds** | as claimed |\n"
    )
    assert claim_rows(text) == [
        {"id": "C9", "claim (paper)": "pitch |x| grows", "status": "holds", "why": "as claimed"}
    ]


def test_missing_inputs_say_which_stage(study, params, tmp_path):
    results, _ = study
    page = build_report(results, tmp_path / "no_figures", params, {})
    assert "dvc repro figures" in page


def test_markdown_tables_and_comments():
    out = markdown_html("<!-- provenance: {} -->\n| a | b \\| c |\n|---|---|\n| 1 | 2 |\n")
    assert "<table>" in out and "provenance" not in out and "b | c" in out


def _browser() -> str | None:
    return next((path for name in BROWSERS if (path := shutil.which(name))), None)


PROBE = """<pre id="probe"></pre><script>
function report() {
  const images = [...document.images].map(i => i.complete && i.naturalWidth > 0);
  const videos = [...document.querySelectorAll("video")].map(v => v.readyState);
  document.getElementById("probe").textContent = JSON.stringify({images, videos});
}
const pending = [...document.querySelectorAll("video")].filter(v => v.readyState < 1);
let left = pending.length;
if (!left) { window.addEventListener("load", report); }
for (const v of pending) {
  const done = () => { if (--left === 0) report(); };
  v.addEventListener("loadedmetadata", done); v.addEventListener("error", done);
  v.load();
}
setTimeout(report, 8000);
</script>"""


@pytest.mark.slow
def test_every_image_and_video_loads_in_a_browser(study, params, tmp_path):
    browser = _browser()
    if browser is None:
        pytest.skip(INSTALL_HINT)
    results, figures = study
    _, report = write_report(results, figures, params, tmp_path / "report.html")
    probed = tmp_path / "probed.html"  # the page plus a script that reports what loaded
    probed.write_text(report.read_text().replace("</body>", PROBE + "</body>"))
    run = subprocess.run(
        [
            browser,
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--no-first-run",
            f"--user-data-dir={tmp_path / 'profile'}",
            "--virtual-time-budget=20000",
            "--dump-dom",
            probed.as_uri(),
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    match = re.search(r'<pre id="probe">(.*?)</pre>', run.stdout, re.DOTALL)
    assert match and match.group(1), run.stderr[-2000:]
    loaded = json.loads(match.group(1))
    assert loaded["images"] == [True] * 4
    assert len(loaded["videos"]) == 1 and min(loaded["videos"]) >= 1  # HAVE_METADATA


def test_push_recovery_table(study, params, tmp_path):
    """The summary's push studies become a table; a failed study is left out of it."""
    import shutil

    results, figures = study
    copy = tmp_path / "results"
    shutil.copytree(results, copy)
    summary = json.loads((copy / "sim_summary.json").read_text())
    summary["pushes"] = {
        "w10-0-forward-steering": {"offline": {"lateral": 312.5}, "online": {"lateral": 187.5}},
        "w0-0-forward-steering": {"failed": "rollout unreadable"},
    }
    (copy / "sim_summary.json").write_text(json.dumps(summary))
    page = build_report(copy, figures, params, {})
    assert "largest push (N)" in page and "312.5" in page and "187.5" in page
    assert "w0-0-forward-steering" not in page
