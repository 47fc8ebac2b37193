"""train.rollout_states: training inputs from the model's own short rollouts (DAgger-style).

A rollout feeds the network its own predictions: the joints and their velocities, the
velocity window up to now, and the future window (the previous prediction's, blended with the
command; pimann.learn.future_window). Trained on the data's states only, the network never sees the
states its own errors lead to, and in rollouts the legs' swing shrinks step by step: fed its
own joints and velocity history (the data's future window and pose kept), a quick w=0 model's
knee swing fell from 0.22 to 0.13 rad (std; data 0.27) on backward clips, with the future
window set to a constant command as well to 0.04, and no rollout of it took a backward step.

Here each member rolls itself out along the training clips, in pieces of `steps` frames that
start on the data's state: at each step it gets the data's input with the fed-back columns
replaced by its own, and predicts. The joints and joint velocities are those of its previous
prediction; a past velocity sample is the data's plus the member's error in predicting that
velocity (the error is small, so it is not rotated between the base frames of the two steps);
the future samples are the previous prediction's output window blended with a command, as a
rollout makes them, the command being the data's mean velocity over the future window. A
training sample then pairs such an input with the data's output at its step: the network
learns to lead a drifted state back onto the data. Computed at the start of each epoch from
the member's current weights, dropout off, so a resumed run recomputes the same inputs.
"""

from __future__ import annotations

import numpy as np
import torch

from pimann.core.params import TrainParams
from pimann.learn.dataset import FeatureDataset
from pimann.learn.epochs import epoch_seed
from pimann.learn.feature_layout import FeatureLayout, Normalisation
from pimann.learn.future_window import command_weights, next_future_matrix


def rollout_pieces(origin: np.ndarray, steps: int) -> np.ndarray:
    """(P, steps) row indices of consecutive frames of one clip (-1: past a piece's end).

    `origin` (N, 2): clip index and step of each row; a piece ends at `steps` frames, at a
    change of clip or at a gap in the steps.
    """
    n = len(origin)
    if n == 0:
        return np.empty((0, steps), dtype=np.int64)
    start = np.ones(n, dtype=bool)
    start[1:] = (origin[1:, 0] != origin[:-1, 0]) | (origin[1:, 1] != origin[:-1, 1] + 1)
    run = np.cumsum(start) - 1  # index of each row's run of consecutive frames
    run_start = np.flatnonzero(start)
    position = np.arange(n) - run_start[run]
    piece = np.cumsum(start | (position % steps == 0)) - 1
    pieces = np.full((piece[-1] + 1, steps), -1, dtype=np.int64)
    pieces[piece, position % steps] = np.arange(n)
    return pieces


def _sample(block: slice, k: int) -> np.ndarray:
    """The x, y, z columns of a window block's sample k."""
    return np.arange(block.start + 3 * k, block.start + 3 * k + 3)


class OwnRollouts:
    """Each member's own-rollout inputs for every training row (see the module docstring)."""

    def __init__(
        self,
        layout: FeatureLayout,
        stats: Normalisation,
        origin: np.ndarray,
        steps: int,
        device: torch.device,
        command_blend_tau: float | None = None,
    ):
        self.pieces = torch.as_tensor(rollout_pieces(origin, steps), device=device)
        self.device = device

        def tensor(values: np.ndarray) -> torch.Tensor:
            return torch.as_tensor(np.asarray(values), dtype=torch.float32, device=device)

        xs, ys = layout.x_slices, layout.y_slices
        # the joints and their velocities (and the gait phase): y's columns -> x's, normalised
        state = layout.fed_back_state()
        self.x_state = np.concatenate([np.arange(xs[b].start, xs[b].stop) for b in state])
        y_state = np.concatenate([np.arange(ys[b].start, ys[b].stop) for b in state])
        self.y_state = y_state
        self.state_scale = tensor(stats.y_std[y_state] / stats.x_std[self.x_state])
        self.state_shift = tensor((stats.y_mean[y_state] - stats.x_mean[self.x_state])
                                  / stats.x_std[self.x_state])  # fmt: skip
        # the velocity at the current step: y's sample at offset 0, linear then angular
        blocks = ("base_linear", "base_angular")
        self.y_now = np.concatenate(
            [_sample(ys[f"{b}_future"], layout.current_output) for b in blocks]
        )
        self.y_now_std = tensor(stats.y_std[self.y_now])
        # the past samples of the input window: (offset in frames, x columns, linear + angular)
        self.past = []
        for k, offset in enumerate(layout.input_offsets):
            if offset <= 0:
                columns = np.concatenate([_sample(xs[f"{b}_window"], k) for b in blocks])
                self.past.append((int(offset), columns, tensor(1.0 / stats.x_std[columns])))
        # the future samples as a rollout fills them (pimann.learn.future_window), the command being
        # the data's mean velocity over the input's future samples; None: the data's own
        self.future = None
        if command_blend_tau is not None:
            future = [k for k, offset in enumerate(layout.input_offsets) if offset > 0]
            x_future = np.stack(
                [np.concatenate([_sample(xs[f"{b}_window"], k) for b in blocks]) for k in future]
            )  # (F_in, 6)
            y_future = np.stack(
                [
                    np.concatenate([_sample(ys[f"{b}_future"], k) for b in blocks])
                    for k in range(len(layout.output_offsets))
                ]
            )  # fmt: skip  (F_out, 6)
            weights = command_weights(layout.output_offsets, command_blend_tau)
            matrix = next_future_matrix(layout)
            self.future = {
                "x": x_future, "y": y_future,
                "own": tensor(matrix * (1.0 - weights)), "command": tensor(matrix @ weights),
                "x_mean": tensor(stats.x_mean[x_future]), "x_std": tensor(stats.x_std[x_future]),
                "y_mean": tensor(stats.y_mean[y_future]), "y_std": tensor(stats.y_std[y_future]),
            }  # fmt: skip

    @torch.no_grad()
    def inputs(self, model: torch.nn.Module, x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        """(E, N, in): x (N, in) with each member's own fed-back columns; y (N, out) the data's
        outputs (normalised, as x)."""
        was_training = model.training
        model.eval()
        members = model.ensemble
        out = x.expand(members, -1, -1).clone()
        pieces, length = self.pieces, self.pieces.shape[1]
        # each member's error in the current velocity, per piece and position (physical units)
        error = torch.zeros(members, len(pieces), length, len(self.y_now), device=self.device)
        previous = None
        for h in range(length):
            valid = pieces[:, h] >= 0
            rows = pieces[valid, h]
            xh = x[rows].expand(members, -1, -1).clone()
            if previous is not None:
                xh[..., self.x_state] = (
                    previous[:, valid][..., self.y_state] * self.state_scale + self.state_shift
                )
                for offset, columns, inverse_std in self.past:
                    source = h + offset - 1  # a rollout's newest sample is the previous step's
                    if source >= 0:
                        xh[..., columns] += error[:, valid, source] * inverse_std
                if self.future is not None:
                    xh[..., self.future["x"].ravel()] = self._future(previous[:, valid], xh)
            out[:, rows] = xh
            prediction = model(xh)
            error[:, valid, h] = prediction[..., self.y_now] - y[rows][:, self.y_now]
            error[:, valid, h] *= self.y_now_std
            previous = torch.zeros(members, len(pieces), prediction.shape[-1], device=self.device)
            previous[:, valid] = prediction
        model.train(was_training)
        return out

    def _future(self, previous: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
        """(E, C, F_in * 6) normalised future samples: the previous prediction's output window
        (already one frame ahead), blended with the command (the data's mean over x's future
        samples)."""
        f = self.future
        own = previous[..., f["y"]] * f["y_std"] + f["y_mean"]  # (E, C, F_out, 6)
        data = x[..., f["x"]] * f["x_std"] + f["x_mean"]  # (E, C, F_in, 6)
        command = data.mean(dim=-2, keepdim=True)
        future = torch.einsum("ij,ecjd->ecid", f["own"], own) + f["command"][:, None] * command
        return ((future - f["x_mean"]) / f["x_std"]).flatten(-2)


class RolloutStates:
    """train.rollout_states: from epoch `first_epoch` on, each training sample's input is,
    with probability `fraction`, the member's own-rollout input (`OwnRollouts`) instead of the
    data's. Each member draws from its own seed and epoch."""

    def __init__(
        self,
        fraction: float,
        first_epoch: int,
        rollouts: OwnRollouts | None,
        x: torch.Tensor,
        y: torch.Tensor,
        kept: torch.Tensor,
        seeds: list[int],
    ):
        self.fraction, self.first_epoch, self.rollouts = fraction, first_epoch, rollouts
        self.x, self.y, self.kept, self.seeds = x, y, kept, seeds
        self.own: torch.Tensor | None = None  # (E, n, in) for the kept rows
        self.generators: list[torch.Generator] = []

    def start_epoch(self, model: torch.nn.Module, epoch: int) -> None:
        """Roll each member out with its weights at the start of `epoch`."""
        self.own = None
        if self.fraction == 0.0 or self.rollouts is None or epoch < self.first_epoch:
            return
        self.own = self.rollouts.inputs(model, self.x, self.y)[:, self.kept]
        self.generators = [
            torch.Generator(self.x.device).manual_seed(epoch_seed(seed, epoch, "rollout_states"))
            for seed in self.seeds
        ]

    def __call__(self, x: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
        """x (E, B, in) of the rows `index` (E, B): some replaced by own-rollout inputs."""
        if self.own is None:
            return x
        own = self.own[torch.arange(len(index), device=index.device)[:, None], index]
        use = torch.stack(
            [torch.rand(index.shape[1], generator=g, device=x.device) for g in self.generators]
        )
        return torch.where((use < self.fraction)[..., None], own, x)


def training_states(
    config: TrainParams,
    command_blend_tau: float,
    data: FeatureDataset,
    keep: np.ndarray,
    seeds: list[int],
    device: torch.device,
) -> tuple[RolloutStates, OwnRollouts | None]:
    """train.rollout_states for a training run: rolled out along every training sample and used
    on the `keep` ones, and the test clips' own rollouts; neither holds data when it is off."""
    kept = torch.as_tensor(keep, device=device)
    if config.rollout_states == 0.0:
        nothing = torch.empty(0, device=device)
        return RolloutStates(0.0, 0, None, nothing, nothing, kept, seeds), None
    x, y = (torch.as_tensor(a, dtype=torch.float32, device=device)
            for a in (data.x_train, data.y_train))  # fmt: skip
    rollouts, test_rollouts = (
        OwnRollouts(data.layout, data.stats, origin, config.rollout_steps, device,
                    command_blend_tau)
        for origin in (data.train_origin, data.test_origin)
    )  # fmt: skip
    states = RolloutStates(config.rollout_states, config.restart_period, rollouts, x, y, kept,
                           seeds)  # fmt: skip
    return states, test_rollouts
