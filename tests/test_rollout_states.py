"""train.rollout_states: own-rollout inputs, checked step by step against the model itself."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch
from builders import (
    SMALL_MODEL,
    trains_differently_and_deterministically,
)

from pimann.learn.dataset import read_dataset
from pimann.learn.epochs import epoch_seed
from pimann.learn.held_out_loss import HeldOutLoss, batched_loss
from pimann.learn.mann import MANN
from pimann.learn.rollout_states import OwnRollouts, RolloutStates, rollout_pieces
from pimann.learn.train import train_models
from pimann.learn.training_loss import TrainingLoss


def test_pieces_follow_clips_gaps_and_length():
    origin = np.array([[0, 5], [0, 6], [0, 7], [0, 8], [0, 9], [0, 11], [1, 12], [1, 13]])
    pieces = rollout_pieces(origin, 3)
    assert pieces.tolist() == [[0, 1, 2], [3, 4, -1], [5, -1, -1], [6, 7, -1]]
    assert rollout_pieces(origin[:0], 3).shape == (0, 3)


@pytest.fixture(scope="module")
def own(dataset_path):  # noqa: F811
    data = read_dataset(dataset_path)
    model = MANN.from_seeds(
        data.layout.input_dim, data.layout.output_dim, SMALL_MODEL, [3, 4]
    ).eval()
    rollouts = OwnRollouts(
        data.layout, data.stats, data.train_origin, 6, torch.device("cpu"), command_blend_tau=1.0
    )
    x, y = torch.as_tensor(data.x_train), torch.as_tensor(data.y_train)
    return data, model, rollouts, x, y, rollouts.inputs(model, x, y)


def test_own_inputs_feed_back_the_members_previous_prediction(own):
    """Row k of a piece: the joints of the member's prediction at row k - 1 (from its own
    input there), the velocity at offset 0 the data's plus that prediction's error; the rest,
    and every piece's first row, the data's."""
    data, model, rollouts, x, y, inputs = own
    layout, stats = data.layout, data.stats
    xs, ys = layout.x_slices, layout.y_slices
    assert inputs.shape == (2, *x.shape)
    first = rollouts.pieces[:, 0]
    assert torch.equal(inputs[:, first], x[first].expand(2, -1, -1))
    later = rollouts.pieces[:, 1:]
    rows, previous = later[later >= 0], rollouts.pieces[:, :-1][later >= 0]
    with torch.no_grad():
        predicted = model(inputs[:, previous]).numpy() * stats.y_std + stats.y_mean
    own_x = inputs[:, rows].numpy() * stats.x_std + stats.x_mean
    data_x = x[rows].numpy() * stats.x_std + stats.x_mean
    np.testing.assert_allclose(own_x[..., xs["joints"]], predicted[..., ys["joints"]], atol=1e-4)
    np.testing.assert_allclose(own_x[..., xs["joint_velocities"]],
                               predicted[..., ys["joint_velocities"]], atol=1e-3)  # fmt: skip
    now = 3 * layout.current_output
    at_zero = 3 * layout.input_offsets.index(0)
    truth = y[previous].numpy() * stats.y_std + stats.y_mean
    for block in ("base_linear", "base_angular"):
        x_cols = slice(
            xs[f"{block}_window"].start + at_zero, xs[f"{block}_window"].start + at_zero + 3
        )
        y_cols = slice(ys[f"{block}_future"].start + now, ys[f"{block}_future"].start + now + 3)
        error = predicted[..., y_cols] - truth[..., y_cols]
        np.testing.assert_allclose(own_x[..., x_cols] - data_x[..., x_cols], error, atol=1e-4)
    # the future samples: the prediction at k - 1 (already one frame ahead), blended with the data's
    # mean future velocity, w = t / window end (np.interp, clamped at the window's end)
    out_offsets = np.asarray(layout.output_offsets, dtype=float)
    weights = out_offsets / out_offsets.max()
    future = [k for k, offset in enumerate(layout.input_offsets) if offset > 0]
    knots = np.eye(len(out_offsets))
    for block in ("base_linear", "base_angular"):
        own_window = predicted[..., ys[f"{block}_future"]].reshape(*predicted.shape[:2], -1, 3)
        start = xs[f"{block}_window"].start
        command = np.mean([data_x[..., start + 3 * k : start + 3 * k + 3] for k in future], 0)
        blended = (1 - weights)[:, None] * own_window + weights[:, None] * command[..., None, :]
        for k in future:
            at = float(layout.input_offsets[k])  # y_i holds the window of frame i + 1
            row = np.array([np.interp(at, out_offsets, knot) for knot in knots])
            expected = np.einsum("j,erjc->erc", row, blended)
            np.testing.assert_allclose(own_x[..., start + 3 * k : start + 3 * k + 3], expected,
                                       atol=1e-3)  # fmt: skip
    untouched = ~layout.fed_back_columns()
    for block in ("base_linear", "base_angular"):  # the future samples are fed back too
        untouched[[c for c in range(xs[f"{block}_window"].start, xs[f"{block}_window"].stop)]] = (
            False
        )
    np.testing.assert_allclose(own_x[..., untouched], np.broadcast_to(data_x[..., untouched],
                               own_x[..., untouched].shape), atol=1e-4)  # fmt: skip
    # each member rolls out on its own
    assert not torch.allclose(inputs[0, rows], inputs[1, rows])


def test_states_mix_per_member_from_the_first_epoch_on(own):
    data, model, rollouts, x, y, inputs = own
    kept = torch.arange(0, len(x), 2)
    index = torch.stack([torch.arange(20), torch.arange(20, 40)])
    batch = x[kept][index]
    later = RolloutStates(0.5, 3, rollouts, x, y, kept, [3, 4])
    later.start_epoch(model, 2)
    assert later(batch, index) is batch  # before first_epoch: the data's
    later.start_epoch(model, 3)
    mixed = later(batch, index)
    own_batch = inputs[:, kept][torch.arange(2)[:, None], index]
    took = (mixed == own_batch).all(-1) & ~(mixed == batch).all(-1)
    assert ((mixed == own_batch).all(-1) | (mixed == batch).all(-1)).all()
    assert 0 < took.float().mean() < 1
    generator = torch.Generator().manual_seed(epoch_seed(4, 3, "rollout_states"))
    expected = torch.rand(20, generator=generator) < 0.5
    assert torch.equal(torch.where(expected[:, None], own_batch[1], batch[1]), mixed[1])
    always = RolloutStates(1.0, 0, rollouts, x, y, kept, [3, 4])
    always.start_epoch(model, 0)
    assert torch.equal(always(batch, index), own_batch)
    assert model.training is False  # inputs() restores the mode it found


def test_rollout_states_train_differently_and_deterministically(tmp_path, params, dataset_path):  # noqa: F811
    two_epochs = dataclasses.replace(params.train, epochs=2, restart_period=1)
    trains_differently_and_deterministically(
        tmp_path, dataclasses.replace(params, train=two_epochs), dataset_path, 1.0,
        rollout_states=0.5, rollout_steps=10,
    )  # fmt: skip


def test_the_test_loss_weighs_own_rollouts_as_training(tmp_path, params, dataset_path):  # noqa: F811
    """The kept epoch's recorded test MSE is (1 - share) x the data inputs' + share x the
    model's own-rollout inputs' on the test clips."""
    import csv

    from pimann.learn.model_files import load_model

    share = 0.5
    train = dataclasses.replace(
        params.train, epochs=2, restart_period=1, rollout_states=share, rollout_steps=10,
        eval_batch_size=7,  # several test batches, each member's own inputs among them
    )  # fmt: skip
    run = dataclasses.replace(params, train=train)
    train_models(dataset_path, tmp_path / "own", 0.0, [0], run, "cpu", plots_dir=tmp_path / "p")
    model, layout, stats, meta = load_model(tmp_path / "own" / "0")
    data = read_dataset(dataset_path)
    x, y = torch.as_tensor(data.x_test), torch.as_tensor(data.y_test)
    tau = params.rollout.command_blend_tau
    own = OwnRollouts(layout, stats, data.test_origin, 10, torch.device("cpu"), tau)
    own = own.inputs(model, x, y)
    with torch.no_grad():
        on_data = ((model(x[None]) - y) ** 2).mean().item()
        on_own = ((model(own) - y) ** 2).mean().item()
    with (tmp_path / "p" / "seed0.csv").open() as file:
        rows = list(csv.DictReader(file))
    recorded = float(rows[meta["best_epoch"] - 1]["test_mse"])
    assert abs(on_own - on_data) > 1e-4  # the mix is told apart from either part
    assert recorded == pytest.approx((1 - share) * on_data + share * on_own, abs=1e-5)


def test_held_out_loss_batches_and_mixes_the_data_and_own_inputs(own):
    """batched_loss in batches of 7 equals one pass over every sample, shared or per-member
    inputs; HeldOutLoss weighs the own-rollout inputs by the share."""
    data, model, rollouts, x, y, inputs = own
    cpu = torch.device("cpu")
    loss = TrainingLoss(data.layout, data.stats, "predicted", cpu)
    with torch.no_grad():
        once = loss(model(x.expand(2, -1, -1)), y.expand(2, -1, -1))
        own_once = loss(model(inputs), y.expand(2, -1, -1))
    for inputs_, expected in ((x, once), (inputs, own_once)):
        batched = batched_loss(model, loss, inputs_, y, None, 7)
        for got, want in zip(batched, expected, strict=True):
            torch.testing.assert_close(got, want, rtol=1e-5, atol=1e-7)
    assert not torch.allclose(once[0], own_once[0])  # the mix below is not trivially equal
    mixed = HeldOutLoss(loss, x, y, None, 7, rollouts, 0.25)(model)
    for got, a, b in zip(mixed, once, own_once, strict=True):
        torch.testing.assert_close(got, 0.75 * a + 0.25 * b, rtol=1e-5, atol=1e-7)
    plain = HeldOutLoss(loss, x, y, None, 7, None, 0.25)(model)
    torch.testing.assert_close(plain[0], once[0], rtol=1e-5, atol=1e-7)


def test_own_inputs_feed_back_the_gait_phase_as_the_joints(params):
    """With features.gait_phase the phase is fed-back state: row k's is the member's predicted
    one at row k - 1 (as the joints), each piece's first row the data's."""
    from builders import synthetic_collection

    from pimann.learn.features import build_dataset

    features = dataclasses.replace(params.features, gait_phase=True, gait_phase_step_s=0.8)
    data = build_dataset(synthetic_collection(n_sources=3, frames=160), features, "full")
    layout, stats = data.layout, data.stats
    xs, ys = layout.x_slices, layout.y_slices
    assert "gait_phase" in xs and np.ptp(data.x_train[:, xs["gait_phase"]]) > 0
    model = MANN.from_seeds(layout.input_dim, layout.output_dim, SMALL_MODEL, [5]).eval()
    rollouts = OwnRollouts(layout, stats, data.train_origin, 6, torch.device("cpu"))
    x, y = torch.as_tensor(data.x_train), torch.as_tensor(data.y_train)
    inputs = rollouts.inputs(model, x, y)
    later = rollouts.pieces[:, 1:]
    rows, previous = later[later >= 0], rollouts.pieces[:, :-1][later >= 0]
    with torch.no_grad():
        predicted = model(inputs[:, previous]).numpy() * stats.y_std + stats.y_mean
    own_x = inputs[:, rows].numpy() * stats.x_std + stats.x_mean
    np.testing.assert_allclose(
        own_x[..., xs["gait_phase"]], predicted[..., ys["gait_phase"]], atol=1e-4
    )
    first = rollouts.pieces[:, 0]
    assert torch.equal(inputs[0, first][:, xs["gait_phase"]], x[first][:, xs["gait_phase"]])
