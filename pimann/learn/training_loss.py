"""The training loss L = L_D + w L_B per ensemble member (paper Sec. III-B, Eq. overall_loss).

L_D is the MSE on the normalised outputs; L_B (`PhysicsInformedLoss`) is taken in physical
units on the denormalised prediction: the base twist at step i (the output window's offset
0), the joint velocities, and the configuration (base position, rpy, joints) predicted, or
the ground truth's with `train.pi_configuration: ground_truth`. The support foot is the lower
predicted sole (the paper).
"""

from __future__ import annotations

from typing import NamedTuple

import torch

from pimann.core.params import TrainParams
from pimann.core.robot import load_robot
from pimann.learn.feature_layout import FeatureLayout, Normalisation
from pimann.learn.physics_loss import PhysicsInformedLoss
from pimann.learn.pi_gradient import HELD_PREDICTIONS


class LossTerms(NamedTuple):
    """The named terms of L per member, each (E,) averaged over the batch."""

    data: torch.Tensor  # L_D, the normalised MSE
    physics: torch.Tensor  # L_B; zeros where it was not taken

    def total(self, pi_weight: float | torch.Tensor) -> torch.Tensor:
        """L = L_D + w L_B; `pi_weight` one w for all members or each member's (E,)."""
        return self.data + pi_weight * self.physics


class TrainingLoss(torch.nn.Module):
    """Per-member L_D (normalised MSE) and L_B (physical units) of an ensemble's prediction."""

    def __init__(
        self,
        layout: FeatureLayout,
        stats: Normalisation,
        device: torch.device,
        *,
        pi_configuration: str,
        pi_gradient: str,
    ):
        super().__init__()
        self.layout, self.pi_configuration = layout, pi_configuration
        self.held = HELD_PREDICTIONS[pi_gradient]
        self.register_buffer("y_mean", torch.as_tensor(stats.y_mean, dtype=torch.float32))
        self.register_buffer("y_std", torch.as_tensor(stats.y_std, dtype=torch.float32))
        self.physics = PhysicsInformedLoss(load_robot("retarget"), torch.float32, device)
        self.to(device)

    @classmethod
    def from_params(
        cls,
        train: TrainParams,
        layout: FeatureLayout,
        stats: Normalisation,
        device: torch.device,
    ) -> TrainingLoss:
        """The loss the trainers minimise, as `train` sets it (one place for both trainers)."""
        return cls(
            layout,
            stats,
            device,
            pi_configuration=train.pi_configuration,
            pi_gradient=train.pi_gradient,
        )

    def pi_terms(self, y: torch.Tensor) -> dict[str, torch.Tensor]:
        """Denormalised quantities of y (..., out) that L_B needs, by argument name."""
        physical = y * self.y_std + self.y_mean
        s = self.layout.y_slices
        now = self.layout.current_output

        def at_now(block: str) -> torch.Tensor:
            return physical[..., s[block]].unflatten(-1, (-1, 3))[..., now, :]

        return {
            "base_position": physical[..., s["base_position"]],
            "base_rpy": physical[..., s["base_rpy"]],
            "joints": physical[..., s["joints"]],
            "base_linear_velocity": at_now("base_linear_future"),
            "base_angular_velocity": at_now("base_angular_future"),
            "joint_velocities": physical[..., s["joint_velocities"]],
        }

    def forward(
        self,
        prediction: torch.Tensor,
        target: torch.Tensor,
        with_pi: bool = True,
        pi_prediction: torch.Tensor | None = None,
    ) -> LossTerms:
        """L_D and L_B of `prediction` against `target`; L_B is 0 when `with_pi` is False.

        `pi_prediction`: the prediction L_B is taken on, when not `prediction` (train.pi_dropout
        false: the same inputs without dropout).
        """
        mse = (prediction - target).square().mean(dim=(-2, -1))
        if not with_pi:
            return LossTerms(mse, torch.zeros_like(mse))
        terms = self.pi_terms(prediction if pi_prediction is None else pi_prediction)
        if self.pi_configuration == "ground_truth":
            truth = self.pi_terms(target)
            for name in ("base_position", "base_rpy", "joints"):
                terms[name] = truth[name]
        for name in self.held:
            terms[name] = terms[name].detach()
        return LossTerms(mse, self.physics(**terms).mean(-1))
