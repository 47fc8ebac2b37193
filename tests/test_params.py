"""params.yaml: typos and missing keys are named, profiles override only what they name."""

from __future__ import annotations

import pytest
import yaml

from pimann.core.errors import PimannError
from pimann.core.params import DEFAULT_PARAMS, load_params


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
    with pytest.raises(
        PimannError, match="data.sources.reactidle.skeleton: unknown 'cmu'; known: auto"
    ):
        load_params(_write(tmp_path, raw))


def _set(raw: dict, dotted: str, value) -> None:
    *parents, leaf = dotted.split(".")
    node = raw
    for part in parents:
        node = node[int(part)] if isinstance(node, list) else node[part]
    if isinstance(node, list):
        node[int(leaf)] = value
    else:
        node[leaf] = value


@pytest.mark.parametrize(
    ("dotted", "value", "message"),
    [
        ("train.batch_size", 0, r"train.batch_size must be >= 1, not 0"),
        ("train.epochs", -3, r"train.epochs must be >= 1, not -3"),
        ("features.test_fraction", 1.5, r"features.test_fraction must be in \(0, 1\), not 1.5"),
        ("retarget.contact_height", float("nan"), r"retarget.contact_height must be a finite"),
        ("model.dropout", 1.0, r"model.dropout must be in \[0, 1\), not 1.0"),
        ("simulate.kp_arms", -1.0, r"simulate.kp_arms must be > 0"),
        ("rollout.scenarios.forward.0.duration", 0.0, r"scenarios.forward.0.duration must be > 0"),
        (
            "rollout.scenario_names.1",
            "backwards",
            r"rollout.scenario_names.1: unknown 'backwards'; known: backward, forward",
        ),
        ("simulate.runs.0.model", "w7", r"simulate.runs.0.model: unknown 'w7'; known: w0, w1"),
        ("simulate.runs.0.seed", 9, r"simulate.runs.0.seed: unknown 9"),
        ("evaluate.pi_weight", 7, r"evaluate.pi_weight: unknown 7.0; known: 0.0, 1.0"),
        ("evaluate.box_weights.1", 3, r"evaluate.box_weights.1: unknown 3.0; known: 0.0, 1.0"),
        ("evaluate.foot_height_weights.0", 5, r"evaluate.foot_height_weights.0: unknown 5.0"),
        ("evaluate.large_weight", 50, r"evaluate.large_weight: unknown 50.0; known: 0.0, 1.0"),
        ("evaluate.scenario", "jog", r"evaluate.scenario: unknown 'jog'; known: forward"),
        ("evaluate.drift_reduction", -1, r"evaluate.drift_reduction must be in \(0, 1\], not -1"),
        ("evaluate.drift_reduction", 1.5, r"evaluate.drift_reduction must be in \(0, 1\], not 1.5"),
        ("evaluate.foot_steering", "maybe", r"evaluate.foot_steering must be bool"),
        ("contacts.off_height", 0.01, r"contacts.off_height must be >= contacts.on_height"),
        ("contacts.switch_time", -0.1, r"contacts.switch_time must be >= 0, not -0.1"),
        ("train.seeds", [0, 0], r"train.seeds must be a non-empty list without repeats"),
        ("simulate.mpc.friction", 0.0, r"simulate.mpc.friction must be > 0, not 0.0"),
        ("simulate.mpc.box_y", [0.01, 0.05], r"simulate.mpc.box_y must be \[low <= 0, high >= 0\]"),
        ("simulate.mpc.com_z_min", 0.8, r"com_z_min must not exceed simulate.mpc.com_z_max"),
        ("simulate.mpc.com_weight", [2.0, 2.0], r"simulate.mpc.com_weight must have 3 entries"),
        ("simulate.mpc.com_weight.2", -1.0, r"simulate.mpc.com_weight.2 must be >= 0, not -1.0"),
        ("simulate.runs.0.controller", "mpc", r"simulate.runs.0.controller must be one of"),
        ("simulate.pushes.rollouts.0.model", "w7", r"simulate.pushes.rollouts.0.model: unknown"),
        ("simulate.pushes.tolerance", 0.0, r"simulate.pushes.tolerance must be > 0"),
    ],
)
def test_bad_values_are_named_with_what_is_allowed(tmp_path, raw, dotted, value, message):
    raw["profile"] = "paper"
    _set(raw, dotted, value)
    with pytest.raises(PimannError, match=message):
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


def test_a_run_without_a_controller_is_offline(tmp_path, raw):
    raw["profile"] = "paper"
    raw["simulate"]["runs"][0].pop("controller", None)
    params = load_params(_write(tmp_path, raw))
    assert params.simulate.runs[0].controller == "offline"
    assert {run.controller for run in params.simulate.runs} == {"offline", "online"}


def test_a_value_the_active_profile_hides_is_still_checked(tmp_path, raw):
    raw["profile"] = "quick"
    raw["profiles"]["quick"]["train.epochs"] = 70
    raw["train"]["epochs"] = -3  # the base: quick overrides it, paper runs it
    with pytest.raises(PimannError, match=r"train.epochs must be >= 1, not -3$"):
        load_params(_write(tmp_path, raw))


def test_a_bad_profile_value_names_the_profile(tmp_path, raw):
    raw["profile"] = "paper"
    raw["profiles"]["quick"]["train.epochs"] = 0  # not the active profile
    with pytest.raises(PimannError, match=r"train.epochs must be >= 1, not 0 \(profile quick\)"):
        load_params(_write(tmp_path, raw))
    raw["profiles"]["quick"]["train.epochs"] = 70
    raw["profiles"]["quick"]["evaluate.pi_weight"] = 3  # a cross-reference, merged
    with pytest.raises(PimannError, match=r"evaluate.pi_weight: unknown 3.*\(profile quick\)"):
        load_params(_write(tmp_path, raw))


def test_what_evaluate_selects_for_the_figures_and_claims_loads_under_evaluate():
    """evaluate's choices for the figures and claims (the scenario, the weights compared, the
    foot rollouts, the drift factor) load from its own section in either profile; figures keeps
    the style alone."""
    selection = {
        "scenario": "authors",
        "box_weights": [0.0, 1.0, 10.0, 20.0],
        "large_weight": 100.0,
        "foot_height_weights": [0.0, 10.0],
        "foot_steering": False,
        "drift_reduction": 0.5,
    }
    for profile in ("quick", "paper"):
        params = load_params(profile=profile)
        assert {key: getattr(params.evaluate, key) for key in selection} == selection, profile
        assert params.evaluate.pi_weight == 10.0
        assert set(vars(params.figures)) == {"width_in", "font_pt", "dpi"}


def test_a_moved_key_in_the_old_section_is_named(tmp_path, raw):
    raw["figures"]["scenario"] = raw["evaluate"].pop("scenario")
    with pytest.raises(PimannError, match=r"unknown key 'figures\.scenario'"):
        load_params(_write(tmp_path, raw))


def test_the_profile_can_be_chosen_by_the_caller(tmp_path, raw):
    raw["profile"] = "quick"
    path = _write(tmp_path, raw)
    paper = load_params(path, profile="paper")
    assert paper.profile == "paper" and paper.train.epochs == raw["train"]["epochs"]
    assert load_params(path).train.epochs == raw["profiles"]["quick"]["train.epochs"]


@pytest.mark.parametrize(
    "way, change, message",
    [("unsteered", {"k9": 1.0}, r"protocols\.authors\.unsteered\.k9: not a protocol key"),
     ("steered", {"k1": -1.0}, r"protocols\.authors\.steered: .*k1"),
     ("steered", {"scenarios": {}}, r"protocols\.authors\.steered\.scenarios: not a protocol")],
)  # fmt: skip
def test_a_protocol_key_is_checked_by_name_and_range(tmp_path, raw, way, change, message):
    raw["rollout"]["protocols"]["authors"][way] = change
    with pytest.raises(PimannError, match=message):
        load_params(_write(tmp_path, raw))


def test_a_protocol_sets_only_its_keys(raw, tmp_path):
    params = load_params(_write(tmp_path, raw))
    unsteered = params.rollout.for_protocol("authors", False)
    steered = params.rollout.for_protocol("authors", True)
    assert (unsteered.command_blend_tau, unsteered.start_history) == (0.0, "zero")
    assert (steered.k0, steered.k1, steered.goal_factor) == (0.2, 2.0, 2.5)
    assert steered.command_blend_tau is None and steered.planar_steering
    assert unsteered.k1 == params.rollout.k1 and not unsteered.protocols  # the rest as is
    raw["rollout"]["protocols"]["forward"] = raw["rollout"]["protocols"]["authors"]
    with pytest.raises(PimannError, match="protocols.forward is also a scenario"):
        load_params(_write(tmp_path, raw))


def _defaults_against(kind: type, values: dict, where: str) -> list[str]:
    """Every field of `kind` with a code default, against the value params.yaml holds there."""
    import dataclasses
    import typing

    differing = []
    hints = typing.get_type_hints(kind)
    for field in dataclasses.fields(kind):
        value = values.get(field.name)
        if field.default is not dataclasses.MISSING:
            default = field.default
        elif field.default_factory is not dataclasses.MISSING:
            default = field.default_factory()
        else:
            default = dataclasses.MISSING
        if default is not dataclasses.MISSING and field.name in values and value != default:
            differing.append(f"{where}.{field.name}: code {default!r}, params.yaml {value!r}")
        nested = typing.get_args(hints[field.name]) or (hints[field.name],)
        for inner in nested:
            if dataclasses.is_dataclass(inner) and isinstance(value, dict):
                differing += _defaults_against(inner, value, f"{where}.{field.name}")
    return differing


def test_no_code_default_differs_from_params_yaml(raw):
    """A section's code default that params.yaml overrides is a second, silent truth: code
    that builds the section itself (tests, benchmarks, studies) would run other values."""
    from pimann.core.params import Params

    assert _defaults_against(Params, raw, "params") == []


def test_the_defaults_check_sees_a_differing_default(raw):
    raw["simulate"]["pushes"]["max_force"] = 123.0
    from pimann.core.params import Params

    assert _defaults_against(Params, raw, "params") == [
        "params.simulate.pushes.max_force: code 800.0, params.yaml 123.0"
    ]
