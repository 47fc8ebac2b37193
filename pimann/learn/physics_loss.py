"""Physics-informed loss L_B (paper Eq. pi_loss): the support foot must not slide.

A still support foot, J_SF^B v_B + J_SF^s sdot = 0 (Eq. kin_feas), fixes the base twist to
v_B = -(J_SF^B)^-1 J_SF^s sdot (Eq. kf_base). With body-fixed (LOCAL) Jacobians the product
(J_SF^B)^-1 J_SF^s sdot needs no inverse: J^B = diag(R^T, R^T) [[I, -[p]x], [0, I]] for the
sole pose (R, p) in the base frame, so it equals sum_j sdot_j [p_j x w_j; w_j], the leg's
joint twists written in the base frame at the base origin (p_j a point on joint j's axis, w_j
its unit axis). It depends on the joints only: the base pose cancels, and enters the loss
only through alpha (which sole is lower), which is not differentiated.
"""

from __future__ import annotations

import torch
from torch import nn

from pimann.core.robot import LEFT_SOLE, RIGHT_SOLE, Robot
from pimann.learn.kinematics_torch import TorchKinematics


class PhysicsInformedLoss(nn.Module):
    """Per-sample L_B in physical units (m, rad, m/s, rad/s), inputs with any leading dims.

    Base velocities are in the base (body) frame, joints in the study's order. Returns the mean
    over the 6 twist components of the squared residual
    r = [v; omega] + [alpha (J_LF^B)^-1 J_LF^s + (1 - alpha) (J_RF^B)^-1 J_RF^s] sdot,
    alpha = 1 where the left sole is lower than the right one, as in the authors' code.
    With `support` (..., 2) flags of the feet in contact (the data's, not predicted), the
    residual is taken for each foot in contact and averaged over them: double support keeps
    both feet still, a frame with no foot down adds nothing (the data report's L_B on the
    data's contacts; training takes the lower sole).
    """

    def __init__(
        self,
        robot: Robot,
        dtype: torch.dtype | None = None,
        device: torch.device | str | None = None,
    ):
        super().__init__()
        self.kinematics = TorchKinematics(
            robot,
            dtype=dtype or torch.get_default_dtype(),
            device=device,
            frames=(LEFT_SOLE, RIGHT_SOLE),
        )

    def foot_twists(self, joints: torch.Tensor, joint_velocities: torch.Tensor):
        """(J_F^B)^-1 J_F^s sdot for the left and right sole, (..., 2, 6), and the chains."""
        kin = self.kinematics
        chain = kin.chains(joints)
        sdot = kin.gather(joint_velocities)
        moments = torch.linalg.cross(chain.joint_positions, chain.joint_axes)
        twists = torch.cat((moments, chain.joint_axes), -1)  # (..., 2, L, 6)
        return (sdot.unsqueeze(-2) @ twists).squeeze(-2), chain

    @staticmethod
    def sole_heights(base_rpy: torch.Tensor, sole_positions: torch.Tensor) -> torch.Tensor:
        """(..., 2) the soles' world heights less the base's; no gradient.

        `sole_positions` (..., 2, 3) in the base frame; world z differs by the base rotation's
        last row, [-sin(pitch), cos(pitch) sin(roll), cos(pitch) cos(roll)].
        """
        with torch.no_grad():
            roll, pitch = base_rpy[..., 0], base_rpy[..., 1]
            row = torch.stack(
                (
                    -torch.sin(pitch),
                    torch.cos(pitch) * torch.sin(roll),
                    torch.cos(pitch) * torch.cos(roll),
                ),
                -1,
            )
            return (row.unsqueeze(-2) * sole_positions).sum(-1)

    @staticmethod
    def lower_is_left(heights: torch.Tensor) -> torch.Tensor:
        """(...,) True where the left sole's height (`sole_heights`) is below the right's."""
        return heights[..., 0] < heights[..., 1]

    @classmethod
    def left_is_support(cls, base_rpy: torch.Tensor, sole_positions: torch.Tensor) -> torch.Tensor:
        """alpha: True where the left sole is lower (world z) than the right; no gradient."""
        return cls.lower_is_left(cls.sole_heights(base_rpy, sole_positions))

    def forward(
        self,
        base_position: torch.Tensor,
        base_rpy: torch.Tensor,
        joints: torch.Tensor,
        base_linear_velocity: torch.Tensor,
        base_angular_velocity: torch.Tensor,
        joint_velocities: torch.Tensor,
        support: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """(...,) loss; `base_position` is accepted for the interface but cancels out."""
        del base_position  # the body-fixed Jacobians and the sole height gap ignore it
        feet, chain = self.foot_twists(joints, joint_velocities)
        twist = torch.cat((base_linear_velocity, base_angular_velocity), -1)
        if support is not None:
            per_foot = (twist.unsqueeze(-2) + feet).square().mean(-1)  # (..., 2)
            weight = support.to(per_foot.dtype)
            return (per_foot * weight).sum(-1) / weight.sum(-1).clamp(min=1.0)
        left = self.left_is_support(base_rpy, chain.frame_positions)
        foot = torch.where(left.unsqueeze(-1), feet[..., 0, :], feet[..., 1, :])
        return (twist + foot).square().mean(-1)
