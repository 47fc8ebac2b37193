"""MANN: expert blending against plain per-expert MLPs, ensembles against single models."""

from __future__ import annotations

import dataclasses

import pytest
import torch
import torch.nn.functional as F

from pimann.core.params import ModelParams, load_params
from pimann.learn.mann import MANN

IN, OUT = 13, 7


@pytest.fixture(scope="module")
def params() -> ModelParams:
    # the paper's architecture, narrower so the tests stay fast
    return dataclasses.replace(load_params().model, prediction_hidden=24, gating_hidden=8)


def plain_mlp(model: MANN, expert: int, x: torch.Tensor) -> torch.Tensor:
    """Expert `expert` as an ordinary MLP built from its weights with F.linear (member 0)."""
    h = x
    for layer in range(model.n_expert_layers):
        weight, bias = model.expert_layer(expert, layer)
        h = F.linear(h, weight[0], bias[0])
        if layer < model.n_expert_layers - 1:
            h = F.elu(h)
    return h


def test_forced_gate_equals_that_experts_mlp(params):
    model = MANN(IN, OUT, params, seeds=[3]).eval()
    x = torch.randn(5, IN, generator=torch.Generator().manual_seed(0))
    outputs = [model(x, forced_gate=j) for j in range(params.n_experts)]
    for j, out in enumerate(outputs):
        assert out.shape == (5, OUT)
        torch.testing.assert_close(out, plain_mlp(model, j, x), rtol=1e-6, atol=1e-6)
    assert (outputs[0] - outputs[1]).abs().max() > 1e-3  # experts differ


def test_blending_outputs_equals_blending_weights(params):
    """Per-sample blended weights sum_j theta_j W_j (MANN's definition) give the same result."""
    model = MANN(IN, OUT, params, seeds=[4]).eval()
    x = torch.randn(6, IN, generator=torch.Generator().manual_seed(1))
    theta = model.gate(x)
    assert theta.shape == (6, params.n_experts)
    torch.testing.assert_close(theta.sum(-1), torch.ones(6))
    expected = []
    for b in range(len(x)):
        h = x[b]
        for layer in range(model.n_expert_layers):
            pairs = [model.expert_layer(j, layer) for j in range(params.n_experts)]
            weight = sum(theta[b, j] * w[0] for j, (w, _) in enumerate(pairs))
            bias = sum(theta[b, j] * c[0] for j, (_, c) in enumerate(pairs))
            h = F.linear(h, weight, bias)
            if layer < model.n_expert_layers - 1:
                h = F.elu(h)
        expected.append(h)
    torch.testing.assert_close(model(x), torch.stack(expected), rtol=1e-5, atol=1e-6)


def test_ensemble_members_equal_single_models(params):
    seeds = [11, 12, 13]
    ensemble = MANN.from_seeds(IN, OUT, params, seeds).eval()
    x = torch.randn(3, 4, IN, generator=torch.Generator().manual_seed(2))
    out = ensemble(x)
    assert out.shape == (3, 4, OUT)
    for k, seed in enumerate(seeds):
        single = MANN(IN, OUT, params, seeds=[seed]).eval()
        for name, value in single.named_parameters():
            torch.testing.assert_close(getattr(ensemble, name)[k], value[0], rtol=0, atol=0)
        torch.testing.assert_close(out[k], single(x[k]), rtol=1e-6, atol=1e-6)
        torch.testing.assert_close(ensemble.member(k)(x[k]), out[k], rtol=0, atol=0)
    assert (out[0] - out[1]).abs().max() > 1e-3


def test_members_train_independently(params):
    """A summed loss gives each member the gradient it would get alone."""
    ensemble = MANN.from_seeds(IN, OUT, params, [5, 6]).eval()
    x = torch.randn(2, 8, IN, generator=torch.Generator().manual_seed(3))
    y = torch.randn(2, 8, OUT, generator=torch.Generator().manual_seed(4))
    ((ensemble(x) - y) ** 2).mean(dim=(1, 2)).sum().backward()
    single = MANN(IN, OUT, params, seeds=[6]).eval()
    ((single(x[1]) - y[1]) ** 2).mean().backward()
    for name, value in single.named_parameters():
        torch.testing.assert_close(getattr(ensemble, name).grad[1], value.grad[0])


def test_dropout_only_in_training(params):
    model = MANN(IN, OUT, params, seeds=[0])
    x = torch.randn(4, IN, generator=torch.Generator().manual_seed(5))
    torch.manual_seed(0)
    assert (model(x) - model(x)).abs().max() > 0  # dropout masks differ between calls
    model.eval()
    torch.testing.assert_close(model(x), model(x), rtol=0, atol=0)


def test_seeded_dropout_is_per_member(params):
    """A member's dropout masks come from its own seed, not from the ensemble it is in."""
    ensemble = MANN.from_seeds(IN, OUT, params, [3, 4]).train()
    single = MANN(IN, OUT, params, seeds=[4]).train()
    x = torch.randn(2, 64, IN, generator=torch.Generator().manual_seed(6))
    ensemble.seed_dropout([100, 200])
    single.seed_dropout([200])
    torch.testing.assert_close(ensemble(x)[1], single(x[1]), rtol=1e-6, atol=1e-6)
    ensemble.eval()
    clean = ensemble(x)
    ensemble.train()
    assert (ensemble(x)[1] - clean[1]).abs().max() > 1e-3  # dropout is on
    # about 30% of a layer's inputs dropped, the kept ones scaled by 1 / 0.7
    h = torch.ones(2, 1000, 512)
    dropped = ensemble._dropout(h)
    assert dropped.unique().tolist() == pytest.approx([0.0, 1 / 0.7])
    assert (dropped == 0).float().mean().item() == pytest.approx(params.dropout, abs=0.01)


def test_forward_with_clean_equals_a_training_and_an_eval_pass(params):
    """One doubled pass gives the same dropout-perturbed prediction (same draws) and the
    eval-mode one, and gradients through both halves equal the two-pass ones."""
    x = torch.randn(2, 16, IN, generator=torch.Generator().manual_seed(7))
    fused = MANN.from_seeds(IN, OUT, params, [3, 4]).train()
    twice = MANN.from_seeds(IN, OUT, params, [3, 4]).train()
    fused.seed_dropout([10, 20])
    twice.seed_dropout([10, 20])
    dropped, clean = fused.forward_with_clean(x)
    expected_dropped = twice(x)
    twice.eval()
    expected_clean = twice(x)
    twice.train()
    torch.testing.assert_close(dropped, expected_dropped, rtol=1e-5, atol=1e-6)
    torch.testing.assert_close(clean, expected_clean, rtol=1e-5, atol=1e-6)
    assert (dropped - clean).abs().max() > 1e-3  # the first half did get dropout
    (dropped.square().sum() + 2 * clean.sum()).backward()
    (expected_dropped.square().sum() + 2 * expected_clean.sum()).backward()
    for (name, a), b in zip(fused.named_parameters(), twice.parameters(), strict=True):
        torch.testing.assert_close(a.grad, b.grad, rtol=1e-4, atol=1e-6, msg=name)
    single = MANN(IN, OUT, params, seeds=[0]).eval()  # 2-D input, eval mode: both clean
    first, second = single.forward_with_clean(x[0])
    assert first.shape == (16, OUT)
    torch.testing.assert_close(first, second, rtol=0, atol=0)


def test_rejects_wrong_shapes(params):
    with pytest.raises(ValueError, match="x must be"):
        MANN.from_seeds(IN, OUT, params, [0, 1])(torch.zeros(4, IN))
    with pytest.raises(ValueError, match="seeds"):
        MANN(IN, OUT, params, ensemble=2, seeds=[0])


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")
def test_cuda_matches_cpu(params):
    model = MANN(IN, OUT, params, seeds=[7]).eval()
    x = torch.randn(4, IN)
    torch.testing.assert_close(model.to("cuda")(x.cuda()).cpu(), model.cpu()(x))
