"""The training loss L = L_D + w L_B per ensemble member (paper Sec. III-B, Eq. overall_loss).

L_D is the MSE on the normalised outputs; L_B (`PhysicsInformedLoss`) is taken in physical
units on the denormalised prediction: the base twist at step i (the output window's offset
0), the joint velocities, and the configuration (base position, rpy, joints) predicted, or
the ground truth's with `train.pi_configuration: ground_truth`.
"""

from __future__ import annotations

import torch

from pimann.core.robot import load_robot
from pimann.learn.feature_layout import FeatureLayout, Normalisation
from pimann.learn.physics_loss import PhysicsInformedLoss

# per `train.pi_gradient`: the predictions L_B's gradient does not move
_HELD = {
    "both": (),
    "joints": ("base_linear_velocity", "base_angular_velocity"),
    "base": ("base_position", "base_rpy", "joints", "joint_velocities"),
    "joint_velocities": (
        "base_linear_velocity",
        "base_angular_velocity",
        "base_position",
        "base_rpy",
        "joints",
    ),
}


class TrainingLoss(torch.nn.Module):
    """Per-member L_D (normalised MSE) and L_B (physical units) of an ensemble's prediction."""

    def __init__(
        self,
        layout: FeatureLayout,
        stats: Normalisation,
        pi_configuration: str,
        device: torch.device,
        pi_support: str = "lower_sole",
        pi_gradient: str = "both",
        consistency_weight: float = 0.0,
        pi_joint_velocities: str = "predicted",
        contact_height: float = 0.02,
        feet_weight: float = 0.0,
    ):
        super().__init__()
        self.pi_joint_velocities = pi_joint_velocities
        self.feet_weight, self.contact_height = float(feet_weight), float(contact_height)
        self.consistency_weight = float(consistency_weight)
        self.dt = 1.0 / float(layout.rate_hz)
        self.layout, self.pi_configuration = layout, pi_configuration
        self.pi_support, self.pi_gradient = pi_support, pi_gradient
        self.register_buffer("y_mean", torch.as_tensor(stats.y_mean, dtype=torch.float32))
        self.register_buffer("y_std", torch.as_tensor(stats.y_std, dtype=torch.float32))
        near_ground = contact_height if pi_support == "near_ground" else None
        self.physics = PhysicsInformedLoss(
            load_robot("retarget"), torch.float32, device, near_ground=near_ground
        )
        self.to(device)

    def consistency(self, prediction: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        """L_C (E,): how far the predicted joints and joint velocities are from agreeing.

        The data satisfy s_i = s_{i-1} + dt sdot_i, so s_{i-1} = s_true - dt sdot_true and the
        prediction's own disagreement is (s - s_true) / dt - (sdot - sdot_true), in rad/s.
        """
        s = self.layout.y_slices
        error = (prediction - target) * self.y_std
        gap = error[..., s["joints"]] / self.dt - error[..., s["joint_velocities"]]
        return gap.square().mean(dim=(-2, -1))

    def feet(self, prediction: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        """L_F (E,): the other sole's motion relative to the lower one from s_{i-1} (the
        data's: s_true - dt sdot_true) to the predicted s_i, near the ground."""
        s = self.layout.y_slices
        physical = prediction * self.y_std + self.y_mean
        truth = target * self.y_std + self.y_mean
        previous = truth[..., s["joints"]] - self.dt * truth[..., s["joint_velocities"]]
        motion = self.physics.feet_motion(
            previous, physical[..., s["joints"]], physical[..., s["base_rpy"]].detach(),
            self.dt, self.contact_height,
        )  # fmt: skip
        return motion.mean(-1)

    def increments(self, prediction: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        """(s_i - s_{i-1}) / dt of the predicted joints, physical units (train.pi_joint_velocities).

        The joints a rollout writes move by this, not by the predicted sdot_i. The data satisfy
        s_{i-1} = s_true - dt sdot_true, so it is (s - s_true) / dt + sdot_true.
        """
        s = self.layout.y_slices
        joints, rates = s["joints"], s["joint_velocities"]
        error = (prediction[..., joints] - target[..., joints]) * self.y_std[joints]
        true_rates = target[..., rates] * self.y_std[rates] + self.y_mean[rates]
        return error / self.dt + true_rates

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
        contacts: torch.Tensor | None = None,
        pi_prediction: torch.Tensor | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """(mse (E,), pi (E,)) averaged over the batch; pi is 0 when `with_pi` is False.

        `contacts` (E, B, 2): the data's feet in contact, needed with pi_support data_contacts.
        `pi_prediction`: the prediction L_B is taken on, when not `prediction` (train.pi_dropout
        false: the same inputs without dropout).
        """
        mse = (prediction - target).square().mean(dim=(-2, -1))
        physical = prediction if pi_prediction is None else pi_prediction  # what L_B judges
        if self.consistency_weight:
            mse = mse + self.consistency_weight * self.consistency(prediction, target)
        if self.feet_weight:
            mse = mse + self.feet_weight * self.feet(physical, target)
        if not with_pi:
            return mse, torch.zeros_like(mse)
        terms = self.pi_terms(physical)
        if self.pi_joint_velocities == "increments":
            terms["joint_velocities"] = self.increments(physical, target)
        if self.pi_support == "data_contacts":
            if contacts is None:
                raise ValueError("pi_support data_contacts needs the samples' contacts")
            terms["support"] = contacts
        if self.pi_configuration == "ground_truth":
            truth = self.pi_terms(target)
            for name in ("base_position", "base_rpy", "joints"):
                terms[name] = truth[name]
        for name in _HELD[self.pi_gradient]:
            terms[name] = terms[name].detach()
        return mse, self.physics(**terms).mean(-1)
