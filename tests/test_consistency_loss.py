"""The joints' consistency term L_C (train.consistency_weight) and the feet term L_F
(train.feet_weight) on a real retargeted clip.

L_C charges a prediction whose joints and joint velocities disagree, s_i != s_{i-1} + dt sdot_i;
it needs s_{i-1}, which the output alone gives only because the features are first differences.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from pimann.core.params import load_params
from pimann.learn.feature_layout import Normalisation, window_layout
from pimann.learn.features import clip_features
from pimann.learn.training_loss import TrainingLoss

PARAMS = load_params()


def _loss_and_data(real_walks, weight):
    layout = window_layout(PARAMS.features, 50.0, "full")
    x, y, _ = clip_features(real_walks["walk"], layout)
    scale = y.std(axis=0) + 1.0  # a normalisation that is not the identity
    stats = Normalisation(x.mean(0), x.std(0) + 1.0, y.mean(0), scale)
    loss = TrainingLoss(layout, stats, "predicted", torch.device("cpu"), consistency_weight=weight)
    return loss, layout, x, y, stats


def _normalised(y, stats):
    return torch.as_tensor((y - stats.y_mean) / stats.y_std, dtype=torch.float32)[None]


def test_a_consistent_prediction_costs_nothing_and_an_inconsistent_one_the_closed_form(
    real_walks,
):
    loss, layout, x, y, stats = _loss_and_data(real_walks, 1.0)
    xs, ys, dt = layout.x_slices, layout.y_slices, 1.0 / layout.rate_hz
    rng = np.random.default_rng(0)
    # other joint velocities, with the joints that agree with them from the data's s_{i-1}
    consistent = y.copy()
    sdot = y[:, ys["joint_velocities"]] + rng.normal(0.0, 0.5, y[:, ys["joint_velocities"]].shape)
    consistent[:, ys["joint_velocities"]] = sdot
    consistent[:, ys["joints"]] = x[:, xs["joints"]] + dt * sdot
    target = _normalised(y, stats)
    prediction = _normalised(consistent, stats)
    assert loss.consistency(prediction, target).item() < 1e-6
    assert (prediction - target).abs().max().item() > 0.1  # the prediction is not the data
    # joints off by delta with the velocities the data's: L_C = mean (delta / dt)^2
    delta = rng.normal(0.0, 0.01, y[:, ys["joints"]].shape)
    shifted = y.copy()
    shifted[:, ys["joints"]] += delta
    want = np.mean((delta / dt) ** 2)
    got = loss.consistency(_normalised(shifted, stats), target).item()
    assert abs(got - want) < 1e-3 * want


def test_the_weight_adds_l_c_to_the_data_term_only(real_walks):
    plain, _, _, y, stats = _loss_and_data(real_walks, 0.0)
    weighted, _, _, _, _ = _loss_and_data(real_walks, 2.0)
    target = _normalised(y, stats)
    noise = torch.randn(target.shape, generator=torch.Generator().manual_seed(1))
    prediction = target + 0.05 * noise
    mse, pi = plain(prediction, target, with_pi=False)
    mse_c, pi_c = weighted(prediction, target, with_pi=False)
    extra = weighted.consistency(prediction, target)
    assert extra.item() > 0.0
    assert torch.allclose(mse_c, mse + 2.0 * extra)
    assert pi.item() == pi_c.item() == 0.0


def test_increments_are_the_predicted_joints_step_from_the_input_joints(real_walks):
    """train.pi_joint_velocities increments: (s_i - s_{i-1}) / dt with s_{i-1} the input's
    joints (x), computed from the output alone; for the data it is the data's sdot_i."""
    loss, layout, x, y, stats = _loss_and_data(real_walks, 0.0)
    xs, ys, dt = layout.x_slices, layout.y_slices, 1.0 / layout.rate_hz
    rng = np.random.default_rng(2)
    predicted = y.copy()
    predicted[:, ys["joints"]] += rng.normal(0.0, 0.01, y[:, ys["joints"]].shape)
    predicted[:, ys["joint_velocities"]] += 1.0  # the predicted sdot does not enter
    got = loss.increments(_normalised(predicted, stats), _normalised(y, stats))[0].numpy()
    want = (predicted[:, ys["joints"]] - x[:, xs["joints"]]) / dt
    np.testing.assert_allclose(got, want, rtol=1e-3, atol=1e-2)
    data = loss.increments(_normalised(y, stats), _normalised(y, stats))[0].numpy()
    np.testing.assert_allclose(data, y[:, ys["joint_velocities"]], rtol=1e-4, atol=1e-3)


def test_increments_enter_l_b_in_place_of_the_predicted_velocities(real_walks):
    layout = window_layout(PARAMS.features, 50.0, "full")
    x, y, _ = clip_features(real_walks["walk"], layout)
    stats = Normalisation(x.mean(0), x.std(0) + 1.0, y.mean(0), y.std(0) + 1.0)
    device = torch.device("cpu")
    pairs = {
        mode: TrainingLoss(layout, stats, "predicted", device, pi_joint_velocities=mode)
        for mode in ("predicted", "increments")
    }
    target = _normalised(y, stats)
    prediction = target.clone()
    prediction[..., layout.y_slices["joint_velocities"]] += 0.5  # only sdot is off
    _, pi_predicted = pairs["predicted"](prediction, target)
    _, pi_increments = pairs["increments"](prediction, target)
    _, pi_data = pairs["increments"](target, target)
    assert pi_increments.item() == pytest.approx(pi_data.item(), rel=1e-5)  # sdot ignored
    assert pi_predicted.item() > 2 * pi_increments.item()


def test_feet_term_starts_from_the_input_joints_and_adds_to_the_data_term(real_walks):
    """train.feet_weight: L_F from s_{i-1} (the input's joints, recovered from the output
    alone) to the predicted s_i, added to L_D times the weight; L_B untouched."""
    layout = window_layout(PARAMS.features, 50.0, "full")
    x, y, _ = clip_features(real_walks["walk"], layout)
    stats = Normalisation(x.mean(0), x.std(0) + 1.0, y.mean(0), y.std(0) + 1.0)
    device = torch.device("cpu")
    plain = TrainingLoss(layout, stats, "predicted", device)
    weighted = TrainingLoss(layout, stats, "predicted", device, feet_weight=3.0)
    xs, ys, dt = layout.x_slices, layout.y_slices, 1.0 / layout.rate_hz
    predicted = y.copy()
    predicted[:, ys["joints"]] += np.random.default_rng(4).normal(0, 0.01, (len(y), 26))
    prediction, target = _normalised(predicted, stats), _normalised(y, stats)
    got = weighted.feet(prediction, target)
    motion = weighted.physics.feet_motion(
        torch.as_tensor(x[:, xs["joints"]], dtype=torch.float32),
        torch.as_tensor(predicted[:, ys["joints"]], dtype=torch.float32),
        torch.as_tensor(predicted[:, ys["base_rpy"]], dtype=torch.float32),
        dt, PARAMS.contacts.on_height,
    )  # fmt: skip
    torch.testing.assert_close(got, motion.mean()[None], rtol=2e-3, atol=1e-6)
    assert got.item() > 3 * weighted.feet(target, target).item()  # the joints' noise shows
    (mse, pi), (mse_f, pi_f) = plain(prediction, target), weighted(prediction, target)
    torch.testing.assert_close(mse_f - mse, 3.0 * got)
    torch.testing.assert_close(pi_f, pi)
