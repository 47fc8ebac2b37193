"""Leg odometry of generated rollouts, vectorised over a batch of rollouts (rows).

Generation places the base so that the support point (the lowest sole corner) stays where it
was (pimann.generate.rollout_batch's rule 4). That needs both sole frames in the base frame
at every step of every rollout: one pinocchio pass per rollout and step
would be a Python loop over rows, so the two leg chains are evaluated here in numpy, all rows
at once, on the geometry the torch kinematics (pimann.learn.kinematics_torch) reads from the
pinocchio model: one 3x3 product per joint depth, whatever the number of rows.
"""

from __future__ import annotations

import numpy as np
import torch

from pimann.core.contacts import FEET
from pimann.core.robot import SOLE_CORNERS, Robot
from pimann.learn.kinematics_torch import TorchKinematics


class SoleFrames:
    """Both sole frames (columns as `FEET`) in the base frame for joints (B, 26), in numpy.

    Each chain is a product of homogeneous transforms [P exp([a] q) | offset], then the frame's
    fixed placement. By Rodrigues, P exp([a] q) = P + sin q P[a] + (1 - cos q) P[a]^2, so each
    transform is T0 + [sin q, cos q] @ [T1, -T2] with T0 = [P + P[a]^2 | offset]: one sine
    (cos q = sin(q + pi/2)) and one product for every joint of every row. The products of the
    chain are taken pairwise: 6 joints and the end frame cost 3 batched 4x4 products.
    """

    def __init__(self, robot: Robot):
        chains = TorchKinematics(robot, torch.float64, "cpu", frames=FEET)
        index = chains.index.numpy()  # (C, L) study joint of each chain step
        n_chains, depth = index.shape
        size = 1 << int(np.ceil(np.log2(depth + 1)))  # joints + the end frame, padded
        carry = chains.carry.numpy()  # (C, L, 3, 5): next offset (column 1), end rotation
        offsets = np.concatenate([chains.first.numpy()[:, 1], carry[:, :, :, 1]], axis=1)
        constant = np.tile(np.eye(4), (n_chains, size, 1, 1))  # padding: identity
        constant[:, : depth + 1, :3, 3] = offsets  # joint l's origin in its parent's frame
        constant[:, depth, :3, :3] = carry[:, -1, :, 2:]  # the frame's rotation after the last
        constant[:, :depth, :3, :3] = chains.placement_rot.numpy() + chains.rot_k2.numpy()
        varying = np.zeros((n_chains, size, 2, 4, 4))  # rows: sin q, cos q
        varying[:, :depth, 0, :3, :3] = chains.rot_k.numpy()
        varying[:, :depth, 1, :3, :3] = -chains.rot_k2.numpy()
        self.constant = constant.reshape(n_chains, size, 1, 16)
        self.varying = varying.reshape(n_chains, size, 2, 16)
        self.index = np.zeros((n_chains, size), dtype=int)  # padding reads joint 0, times 0
        self.index[:, :depth] = index
        self.shift = np.array([0.0, np.pi / 2])

    def transforms(self, joints: np.ndarray) -> np.ndarray:
        """(B, C, 4, 4) homogeneous placements of the frames in the base frame."""
        sin_cos = np.sin(joints[:, self.index, None] + self.shift)[..., None, :]  # (B,C,S,1,2)
        transforms = (sin_cos @ self.varying + self.constant).reshape(*sin_cos.shape[:3], 4, 4)
        while transforms.shape[2] > 1:  # pairwise: (T0 T1)(T2 T3)...
            transforms = transforms[:, :, 0::2] @ transforms[:, :, 1::2]
        return transforms[:, :, 0]

    def __call__(self, joints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(positions (B, C, 3), rotations (B, C, 3, 3)) of the frames in the base frame."""
        transforms = self.transforms(joints)
        return transforms[:, :, :3, 3], transforms[:, :, :3, :3]


class Odometry:
    """Per row: the support corner (foot, corner), its world anchor and the feet's corners."""

    def __init__(self, robot: Robot, rows: int):
        self.frames = SoleFrames(robot)
        self.corners = np.vstack([SOLE_CORNERS.T, np.ones(len(SOLE_CORNERS))])  # (4, C) homog.
        self.rows = np.arange(rows)
        self.support_foot = np.zeros(rows, dtype=int)  # the support corner: its foot,
        self.support_corner = np.zeros(rows, dtype=int)  # and which of its corners
        self.anchor = np.zeros((rows, 3))
        self.world_corners = np.zeros((rows, len(FEET), 3, len(SOLE_CORNERS)))

    def rotated_corners(self, rotation: np.ndarray, joints: np.ndarray) -> np.ndarray:
        """(B, 2, 3, C) sole corners relative to the base in world axes (base at the origin)."""
        return rotation[:, None] @ (self.frames.transforms(joints)[:, :, :3] @ self.corners)

    def place(
        self, rotation: np.ndarray, joints: np.ndarray, first: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Base positions (B, 3) for orientations (B, 3, 3) and joints; `first` sets the start.

        Returns (base position, lowest corner height of each foot (B, 2), support foot (B,)).
        """
        rotated = self.rotated_corners(rotation, joints)
        heights = rotated[:, :, 2]  # (B, 2, C)
        foot = _support_foot(heights)
        corner = heights[self.rows, foot].argmin(axis=1)
        support_point = rotated[self.rows, foot, :, corner]  # (B, 3)
        if first is not None:
            position = first
            self.anchor = first + support_point
        else:
            moved = (foot != self.support_foot) | (corner != self.support_corner)
            if moved.any():  # pin the new support point on the ground
                anchor = self.world_corners[self.rows, foot, :, corner]
                anchor[:, 2] = 0.0
                self.anchor = np.where(moved[:, None], anchor, self.anchor)
            position = self.anchor - support_point
        self.support_foot, self.support_corner = foot, corner
        self.world_corners = rotated + position[:, None, :, None]
        return position, self.world_corners[:, :, 2].min(axis=2), foot


def _support_foot(heights: np.ndarray) -> np.ndarray:
    """(B,) the foot with the lowest corner, from corner heights (B, 2, C)."""
    return heights.min(axis=2).argmin(axis=1)
