"""TorchKinematics against pinocchio (placements, LOCAL Jacobians) and finite differences."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
import torch

from pimann.core.robot import LEFT_SOLE, RIGHT_SOLE
from pimann.learn.kinematics_torch import TorchKinematics, rpy_to_matrix


@pytest.fixture(scope="module")
def kinematics(robot) -> TorchKinematics:
    return TorchKinematics(robot)


def random_states(robot, rng, n):
    joints = rng.uniform(robot.joint_lower, robot.joint_upper, size=(n, 26))
    rpy = rng.uniform([-np.pi, -1.5, -np.pi], [np.pi, 1.5, np.pi], size=(n, 3))
    return rng.normal(size=(n, 3)), rpy, joints


def test_rpy_matches_pinocchio(rng):
    rpy = rng.uniform(-np.pi, np.pi, size=(20, 3))
    expected = np.stack([pin.rpy.rpyToMatrix(a) for a in rpy])
    np.testing.assert_allclose(rpy_to_matrix(torch.tensor(rpy)).numpy(), expected, atol=1e-14)


def test_placements_and_jacobians_match_pinocchio(robot, kinematics, rng):
    position, rpy, joints = random_states(robot, rng, 16)
    rotation = np.stack([pin.rpy.rpyToMatrix(a) for a in rpy])
    out = kinematics(torch.tensor(position), torch.tensor(rotation), torch.tensor(joints))
    assert set(out) == {LEFT_SOLE, RIGHT_SOLE}
    for b in range(len(joints)):
        quaternion = pin.Quaternion(rotation[b]).coeffs()
        q = robot.configuration(position[b], quaternion, joints[b])
        for frame, result in out.items():
            placement = robot.frame_placement(q, frame)
            np.testing.assert_allclose(result.position[b], placement.translation, atol=1e-8)
            np.testing.assert_allclose(result.rotation[b], placement.rotation, atol=1e-8)
            jacobian = robot.frame_jacobian(q, frame, pin.LOCAL)
            np.testing.assert_allclose(result.jacobian[b], jacobian, atol=1e-8)


def test_leading_dims_broadcast(robot, kinematics, rng):
    position, rpy, joints = random_states(robot, rng, 6)
    args = [torch.tensor(position), rpy_to_matrix(torch.tensor(rpy)), torch.tensor(joints)]
    flat = kinematics(*args)[LEFT_SOLE].jacobian
    shaped = kinematics(*[a.reshape(2, 3, *a.shape[1:]) for a in args])[LEFT_SOLE].jacobian
    assert shaped.shape == (2, 3, 6, 32)
    np.testing.assert_allclose(shaped.reshape(6, 6, 32), flat, atol=1e-15)


def test_only_leg_joints_move_the_soles(kinematics):
    """The torso, neck and arms must have all-zero Jacobian columns for the soles."""
    leg = set(kinematics.index_flat.tolist())
    assert leg == set(range(12))


@pytest.mark.parametrize("graph_safe", [False, True])
def test_autograd_matches_finite_differences(robot, rng, graph_safe):
    """Both paths: cumsum and scatter_add, and CUDA's products with constant matrices."""
    kinematics = TorchKinematics(robot, graph_safe=graph_safe)
    position, rpy, joints = (torch.tensor(a) for a in random_states(robot, rng, 3))

    def scalar(joint_values: torch.Tensor) -> torch.Tensor:
        """One value per sample, so perturbing a joint in every sample gives per-sample FDs."""
        out = kinematics(position, rpy_to_matrix(rpy), joint_values)
        left, right = out[LEFT_SOLE], out[RIGHT_SOLE]
        return (
            left.position.sum(-1)
            + right.rotation[..., 0, 2]
            + left.jacobian[..., 1, 6 + 3]  # d(sole lateral velocity)/d(l_knee rate)
            + right.jacobian[..., 3, 6 + 7]
        )

    values = joints.clone().requires_grad_(True)
    (gradient,) = torch.autograd.grad(scalar(values).sum(), values)
    step = 1e-6
    numeric = torch.zeros_like(joints)
    for i in range(joints.shape[-1]):
        delta = torch.zeros_like(joints)
        delta[:, i] = step
        numeric[:, i] = (scalar(joints + delta) - scalar(joints - delta)) / (2 * step)
    assert gradient[:, :12].abs().max() > 1e-2  # the test would notice a zero gradient
    np.testing.assert_allclose(gradient, numeric, atol=1e-7)


@pytest.mark.parametrize("graph_safe", [False, True])
def test_other_frames_with_padding_and_gather(robot, rng, graph_safe):
    """Chains of different depths (padding) and out-of-order joints (the torso) still match."""
    frames = ("data_LeftLowerLeg", "data_T8", RIGHT_SOLE)
    kinematics = TorchKinematics(robot, frames=frames, graph_safe=graph_safe)
    assert kinematics._slice is None  # torso_roll precedes torso_pitch along the chain
    position, rpy, joints = random_states(robot, rng, 4)
    rotation = np.stack([pin.rpy.rpyToMatrix(a) for a in rpy])
    out = kinematics(torch.tensor(position), torch.tensor(rotation), torch.tensor(joints))
    for b in range(len(joints)):
        q = robot.configuration(position[b], pin.Quaternion(rotation[b]).coeffs(), joints[b])
        for frame in frames:
            placement = robot.frame_placement(q, frame)
            np.testing.assert_allclose(out[frame].position[b], placement.translation, atol=1e-8)
            np.testing.assert_allclose(out[frame].rotation[b], placement.rotation, atol=1e-8)
            jacobian = robot.frame_jacobian(q, frame, pin.LOCAL)
            np.testing.assert_allclose(out[frame].jacobian[b], jacobian, atol=1e-8)


def test_the_graph_safe_path_gives_the_cpu_path(robot, kinematics, rng):
    """CUDA's constant-matrix products (forced on the CPU) against cumsum and scatter_add:
    the same placements and Jacobians to rounding, the Jacobian's zero columns exactly zero."""
    safe = TorchKinematics(robot, graph_safe=True)
    position, rpy, joints = (torch.tensor(a) for a in random_states(robot, rng, 32))
    rotation = rpy_to_matrix(rpy)
    plain, products = kinematics(position, rotation, joints), safe(position, rotation, joints)
    for frame, reference in plain.items():
        for mine, theirs in zip(products[frame], reference, strict=True):
            torch.testing.assert_close(mine, theirs, rtol=0, atol=1e-14)
        assert torch.equal(products[frame].jacobian[..., 6 + 12 :] == 0, torch.ones(32, 6, 14) > 0)
    float_safe = TorchKinematics(robot, torch.float32, graph_safe=True)
    out = float_safe(position.float(), rotation.float(), joints.float())[LEFT_SOLE]
    torch.testing.assert_close(out.jacobian, plain[LEFT_SOLE].jacobian.float(), atol=1e-5, rtol=0)


def test_the_gather_of_unordered_chains_is_index_select(robot, rng):
    """The selection-matrix gather (capture-safe) against index_select, values and gradients."""
    kinematics = TorchKinematics(robot, frames=("data_T8", "data_LeftLowerLeg"))
    assert kinematics._slice is None
    joints = torch.tensor(rng.normal(size=(5, 26)), requires_grad=True)
    mine = kinematics.gather(joints)
    reference = joints.index_select(-1, kinematics.index_flat).unflatten(-1, mine.shape[-2:])
    assert torch.equal(mine, reference)
    upstream = torch.tensor(rng.normal(size=mine.shape))
    (grad_mine,) = torch.autograd.grad((mine * upstream).sum(), joints)
    (grad_ref,) = torch.autograd.grad((reference * upstream).sum(), joints)
    torch.testing.assert_close(grad_mine, grad_ref, rtol=0, atol=1e-15)
    assert grad_mine[:, 12:].abs().max() > 0  # torso joints carry gradient
