"""Teacher-forced response per motion class (diagnostics.teacher_forcing) on a tiny real
pipeline."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch
from builders import synthetic_collection

from diagnostics.teacher_forcing import _slope, class_response
from pimann.core.params import ModelParams, load_params
from pimann.core.trajectory import write_collection
from pimann.learn.dataset import write_dataset
from pimann.learn.features import build_dataset
from pimann.learn.mann import MANN
from pimann.learn.model_files import save_model


def test_slope_of_a_scaled_copy_and_of_a_constant():
    truth = np.linspace(-1, 1, 50)
    assert _slope(truth, truth) == pytest.approx(1.0)
    assert _slope(truth, 0.5 * truth + 3) == pytest.approx(0.5)
    assert _slope(truth, np.full(50, 0.2)) == pytest.approx(0.0, abs=1e-12)


def test_class_response_reports_the_data_velocity_per_class(tmp_path):
    params = load_params()
    clips = synthetic_collection(n_sources=6, frames=200)  # straight walks at 0.2-0.7 m/s
    collection = tmp_path / "walking.h5"
    write_collection(collection, clips)
    dataset = build_dataset(clips, params.features, "full")
    dataset_path = tmp_path / "full.h5"
    write_dataset(dataset_path, dataset)
    small = ModelParams(2, 8, 2, 16, 2, 0.0, "elu")
    torch.manual_seed(0)
    model = MANN(dataset.layout.input_dim, dataset.layout.output_dim, small, seeds=[0])
    meta = {
        "pi_weight": 0.0,
        "seed": 0,
        "variant": "full",
        "dataset": str(dataset_path),
        "params": {"model": dataclasses.asdict(small)},
    }
    save_model(tmp_path / "w0" / "0", model, dataset.layout, dataset.stats, meta)
    table = class_response(tmp_path / "w0", collection, samples=500)
    assert set(table["split"]) == {"train", "test"}
    assert set(table["class"]) <= {"forward", "turning", "diagonal", "backward"}
    # the training clips played backward (features.time_reversed) walk backward, in training
    backward = table["class"] == "backward"
    assert backward.any() and set(table.loc[backward, "split"]) == {"train"}
    # the truth is the clips' own speed in the base frame (0.2 .. 0.7 m/s, pitched base)
    straight = table["class"].isin(["forward", "backward"])
    speed = table["vx_true"].where(~backward, -table["vx_true"])[straight]
    assert straight.sum() >= 3 and ((speed > 0.1) & (speed < 0.8)).all()
    assert table["samples"].min() >= 50 and np.isfinite(table["vx_slope"]).all()
    for column in ("feet_true", "feet_pred", "feet_sdot", "sdot_step_slope"):
        assert np.isfinite(table[column]).all()
    assert (table["feet_pred"] > table["feet_true"]).all()  # an untrained network's joints


def test_models_folder_or_one_training_output_and_a_named_error(tmp_path, capsys):
    from diagnostics.teacher_forcing import main, model_folders

    (tmp_path / "w10" / "0").mkdir(parents=True)
    (tmp_path / "w10" / "0" / "meta.json").write_text("{}")
    (tmp_path / "notes").mkdir()
    assert model_folders(tmp_path) == [tmp_path / "w10"]
    assert model_folders(tmp_path / "w10") == [tmp_path / "w10"]
    assert main(["--models", str(tmp_path / "notes")]) == 2
    error = capsys.readouterr().err
    assert "notes" in error and "no trained models" in error and error.count("\n") == 1


def test_contact_leg_velocity_is_pinocchios_sole_velocity_with_the_base_held(robot):
    """The contact sole's forward velocity that the joints alone give, base at rest at the
    origin (pinocchio, WORLD = base axes), for the foot in contact; NaN in double support, in
    flight, or without contact flags."""
    import pinocchio as pin

    from diagnostics.teacher_forcing import contact_leg_velocity
    from pimann.core.robot import LEFT_SOLE, RIGHT_SOLE
    from pimann.learn.training_loss import TrainingLoss

    params = load_params()
    dataset = build_dataset(synthetic_collection(n_sources=2, frames=120), params.features, "full")
    layout, stats = dataset.layout, dataset.stats
    y = dataset.y_train[:6]
    contacts = np.array([[1, 0], [0, 1], [1, 1], [0, 0], [1, 0], [0, 1]], bool)
    loss = TrainingLoss(
        layout, stats, torch.device("cpu"), pi_configuration="predicted", pi_gradient="both"
    )
    share = contact_leg_velocity(loss, y, contacts)
    assert np.isnan(share[[2, 3]]).all()
    assert np.isnan(contact_leg_velocity(loss, y, None)).all()
    physical = y * stats.y_std + stats.y_mean
    for k in (0, 1, 4, 5):
        joints = physical[k, layout.y_slices["joints"]]
        velocities = physical[k, layout.y_slices["joint_velocities"]]
        q = robot.configuration(np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]), joints)
        v = robot.velocity(np.zeros(3), np.zeros(3), velocities)
        sole = LEFT_SOLE if contacts[k, 0] else RIGHT_SOLE
        expected = (robot.frame_jacobian(q, sole, pin.WORLD) @ v)[0]
        assert share[k] == pytest.approx(expected, abs=1e-4)
    assert np.ptp(share[[0, 1, 4, 5]]) > 1e-3  # the samples differ: not a constant passing


def test_feet_motion_moves_with_the_leg_joints_only(real_walks):
    """L_F teacher-forced: the arms' joints do not move the soles, the legs' do."""
    from diagnostics.teacher_forcing import feet_motion
    from pimann.core.robot import JOINT_NAMES, LEG_JOINTS
    from pimann.learn.feature_layout import Normalisation, window_layout
    from pimann.learn.features import clip_features
    from pimann.learn.training_loss import TrainingLoss

    params = load_params()
    layout = window_layout(params.features, 50.0, "full")
    x, y, _ = clip_features(real_walks["walk"], layout)
    stats = Normalisation(x.mean(0), x.std(0) + 1.0, y.mean(0), y.std(0) + 1.0)
    xn, yn = (x - stats.x_mean) / stats.x_std, (y - stats.y_mean) / stats.y_std
    loss = TrainingLoss(
        layout, stats, torch.device("cpu"), pi_configuration="predicted", pi_gradient="both"
    )
    height = params.contacts.on_height
    data = feet_motion(loss, layout, stats, xn, yn, yn, height)
    assert data.shape == (len(y),) and (data >= 0).all() and data.mean() > 0
    joints = layout.y_slices["joints"].start
    arms = [k for k in range(len(JOINT_NAMES)) if k not in LEG_JOINTS]
    rng = np.random.default_rng(5)
    moved_arms, moved_legs = yn.copy(), yn.copy()
    moved_arms[:, [joints + k for k in arms]] += rng.normal(0, 0.3, (len(y), len(arms)))
    moved_legs[:, [joints + k for k in LEG_JOINTS]] += rng.normal(0, 0.05, (len(y), 12))
    arms_value = feet_motion(loss, layout, stats, xn, yn, moved_arms, height)
    np.testing.assert_allclose(arms_value, data, rtol=1e-3, atol=1e-6)
    assert feet_motion(loss, layout, stats, xn, yn, moved_legs, height).mean() > 3 * data.mean()


def test_integrated_joints_are_the_input_joints_moved_by_the_predicted_velocities(real_walks):
    """On the data's own outputs s_{i-1} + dt sdot_i is the data's s_i (first differences)."""
    from diagnostics.teacher_forcing import integrated_joints
    from pimann.learn.feature_layout import Normalisation, window_layout
    from pimann.learn.features import clip_features

    layout = window_layout(load_params().features, 50.0, "full")
    x, y, _ = clip_features(real_walks["walk"], layout)
    stats = Normalisation(x.mean(0), x.std(0) + 1.0, y.mean(0), y.std(0) + 1.0)
    xn, yn = (x - stats.x_mean) / stats.x_std, (y - stats.y_mean) / stats.y_std
    np.testing.assert_allclose(integrated_joints(layout, stats, xn, yn), yn, atol=1e-9)
    moved = yn.copy()
    moved[:, layout.y_slices["joint_velocities"]] += 1.0
    assert np.abs(integrated_joints(layout, stats, xn, moved) - yn).max() > 1e-3
