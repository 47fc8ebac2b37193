"""Mode-Adaptive Neural Network (Zhang et al. 2018), vectorised over an ensemble of models.

A gating network turns the input into K expert weights theta; each layer of the prediction
network uses, per sample, the blended weights sum_j theta_j W_j. Blending the K experts'
outputs, sum_j theta_j (W_j h + b_j), is the same for a linear layer and much cheaper: one
matmul against all experts at once instead of one weight matrix per sample (14x faster on this CPU).

`ensemble` models (e.g. the 5 seeds of one PI weight) live in one module with a leading
ensemble dim on every parameter, so one optimiser step trains all of them. Members never
mix: summing the members' losses gives each member exactly its solo gradient, AdamW acts
elementwise (do not clip the gradient norm across members), and with `seed_dropout` each
member draws its dropout masks from its own generator, so a member trains the same whatever
ensemble it is part of.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

from pimann.core.params import ModelParams


def _linear_init(generator: torch.Generator, *shape: int) -> tuple[torch.Tensor, torch.Tensor]:
    """nn.Linear's default init, U(-1/sqrt(fan_in), 1/sqrt(fan_in)), for (..., out, in)."""
    bound = 1.0 / math.sqrt(shape[-1])
    weight = (torch.rand(shape, generator=generator) * 2 - 1) * bound
    bias = (torch.rand(shape[:-1], generator=generator) * 2 - 1) * bound
    return weight, bias


class MANN(nn.Module):
    """x (E, B, input_dim) -> y (E, B, output_dim); with ensemble 1 also (B, in) -> (B, out).

    Parameters: gate_weight_i (E, out, in), gate_bias_i (E, out), expert_weight_i
    (E, in, K * out) stored transposed for one batched matmul, expert_bias_i (E, K * out).
    Dropout precedes every linear layer, ELU follows every hidden one; the gate ends in a
    softmax over the K experts.
    """

    def __init__(
        self,
        input_dim: int,
        output_dim: int,
        params: ModelParams,
        ensemble: int = 1,
        seeds: list[int] | None = None,
    ):
        super().__init__()
        if seeds is None:  # follow torch's global seed, like nn.Linear
            seeds = torch.randint(0, 2**62, (ensemble,)).tolist()
        if len(seeds) != ensemble:
            raise ValueError(f"{len(seeds)} seeds for an ensemble of {ensemble}")
        if not 0.0 <= params.dropout < 1.0:
            raise ValueError(f"dropout must be in [0, 1), not {params.dropout}")
        if params.activation != "elu":
            raise ValueError(f"unsupported activation {params.activation!r}")
        self.input_dim, self.output_dim, self.ensemble = input_dim, output_dim, ensemble
        self.params, self.n_experts, self.dropout = params, params.n_experts, params.dropout
        self.seeds = list(seeds)
        self.dropout_generators: list[torch.Generator] | None = None
        gate_sizes = _sizes(input_dim, params.gating_hidden, params.n_experts, params.gating_layers)
        expert_sizes = _sizes(
            input_dim, params.prediction_hidden, output_dim, params.prediction_layers
        )
        members = [self._member(s, gate_sizes, expert_sizes) for s in seeds]
        for name in members[0]:
            self.register_parameter(name, nn.Parameter(torch.stack([m[name] for m in members])))
        self.n_gate_layers, self.n_expert_layers = len(gate_sizes) - 1, len(expert_sizes) - 1

    @classmethod
    def from_seeds(
        cls, input_dim: int, output_dim: int, params: ModelParams, seeds: list[int]
    ) -> MANN:
        """An ensemble whose member k equals MANN(..., seeds=[seeds[k]])."""
        return cls(input_dim, output_dim, params, ensemble=len(seeds), seeds=seeds)

    def _member(self, seed: int, gate_sizes: list[int], expert_sizes: list[int]) -> dict:
        """One model's initial parameters, drawn from its own seed in a fixed order."""
        generator = torch.Generator().manual_seed(seed)
        tensors = {}
        for i, (fan_in, fan_out) in enumerate(zip(gate_sizes, gate_sizes[1:], strict=False)):
            tensors[f"gate_weight_{i}"], tensors[f"gate_bias_{i}"] = _linear_init(
                generator, fan_out, fan_in
            )
        k = self.n_experts
        for i, (fan_in, fan_out) in enumerate(zip(expert_sizes, expert_sizes[1:], strict=False)):
            weight, bias = _linear_init(generator, k, fan_out, fan_in)  # each expert like Linear
            tensors[f"expert_weight_{i}"] = weight.permute(2, 0, 1).reshape(fan_in, k * fan_out)
            tensors[f"expert_bias_{i}"] = bias.reshape(k * fan_out)
        return tensors

    def seed_dropout(self, seeds: list[int] | None) -> None:
        """One dropout generator per member, seeded with seeds[k]; None: torch's global RNG."""
        if seeds is None:
            self.dropout_generators = None
            return
        if len(seeds) != self.ensemble:
            raise ValueError(f"{len(seeds)} dropout seeds for an ensemble of {self.ensemble}")
        device = next(self.parameters()).device
        self.dropout_generators = [torch.Generator(device).manual_seed(s) for s in seeds]

    def _dropout(self, h: torch.Tensor, rows: int | None = None) -> torch.Tensor:
        """Inverted dropout on the first `rows` samples of the batch (None: all of them).

        A uniform draw and a compare cost half of torch's bernoulli_. The draw is float32
        whatever h's dtype (bfloat16 under autocast), so both precisions drop the same units.
        """
        if not self.training or self.dropout == 0.0:
            return h
        shape = h.shape[1:] if rows is None else (rows,) + h.shape[2:]
        dtype = torch.promote_types(h.dtype, torch.float32)  # bfloat16 draws in float32
        if self.dropout_generators is None:
            noise = torch.rand((h.shape[0],) + shape, device=h.device, dtype=dtype)
        else:
            noise = torch.stack(
                [
                    torch.rand(shape, generator=g, device=h.device, dtype=dtype)
                    for g in self.dropout_generators
                ]
            )
        mask = ((noise >= self.dropout) * (1.0 / (1.0 - self.dropout))).to(h.dtype)
        if rows is not None:
            mask = torch.cat(
                [mask, mask.new_ones((h.shape[0], h.shape[1] - rows) + h.shape[2:])], 1
            )
        return h * mask

    def expert_layer(self, expert: int, layer: int) -> tuple[torch.Tensor, torch.Tensor]:
        """Expert `expert`'s plain weight (E, out, in) and bias (E, out) of one layer."""
        weight = getattr(self, f"expert_weight_{layer}")
        bias = getattr(self, f"expert_bias_{layer}")
        fan_in = weight.shape[1]
        weight = weight.view(self.ensemble, fan_in, self.n_experts, -1)[:, :, expert]
        return weight.transpose(1, 2), bias.view(self.ensemble, self.n_experts, -1)[:, expert]

    def _batched(self, x: torch.Tensor) -> tuple[torch.Tensor, bool]:
        if x.dim() == 2 and self.ensemble == 1:
            return x.unsqueeze(0), True
        if x.dim() != 3 or x.shape[0] != self.ensemble:
            raise ValueError(f"x must be (E={self.ensemble}, B, {self.input_dim}), not {x.shape}")
        return x, False

    def _gate(self, x: torch.Tensor, rows: int | None = None) -> torch.Tensor:
        h = x
        for i in range(self.n_gate_layers):
            h = self._dropout(h, rows)
            weight, bias = getattr(self, f"gate_weight_{i}"), getattr(self, f"gate_bias_{i}")
            h = torch.baddbmm(bias.unsqueeze(1), h, weight.transpose(1, 2))
            if i < self.n_gate_layers - 1:
                h = F.elu(h)
        return torch.softmax(h, -1)

    def gate(self, x: torch.Tensor) -> torch.Tensor:
        """Expert weights theta (E, B, K), or (B, K) for a 2-D x with ensemble 1."""
        x, squeeze = self._batched(x)
        theta = self._gate(x)
        return theta.squeeze(0) if squeeze else theta

    def forward(self, x: torch.Tensor, forced_gate: int | None = None) -> torch.Tensor:
        """Prediction; `forced_gate` = j uses expert j alone (theta one-hot), for tests."""
        x, squeeze = self._batched(x)
        h = self._predict(x, forced_gate)
        return h.squeeze(0) if squeeze else h

    def forward_with_clean(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The training prediction (with dropout) and the dropout-free one, in one pass.

        Equal to `model(x)` then `model.eval()(x)` (the same dropout draws) at about two
        thirds of the cost: the batch doubled, dropout on its first half only
        (train.pi_dropout: false).
        """
        x, squeeze = self._batched(x)
        rows = x.shape[1]
        both = self._predict(torch.cat([x, x], 1), None, rows)
        dropped, clean = both[:, :rows], both[:, rows:]
        return (dropped.squeeze(0), clean.squeeze(0)) if squeeze else (dropped, clean)

    def _predict(
        self, x: torch.Tensor, forced_gate: int | None, rows: int | None = None
    ) -> torch.Tensor:
        """x (E, B, in) -> (E, B, out); dropout on the first `rows` samples (None: all)."""
        if forced_gate is None:
            theta = self._gate(x, rows)
        else:
            theta = x.new_zeros(x.shape[:2] + (self.n_experts,))
            theta[..., forced_gate] = 1.0
        theta = theta.unsqueeze(-1)  # (E, B, K, 1)
        h = x
        for i in range(self.n_expert_layers):
            h = self._dropout(h, rows)
            weight = getattr(self, f"expert_weight_{i}")
            bias = getattr(self, f"expert_bias_{i}")
            out = torch.baddbmm(bias.unsqueeze(1), h, weight)  # (E, B, K * out)
            h = (out.unflatten(-1, (self.n_experts, -1)) * theta).sum(-2)
            if i < self.n_expert_layers - 1:
                h = F.elu(h)
        return h

    def member(self, k: int) -> MANN:
        """Member k as a stand-alone single model (a copy), e.g. to save or roll out alone."""
        single = MANN(self.input_dim, self.output_dim, self.params, seeds=[self.seeds[k]])
        state = {name: value[k : k + 1] for name, value in self.state_dict().items()}
        single.load_state_dict(state)
        return single.to(next(self.parameters()).device).train(self.training)


def _sizes(input_dim: int, hidden: int, output_dim: int, layers: int) -> list[int]:
    """Layer widths: `layers` linear layers from input_dim through `hidden` to output_dim."""
    return [input_dim] + [hidden] * (layers - 1) + [output_dim]
