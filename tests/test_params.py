"""params.yaml: typos and missing keys are named, profiles override only what they name."""

from __future__ import annotations

import pytest
import yaml

from pimann.errors import PimannError
from pimann.params import DEFAULT_PARAMS, load_params


def _write(tmp_path, raw: dict):
    path = tmp_path / "params.yaml"
    path.write_text(yaml.safe_dump(raw))
    return path


@pytest.fixture
def raw() -> dict:
    return yaml.safe_load(DEFAULT_PARAMS.read_text())


def test_repository_params_load():
    params = load_params()
    assert params.profile in ("quick", "paper")
    assert params.retarget.rate_hz == 50.0
    assert all(
        s.skeleton == "auto" or s.skeleton in params.data.skeletons
        for s in params.data.sources.values()
    )


def test_typo_is_named(tmp_path, raw):
    raw["retarget"]["segmnt_gain"] = raw["retarget"].pop("segment_gain")
    with pytest.raises(PimannError, match=r"params.yaml: unknown key 'retarget.segmnt_gain'"):
        load_params(_write(tmp_path, raw))


def test_missing_key_is_named(tmp_path, raw):
    del raw["data"]["mirror"]
    with pytest.raises(PimannError, match="missing key 'data.mirror'"):
        load_params(_write(tmp_path, raw))


def test_wrong_type_is_named(tmp_path, raw):
    raw["retarget"]["iterations_per_frame"] = "three"
    with pytest.raises(PimannError, match="retarget.iterations_per_frame must be int"):
        load_params(_write(tmp_path, raw))


def test_unknown_skeleton_is_named(tmp_path, raw):
    raw["data"]["sources"]["reactidle"]["skeleton"] = "cmu"
    with pytest.raises(PimannError, match="unknown skeleton 'cmu' in data.sources.reactidle"):
        load_params(_write(tmp_path, raw))


def test_profile_overrides_only_named_keys(tmp_path, raw):
    raw["profiles"]["quick"] = {"data.sources.bandai_namco.max_takes": 3}
    raw["profile"] = "quick"
    quick = load_params(_write(tmp_path, raw))
    raw["profile"] = "paper"
    paper = load_params(_write(tmp_path, raw))
    assert quick.data.sources["bandai_namco"].max_takes == 3
    assert (
        paper.data.sources["bandai_namco"].max_takes
        == (raw["data"]["sources"]["bandai_namco"]["max_takes"])
    )
    assert quick.data.sources["reactidle"] == paper.data.sources["reactidle"]
    assert quick.retarget == paper.retarget


def test_bad_profile_override_is_named(tmp_path, raw):
    raw["profiles"]["quick"] = {"data.sources.bandai_namco.max_take": 3}
    raw["profile"] = "quick"
    with pytest.raises(
        PimannError, match="profile override 'data.sources.bandai_namco.max_take' names no key"
    ):
        load_params(_write(tmp_path, raw))


def test_unknown_profile(tmp_path, raw):
    raw["profile"] = "huge"
    with pytest.raises(PimannError, match="profile 'huge'"):
        load_params(_write(tmp_path, raw))
