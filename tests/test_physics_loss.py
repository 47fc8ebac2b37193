"""PhysicsInformedLoss against base twists built from pinocchio's Jacobians."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
import torch

from diagnostics.teacher_forcing import relative_sole_motion
from pimann.core.robot import LEFT_SOLE, RIGHT_SOLE
from pimann.learn.physics_loss import PhysicsInformedLoss


@pytest.fixture(scope="module")
def loss(robot) -> PhysicsInformedLoss:
    return PhysicsInformedLoss(robot, dtype=torch.float64)


def still_foot_states(robot, rng, n):
    """Random states whose base twist keeps pinocchio's lower sole still (an independent ref)."""
    rows = []
    for _ in range(n):
        joints = rng.uniform(robot.joint_lower, robot.joint_upper)
        rpy = rng.uniform([-0.3, -0.3, -np.pi], [0.3, 0.3, np.pi])
        position = rng.normal(size=3)
        q = robot.configuration(position, pin.Quaternion(pin.rpy.rpyToMatrix(rpy)).coeffs(), joints)
        heights = {f: robot.frame_placement(q, f).translation[2] for f in (LEFT_SOLE, RIGHT_SOLE)}
        support = min(heights, key=heights.get)
        jacobian = robot.frame_jacobian(q, support, pin.LOCAL)
        joint_velocities = rng.normal(size=26)
        twist = -np.linalg.solve(jacobian[:, :6], jacobian[:, 6:] @ joint_velocities)
        rows.append((position, rpy, joints, twist, joint_velocities, support, jacobian))
    return rows


def evaluate(loss, rows, twist_offset=None):
    position, rpy, joints, twist, joint_velocities = (
        torch.tensor(np.stack([r[i] for r in rows])) for i in range(5)
    )
    if twist_offset is not None:
        twist = twist + torch.as_tensor(twist_offset)
    return loss(position, rpy, joints, twist[:, :3], twist[:, 3:], joint_velocities)


def test_still_support_foot_gives_zero(robot, loss, rng):
    rows = still_foot_states(robot, rng, 12)
    assert {r[5] for r in rows} == {LEFT_SOLE, RIGHT_SOLE}  # both feet serve as support
    values = evaluate(loss, rows)
    assert values.shape == (12,)
    assert values.max() < 1e-10


def test_alpha_picks_the_lower_foot(robot, loss, rng):
    rows = still_foot_states(robot, rng, 12)
    position, rpy, joints = (torch.tensor(np.stack([r[i] for r in rows])) for i in range(3))
    chain = loss.kinematics.chains(joints)
    left = loss.left_is_support(rpy, chain.frame_positions)
    assert left.tolist() == [r[5] == LEFT_SOLE for r in rows]
    # the other foot's kinematics generally disagree: swapping the support gives a large loss
    wrong = [(*r[:3], -r[3], *r[4:]) for r in rows]
    assert (evaluate(loss, wrong) > 1e-4).all()


def test_data_contacts_choose_the_feet(robot, loss, rng):
    """Given contact flags: the flagged foot's residual, both averaged, none gives 0."""
    rows = still_foot_states(robot, rng, 8)
    position, rpy, joints, twist, joint_velocities = (
        torch.tensor(np.stack([r[i] for r in rows])) for i in range(5)
    )
    left = torch.tensor([r[5] == LEFT_SOLE for r in rows])
    args = (position, rpy, joints, twist[:, :3], twist[:, 3:], joint_velocities)
    lower = loss(*args)
    as_data = loss(*args, support=torch.stack((left, ~left), -1))
    torch.testing.assert_close(as_data, lower)  # the lower sole flagged: the paper's value
    swapped = loss(*args, support=torch.stack((~left, left), -1))
    assert (swapped > 1e-4).all()  # the moving foot flagged instead
    both = loss(*args, support=torch.ones(8, 2, dtype=torch.bool))
    torch.testing.assert_close(both, (lower + swapped) / 2)
    none = loss(*args, support=torch.zeros(8, 2, dtype=torch.bool))
    assert (none == 0).all()


def test_loss_grows_with_foot_sliding(robot, loss, rng):
    """Sliding the support sole at speed u makes the base twist off by (J^B)^-1 u."""
    rows = still_foot_states(robot, rng, 4)
    direction = rng.normal(size=6)
    previous = evaluate(loss, rows)
    for speed in (0.01, 0.1, 0.3, 1.0):
        offsets = np.stack([np.linalg.solve(r[6][:, :6], speed * direction) for r in rows])
        values = evaluate(loss, rows, offsets)
        assert (values > previous).all()
        np.testing.assert_allclose(values, (offsets**2).mean(-1), rtol=1e-8)
        previous = values


def test_gradients_match_finite_differences(robot, loss, rng):
    rows = still_foot_states(robot, rng, 3)
    position, rpy, joints, twist, joint_velocities = (
        torch.tensor(np.stack([r[i] for r in rows])) for i in range(5)
    )
    twist = twist + 0.1  # off the minimum, so the gradient is not zero

    def per_sample(joint_values, twist_values):
        return loss(
            position, rpy, joint_values, twist_values[:, :3], twist_values[:, 3:], joint_velocities
        )

    j, t = joints.clone().requires_grad_(True), twist.clone().requires_grad_(True)
    grad_j, grad_t = torch.autograd.grad(per_sample(j, t).sum(), (j, t))
    np.testing.assert_allclose(grad_t, 2 * 0.1 / 6 * torch.ones_like(twist), atol=1e-10)
    step = 1e-6
    numeric = torch.zeros_like(joints)
    for i in range(26):
        delta = torch.zeros_like(joints)
        delta[:, i] = step
        numeric[:, i] = (per_sample(joints + delta, twist) - per_sample(joints - delta, twist)) / (
            2 * step
        )
    assert grad_j.abs().max() > 1e-4
    np.testing.assert_allclose(grad_j, numeric, atol=1e-8)


def test_leading_dims_and_float32(robot, rng):
    rows = still_foot_states(robot, rng, 6)
    loss32 = PhysicsInformedLoss(robot, dtype=torch.float32)
    args = [torch.tensor(np.stack([r[i] for r in rows]), dtype=torch.float32) for i in range(5)]
    position, rpy, joints, twist, joint_velocities = (a.reshape(2, 3, -1) for a in args)
    values = loss32(position, rpy, joints, twist[..., :3], twist[..., 3:], joint_velocities)
    assert values.shape == (2, 3) and values.dtype == torch.float32
    assert values.max() < 1e-9


def test_feet_motion_is_the_other_soles_motion_seen_from_the_lower_one(robot, loss, rng):
    """L_F (a diagnostic) against pinocchio: the other sole's pose in the lower sole's frame at two
    configurations, its change over dt (linear; small-angle rotation), weighted by height."""
    dt, height = 0.02, 0.3
    before = rng.uniform(robot.joint_lower, robot.joint_upper, size=(10, 26))
    after = before + rng.normal(scale=0.005, size=before.shape)  # about one frame's step
    rpy = rng.uniform([-0.2, -0.2, -np.pi], [0.2, 0.2, np.pi], size=(10, 3))
    value = relative_sole_motion(
        loss, *(torch.tensor(a) for a in (before, after, rpy)), dt=dt, height=height
    ).numpy()
    expected, weights = [], []
    for q0, q1, angles in zip(before, after, rpy, strict=True):
        quaternion = pin.Quaternion(pin.rpy.rpyToMatrix(angles)).coeffs()
        poses = [
            {
                f: robot.frame_placement(robot.configuration(np.zeros(3), quaternion, q), f)
                for f in (LEFT_SOLE, RIGHT_SOLE)
            }
            for q in (q0, q1)
        ]
        z = {f: poses[1][f].translation[2] for f in (LEFT_SOLE, RIGHT_SOLE)}
        lower, other = sorted(z, key=z.get)
        relative = [p[lower].inverse() * p[other] for p in poses]
        linear = (relative[1].translation - relative[0].translation) / dt
        angular = pin.log3(relative[0].rotation.T @ relative[1].rotation) / dt
        weight = 1 / (1 + np.exp(-(height - (z[other] - z[lower])) * 4 / height))
        weights.append(weight)
        expected.append(weight * np.mean(np.concatenate((linear, angular)) ** 2))
    np.testing.assert_allclose(value, expected, rtol=3e-4)  # small-angle vee against log3
    assert min(weights) < 0.2 and max(weights) > 0.5  # heights that count and do not
    assert np.min(expected) > 0  # the feet move relative to each other
    still = relative_sole_motion(
        loss, *(torch.tensor(a) for a in (after, after, rpy)), dt=dt, height=height
    )
    assert still.abs().max() < 1e-20  # no motion, no loss
