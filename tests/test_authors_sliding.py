"""The authors' sliding metric (`support_rmse_paper_*`), step by step as their rollout's
advance() computes it: hand-made cases whose numbers follow by hand, and a frame-by-frame
recomputation with other pinocchio calls on a real retargeted walk."""

from __future__ import annotations

import dataclasses

import numpy as np
import pinocchio as pin
import pytest
from builders import CONTACT_PARAMS, EVALUATE_PARAMS
from test_metrics import FRAMES, SQRT3, stance_trajectory

from pimann.core.contacts import (
    FEET,
    contacts_from_heights,
    foot_kinematics,
    trajectory_configurations,
)
from pimann.core.robot import JOINT_NAMES, corner_offsets
from pimann.evaluate.metrics import sliding_frames, trajectory_metrics
from pimann.evaluate.sliding import AUTHORS_SOLE_CORNERS, authors_sole_velocities, sole_jacobians


def test_a_sole_on_its_heel_counts_two_steps_by_the_authors_rule(robot):
    """The left sole tipped 0.4 rad onto its heel (origin 4.6 cm up), the whole robot sliding
    at 0.05 m/s, the file's joint velocities zero. The authors' trigger starts on and needs
    three samples above 2 cm to switch off: it counts steps 1 and 2 only; the lowest-corner
    rule counts every frame. Their velocities come from the joint velocities alone (zero
    here), so their metric is exactly 0 where the position level reads the slide: 0.05 / sqrt 3
    a frame."""
    trajectory = stance_trajectory(robot, slide=0.05, tip=0.4)
    trajectory = dataclasses.replace(
        trajectory, joint_velocities=np.zeros_like(trajectory.joint_positions)
    )
    frames = sliding_frames(trajectory, robot, EVALUATE_PARAMS, CONTACT_PARAMS)
    metrics = trajectory_metrics(trajectory, robot, EVALUATE_PARAMS, CONTACT_PARAMS)
    assert frames["contacts"][:, 0].all()  # lowest corner on the floor: down throughout
    assert metrics["support_rmse_paper_linear_left"] == 0.0
    assert metrics["support_rmse_paper_angular_total"] == 0.0
    assert metrics["support_rmse_linear_position_left"] == pytest.approx(
        FRAMES * 0.05 / SQRT3, abs=0.02
    )
    # the authors' flags: the right foot swings high, the left origin sits at 4.6 cm
    configurations = trajectory_configurations(robot, trajectory)
    heights = np.array(
        [[robot.frame_placement(q, f).translation[2] for f in FEET] for q in configurations]
    )
    assert heights[:, 0] == pytest.approx(np.full(FRAMES, 0.1167 * np.sin(0.4)), abs=2e-3)
    flags = np.zeros((FRAMES, 2), dtype=bool)
    flags[1:] = contacts_from_heights(heights[1:], 1 / 50, CONTACT_PARAMS, initial=True)
    assert flags[:4, 0].tolist() == [False, True, True, False]  # frame 0 has no step
    assert not flags[3:, 0].any()


def _support_jacobians(robot, q):
    """{foot: (6, nv) LOCAL_WORLD_ALIGNED Jacobian} at q, and the support foot by the authors'
    corners (a second path: per-frame pinocchio calls, corners from the placements)."""
    model = robot.model
    data = model.createData()
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    jacobians, lowest = {}, {}
    for foot in FEET:
        frame = robot.frame_id(foot)
        jacobians[foot] = pin.getFrameJacobian(model, data, frame, pin.LOCAL_WORLD_ALIGNED)
        placement = data.oMf[frame]
        lowest[foot] = min(placement.act(c)[2] for c in AUTHORS_SOLE_CORNERS)
    support = FEET[1] if lowest[FEET[1]] < lowest[FEET[0]] else FEET[0]
    return jacobians, support


def test_the_lag_residual_is_the_support_jacobians_change(robot):
    """Joints held still but a joint velocity in the file, the base turning 0.02 rad about z a
    step: from q_{i-1} the base twist t keeps the support sole still, A t + B sdot = 0 (A, B the
    support Jacobian's base and joint blocks in the mixed representation). The turn rotates both
    blocks with Q = diag(Rz, Rz): at q_i the residual is Q A (Q^T - I) t, computed here from the
    Jacobian at q_{i-1} alone. Without the turn (q_i = q_{i-1}) it vanishes."""
    rng = np.random.default_rng(3)
    base = stance_trajectory(robot)
    n = 6
    sdot = np.zeros((n, len(JOINT_NAMES)))
    legs = [JOINT_NAMES.index(name) for name in ("r_hip_pitch", "r_knee", "l_knee", "l_hip_roll")]
    sdot[:, legs] = rng.normal(0.0, 0.5, (n, len(legs)))
    for turn in (0.0, 0.02):
        yaw = pin.utils.rotate("z", turn)
        quaternions, positions = [], []
        for k in range(n):
            rotation = (
                np.linalg.matrix_power(yaw, k)
                @ pin.Quaternion(base.base_quaternion_xyzw[0]).matrix()
            )
            quaternions.append(pin.Quaternion(rotation).coeffs())
            positions.append(np.linalg.matrix_power(yaw, k) @ base.base_position[0])
        trajectory = dataclasses.replace(
            base,
            time=base.time[:n],
            base_position=np.array(positions),
            base_quaternion_xyzw=np.array(quaternions),
            joint_positions=np.tile(base.joint_positions[0], (n, 1)),
            joint_velocities=sdot,
        )
        q = trajectory_configurations(robot, trajectory)
        feet = foot_kinematics(robot, q)
        velocities = authors_sole_velocities(robot, q, sole_jacobians(robot, q), sdot, feet)
        assert np.isnan(velocities[0]).all()
        for i in range(1, n):
            jacobians, support = _support_jacobians(robot, q[i - 1])
            j = jacobians[support]
            rotation = pin.Quaternion(q[i - 1][3:7]).matrix()
            to_body = np.kron(np.eye(2), rotation.T)
            a = j[:, :6] @ to_body  # the mixed base block
            b = j[:, robot.v_index]
            t = -np.linalg.solve(a, b @ sdot[i])
            big_q = np.kron(np.eye(2), yaw)
            expected = big_q @ a @ (big_q.T - np.eye(6)) @ t
            got = velocities[i, FEET.index(support)]
            assert got == pytest.approx(expected, abs=1e-10)
            if turn == 0.0:
                assert np.abs(got).max() < 1e-12
            else:
                assert np.abs(got[:3]).max() > 1e-4  # a residual the order of operations makes


def _reference_paper_metric(robot, trajectory, sdot):
    """The authors' metric frame by frame with other pinocchio calls: the WORLD Jacobian at
    q_{i-1} for the support pick and the base twist (converted to the mixed one with the base
    placement), forwardKinematics at q_i with that twist and sdot_i, getFrameVelocity(WORLD)."""
    model = robot.model
    data = model.createData()
    q = trajectory_configurations(robot, trajectory)
    n = len(q)
    totals = np.zeros((2, 2))  # foot x (linear, angular)
    heights = np.zeros((n, 2))
    velocities = np.zeros((n, 2, 6))
    for i in range(1, n):
        pin.computeJointJacobians(model, data, q[i - 1])
        pin.updateFramePlacements(model, data)
        lowest = []
        for foot in FEET:
            frame = robot.frame_id(foot)
            placement = data.oMf[frame]
            lowest.append(min(placement.act(c)[2] for c in AUTHORS_SOLE_CORNERS))
        support = robot.frame_id(FEET[1] if lowest[1] < lowest[0] else FEET[0])
        world_jacobian = pin.getFrameJacobian(model, data, support, pin.WORLD)
        base_previous = pin.SE3(pin.Quaternion(q[i - 1][3:7]).matrix(), q[i - 1][:3])
        # the spatial twist that holds the support frame still, then the mixed one (p_dot, omega)
        body = -np.linalg.solve(world_jacobian[:, :6], world_jacobian[:, robot.v_index] @ sdot[i])
        spatial = base_previous.act(pin.Motion(body))
        omega = spatial.angular
        p_dot = spatial.linear + np.cross(omega, base_previous.translation)
        base_now = pin.SE3(pin.Quaternion(q[i][3:7]).matrix(), q[i][:3])
        v = np.zeros(model.nv)
        v[:3] = base_now.rotation.T @ p_dot
        v[3:6] = base_now.rotation.T @ omega
        v[robot.v_index] = sdot[i]
        pin.forwardKinematics(model, data, q[i], v)
        for f, foot in enumerate(FEET):
            frame = robot.frame_id(foot)
            heights[i, f] = pin.updateFramePlacement(model, data, frame).translation[2]
            velocities[i, f] = pin.getFrameVelocity(model, data, frame, pin.WORLD).vector
    flags = np.zeros((n, 2), dtype=bool)
    flags[1:] = contacts_from_heights(heights[1:], 1 / trajectory.rate_hz, CONTACT_PARAMS, True)
    for f in range(2):
        for part, rows in ((0, slice(0, 3)), (1, slice(3, 6))):
            rms = np.linalg.norm(velocities[:, f, rows], axis=-1) / SQRT3
            totals[f, part] = rms[flags[:, f]].sum()
    return totals.mean(axis=0)


def test_frame_by_frame_recomputation_on_a_real_walk(robot, real_walks):
    """A real retargeted Bandai Namco walk (support switches, touchdowns, lift-offs), 3 s of it,
    with joint velocities that differ from the joints' steps (as a network's do)."""
    walk = real_walks["walk"]
    n = 151
    rng = np.random.default_rng(0)
    steps = np.diff(walk.joint_positions[:n], axis=0) * walk.rate_hz
    sdot = np.vstack([np.zeros((1, steps.shape[1])), steps]) + rng.normal(0, 0.05, (n, 26))
    trajectory = dataclasses.replace(
        walk,
        time=walk.time[:n],
        base_position=walk.base_position[:n],
        base_quaternion_xyzw=walk.base_quaternion_xyzw[:n],
        joint_positions=walk.joint_positions[:n],
        joint_velocities=sdot,
        contacts=None,
    )
    metrics = trajectory_metrics(trajectory, robot, EVALUATE_PARAMS, CONTACT_PARAMS)
    linear, angular = _reference_paper_metric(robot, trajectory, sdot)
    assert linear > 1.0 and angular > 0.3  # the walk slides under this metric: not vacuous
    assert metrics["support_rmse_paper_linear_total"] == pytest.approx(linear, rel=1e-9)
    assert metrics["support_rmse_paper_angular_total"] == pytest.approx(angular, rel=1e-9)
    # the sum runs over the steps, frame 0 excluded: 150 here, 500 in a 501-frame rollout
    frames = sliding_frames(trajectory, robot, EVALUATE_PARAMS, CONTACT_PARAMS)
    assert (frames["paper_linear"][0] == 0).all()


def test_support_pick_uses_the_authors_corners(robot):
    """The authors' corners (+-0.08, +-0.03): a sole pitched 0.4 rad onto its heel has its
    lowest one 0.08 sin 0.4 below its origin (the retargeting's larger sole: 0.1167 sin 0.4)."""
    rotation = pin.utils.rotate("y", -0.4)
    lowest = corner_offsets(rotation[None], AUTHORS_SOLE_CORNERS)[0][:, 2].min()
    assert lowest == pytest.approx(-0.08 * np.sin(0.4), abs=1e-12)
    jacobians = sole_jacobians(robot, robot.standing_configuration()[None])
    assert jacobians.shape == (1, 2, 6, robot.model.nv)
