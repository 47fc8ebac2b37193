"""The test loss that picks each member's best epoch (pimann.learn.train).

With train.rollout_states the network is trained on its own rollouts' inputs as well as the
data's; the test loss weighs the test clips' own-rollout inputs alike, or it would pick the
last epoch before the own rollouts start (a quick w=10 run picked epoch 10 of 70).
"""

from __future__ import annotations

import dataclasses

import torch

from pimann.learn.mann import MANN
from pimann.learn.rollout_states import OwnRollouts
from pimann.learn.training_loss import TrainingLoss


def batched_loss(
    model: MANN,
    loss: TrainingLoss,
    x: torch.Tensor,
    y: torch.Tensor,
    contacts: torch.Tensor | None,
    batch: int,
) -> tuple[torch.Tensor, torch.Tensor]:
    """(mse, pi) per member, averaged over the samples, dropout off; x (N, in) shared by the
    members or each member's own (E, N, in), in batches of `batch` samples; the model's
    mode is restored after."""
    training = model.training
    model.eval()
    totals = torch.zeros(2, model.ensemble, device=x.device)
    n = x.shape[-2]
    with torch.no_grad():
        for start in range(0, n, batch):
            xb = x[..., start : start + batch, :].expand(model.ensemble, -1, -1)
            yb = y[start : start + batch].expand(model.ensemble, -1, -1)
            cb = None
            if contacts is not None:
                cb = contacts[start : start + batch].expand(model.ensemble, -1, -1)
            mse, pi = loss(model(xb), yb, True, cb)
            totals += torch.stack([mse, pi]) * xb.shape[1]
    model.train(training)
    return totals[0] / n, totals[1] / n


@dataclasses.dataclass
class HeldOutLoss:
    """(mse, pi) per member on the test set: (1 - share) x the data's inputs + share x the
    member's own-rollout inputs (`rollouts`; None: the data's only)."""

    loss: TrainingLoss
    x: torch.Tensor
    y: torch.Tensor
    contacts: torch.Tensor | None
    batch: int
    rollouts: OwnRollouts | None
    share: float

    def __call__(self, model: MANN) -> tuple[torch.Tensor, torch.Tensor]:
        data = batched_loss(model, self.loss, self.x, self.y, self.contacts, self.batch)
        if self.rollouts is None:
            return data
        own_x = self.rollouts.inputs(model, self.x, self.y)
        own = batched_loss(model, self.loss, own_x, self.y, self.contacts, self.batch)
        mixed = ((1.0 - self.share) * a + self.share * b for a, b in zip(data, own, strict=True))
        return tuple(mixed)
