"""Sole velocities as the authors' evaluation takes them (SPEC 8.1): the joints move at the
given joint velocities and the base moves so that the foot whose sole corner is lowest stays
still, J_s,B v_B + J_s,s sdot = 0 for that foot s. Its twist is then zero, and the other sole's
is its motion relative to the support sole: what the joint velocities alone make the feet do.
The trajectory's own base motion (odometry, IK) does not enter (pimann.evaluate.metrics' velocity
level).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from pimann.core.contacts import FEET
from pimann.core.robot import Robot


def support_foot_velocities(
    robot: Robot, configurations: np.ndarray, joint_velocities: np.ndarray, heights: np.ndarray
) -> np.ndarray:
    """(T, 2, 6) sole twists [linear, angular], LOCAL_WORLD_ALIGNED, columns as `FEET`.

    configurations (T, nq); joint_velocities (T, 26), the study's joint order; heights (T, 2):
    each sole's lowest corner (pimann.core.contacts.FootKinematics.heights), the lower one is the
    support foot (the left on a tie). One pinocchio Jacobian pass per frame.
    """
    model = robot.model
    data = model.createData()  # private: the cached Robot's data may be in use elsewhere
    frame_ids = [robot.frame_id(name) for name in FEET]
    base = robot.velocity_order[:6]  # the free flyer's columns
    support = np.argmin(np.asarray(heights), axis=1)
    n = len(configurations)
    jacobians = np.empty((n, 2, 6, model.nv))
    for k, q in enumerate(configurations):
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        for f, frame_id in enumerate(frame_ids):
            jacobians[k, f] = pin.getFrameJacobian(model, data, frame_id, pin.LOCAL_WORLD_ALIGNED)
    joint_part = np.einsum("tfij,tj->tfi", jacobians[..., robot.v_index], joint_velocities)
    held = jacobians[np.arange(n), support][..., base]  # (T, 6, 6) the support sole's base block
    base_twist = -np.linalg.solve(held, joint_part[np.arange(n), support][..., None])[..., 0]
    return np.einsum("tfij,tj->tfi", jacobians[..., base], base_twist) + joint_part
