"""The network as a rollout calls it: physical inputs in, physical outputs out, a batch of
rows at a time, at the least overhead a CPU allows (pimann.generate.batch_generator)."""

from __future__ import annotations

import numpy as np
import torch

from pimann.core.errors import PimannError
from pimann.learn.feature_layout import FeatureLayout, Normalisation
from pimann.learn.mann import MANN


class NumpyMANN:
    """`MANN.forward` of a one-member CPU model in numpy, the same parameters and operations.

    A rollout alone calls the network with one sample a step, where torch's per-operation
    overhead and MKL's matrix-vector products (the 512 x 2048 layer: 100 us on one core of an
    AMD EPYC, OpenBLAS 55 us) make torch twice numpy's time (about 120 us a step in numpy;
    6 MB of float32 weights read a step). A batch runs transposed, W^T (K out, in) @ h^T
    (in, B): OpenBLAS's x @ W packs all of W at every call, 450-600 us for the 512 x 2048
    layer at 2 to 8 rows (8x one row's matrix-vector product), which is what a batch's last
    rows (the longest scripts) cost; transposed, 2 rows take half that and 32 rows 20% less.
    One row keeps x @ W (a matrix-vector product).
    Equal to `MANN.forward` to rounding (float32: 1e-7; tests/test_batch_generator.py). A
    snapshot: later changes to the model's parameters are not seen.
    """

    def __init__(self, model: MANN):
        if model.ensemble != 1:
            raise ValueError(f"one member, not an ensemble of {model.ensemble}")
        member = {
            name: value[0].detach().cpu().numpy().copy()
            for name, value in model.state_dict().items()
        }
        self.n_experts = model.n_experts
        # (weight (in, out), its transpose (out, in), bias) per layer; the gate's are stored
        # (out, in) as nn.Linear's, the experts' blocks (in, K out)
        self.gate = [
            self._layer(member[f"gate_weight_{i}"].T, member[f"gate_bias_{i}"])
            for i in range(model.n_gate_layers)
        ]
        self.experts = [
            self._layer(member[f"expert_weight_{i}"], member[f"expert_bias_{i}"])
            for i in range(model.n_expert_layers)
        ]

    @staticmethod
    def _layer(weight: np.ndarray, bias: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return np.ascontiguousarray(weight), np.ascontiguousarray(weight.T), bias

    @staticmethod
    def _elu(h: np.ndarray) -> np.ndarray:
        return np.maximum(h, 0) + np.expm1(np.minimum(h, 0))

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """y (B, out) for x (B, in), in the model's dtype."""
        if len(x) == 1:
            return self._rows(x)
        return np.ascontiguousarray(self._columns(np.ascontiguousarray(x.T)).T)

    def _rows(self, x: np.ndarray) -> np.ndarray:
        """The network on x (B, in), samples as rows."""
        h = x
        for i, (weight, _, bias) in enumerate(self.gate):
            h = h @ weight + bias
            if i < len(self.gate) - 1:
                h = self._elu(h)
        h = np.exp(h - h.max(axis=-1, keepdims=True))
        theta = (h / h.sum(axis=-1, keepdims=True))[:, None]  # (B, 1, K)
        h = x
        for i, (weight, _, bias) in enumerate(self.experts):
            out = (h @ weight + bias).reshape(len(x), self.n_experts, -1)
            h = (theta @ out)[:, 0]  # sum_j theta_j (W_j h + b_j)
            if i < len(self.experts) - 1:
                h = self._elu(h)
        return h

    def _columns(self, x: np.ndarray) -> np.ndarray:
        """The network on x (in, B), samples as columns; (out, B)."""
        h = x
        for i, (_, weight, bias) in enumerate(self.gate):
            h = weight @ h + bias[:, None]
            if i < len(self.gate) - 1:
                h = self._elu(h)
        h = np.exp(h - h.max(axis=0, keepdims=True))
        theta = h / h.sum(axis=0, keepdims=True)  # (K, B)
        h = x
        for i, (_, weight, bias) in enumerate(self.experts):
            out = (weight @ h + bias[:, None]).reshape(self.n_experts, -1, h.shape[1])
            h = out[0] * theta[0]  # sum_j theta_j (W_j h + b_j)
            for j in range(1, self.n_experts):
                h += out[j] * theta[j]
            if i < len(self.experts) - 1:
                h = self._elu(h)
        return h


class RolloutNetwork:
    """x (B, in) -> y (B, out), physical units, in the model's dtype; call in inference mode.

    At batch 1 the conversions cost as much as a small layer: numpy casts to the model's
    dtype, and the caller holds one `torch.inference_mode` over the whole rollout. A
    one-member MANN on the CPU runs as `NumpyMANN` (half torch's time at batch 1, 3/4 at 32);
    an ensemble, another module or a GPU keeps torch.
    """

    def __init__(self, model: torch.nn.Module, layout: FeatureLayout, stats: Normalisation):
        self.model = model.eval()
        parameter = next(model.parameters(), None)
        dtype = torch.float32 if parameter is None else parameter.dtype
        self.device = None if parameter is None or parameter.device.type == "cpu" else parameter
        self.np_dtype = torch.empty(0, dtype=dtype).numpy().dtype
        self.numpy = None
        if self.device is None and isinstance(model, MANN) and model.ensemble == 1:
            self.numpy = NumpyMANN(model)
        self.x_mean, self.x_scale = stats.x_mean.astype(float), 1.0 / stats.x_std.astype(float)
        self.y_mean, self.y_std = stats.y_mean.astype(float), stats.y_std.astype(float)
        if len(self.x_mean) != layout.input_dim or len(self.y_mean) != layout.output_dim:
            raise PimannError(None, "normalisation statistics do not match the feature layout")

    def __call__(self, x: np.ndarray) -> np.ndarray:
        x = ((x - self.x_mean) * self.x_scale).astype(self.np_dtype)
        if self.numpy is not None:
            return self.numpy(x) * self.y_std + self.y_mean  # float64
        tensor = torch.from_numpy(x)
        if self.device is not None:
            tensor = tensor.to(self.device.device)
        y = self.model(tensor)
        y = (y if self.device is None else y.cpu()).numpy()
        return y * self.y_std + self.y_mean  # float64
