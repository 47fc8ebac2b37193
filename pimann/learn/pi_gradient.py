"""What `train.pi_gradient` holds out of L_B's gradient: the predictions L_B does not move.

L_B's residual v_B + (J^B)^-1 J^s sdot is taken at the predicted configuration; the paper
(`both`) lets its gradient move every prediction it reads. Torch-free, so that the claims can
say why a model's feet do not tip without importing the training loss.
"""

from __future__ import annotations

# per `train.pi_gradient`: the predictions L_B's gradient does not move
HELD_PREDICTIONS: dict[str, tuple[str, ...]] = {
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


def holds_configuration(pi_gradient: str) -> bool:
    """Whether L_B cannot move the predicted configuration (joints): the way by which a large
    w tips the support foot onto its heel is closed."""
    return "joints" in HELD_PREDICTIONS[pi_gradient]
