"""The `pimann` command line: JSON on stdout, one-line errors naming the file, exit codes."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from pimann.cli import main
from pimann.paths import shared_dir

MVNX = shared_dir() / "data" / "xsens" / "mvnx" / "Meri-020.mvnx"


def test_mocap_info_mvnx(capsys):
    assert main(["mocap-info", str(MVNX)]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["format"] == "mvnx" and info["frames"] == 4 and info["rate_hz"] == 240.0
    assert "Pelvis" in info["segments"] and "LeftFoot" in info["segments"]


@pytest.mark.parametrize(
    "argv, message",
    [
        (["mocap-info", "missing.mvnx"], "missing.mvnx: file not found"),
        (["metrics", "missing.h5"], "missing.h5: file not found"),
    ],
)
def test_bad_input_is_one_line(capsys, argv, message):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1


def test_truncated_mvnx_names_the_file(tmp_path, capsys):
    cut = tmp_path / "cut.mvnx"
    cut.write_bytes(MVNX.read_bytes()[:40000])
    assert main(["mocap-info", str(cut)]) == 2
    err = capsys.readouterr().err
    assert "cut.mvnx" in err and "Traceback" not in err


def test_console_script_has_no_traceback(tmp_path):
    """Through a real process: stderr is a single line, exit status non-zero."""
    bad = tmp_path / "bad.bvh"
    bad.write_text("HIERARCHY\nROOT Hips\n{\n")
    result = subprocess.run(
        [sys.executable, "-m", "pimann.cli", "mocap-info", str(bad)],
        capture_output=True,
        text=True,
        check=False,
    )
    assert result.returncode == 2
    assert "bad.bvh" in result.stderr and "Traceback" not in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
