"""The test loss that picks each member's best epoch (pimann.learn.train, pimann.learn.sweep)."""

from __future__ import annotations

import torch

from pimann.learn.mann import MANN
from pimann.learn.training_loss import TrainingLoss


def batched_loss(
    model: MANN, loss: TrainingLoss, x: torch.Tensor, y: torch.Tensor, batch: int
) -> tuple[torch.Tensor, torch.Tensor]:
    """(L_D, L_B) per member, averaged over the samples, dropout off; x (N, in) shared by the
    members, in batches of `batch` samples (the model's mode is restored after)."""
    training = model.training
    model.eval()
    totals = torch.zeros(2, model.ensemble, device=x.device)
    n = x.shape[-2]
    with torch.no_grad():
        for start in range(0, n, batch):
            xb = x[..., start : start + batch, :].expand(model.ensemble, -1, -1)
            yb = y[start : start + batch].expand(model.ensemble, -1, -1)
            mse, pi = loss(model(xb), yb, True)
            totals += torch.stack([mse, pi]) * xb.shape[1]
    model.train(training)
    return totals[0] / n, totals[1] / n
