"""Batched, differentiable forward kinematics of ergoCub's sole frames in torch.

The physics-informed loss needs sole placements and Jacobians on every training sample, with
gradients, so pinocchio (one configuration at a time, no autograd) cannot serve. The geometry
(joint placements, axes, parents, frame placements) is read from the pinocchio model, never
typed by hand. Only the chains from the base to the requested frames are computed; the chains
are stacked on one tensor dimension so that one Python step per joint depth serves all of them.

Shapes: any leading batch dims `...`; joints are in the study's order (`robot.JOINT_NAMES`).

On CUDA (`graph_safe`) the cumulative sum along the chains and the scatter of the Jacobian's
columns are products with constant 0/1 matrices instead: torch has no deterministic CUDA
kernel for a float cumsum, and the deterministic scatter checks its indices with a host sync,
which a CUDA graph cannot capture. The products give the same values (the scatter's exactly,
the sum's to rounding); the CPU keeps cumsum and scatter_add.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import pinocchio as pin
import torch
from torch import nn

from pimann.core.errors import PimannError
from pimann.core.robot import JOINT_NAMES, LEFT_SOLE, N_JOINTS, RIGHT_SOLE, Robot


class FrameKinematics(NamedTuple):
    """One frame's world placement and its body-fixed (pinocchio LOCAL) Jacobian."""

    position: torch.Tensor  # (..., 3) world
    rotation: torch.Tensor  # (..., 3, 3) world <- frame
    jacobian: torch.Tensor  # (..., 6, 6 + 26): [base linear, base angular (body), joints]


class ChainKinematics(NamedTuple):
    """Joint axes and frames of every chain, relative to the base frame (C chains, L depth)."""

    joint_positions: torch.Tensor  # (..., C, L, 3) a point on each joint axis, base frame
    joint_axes: torch.Tensor  # (..., C, L, 3) unit axis in the base frame (0 for padding)
    frame_positions: torch.Tensor  # (..., C, 3) the chain's end frame in the base frame
    frame_rotations: torch.Tensor  # (..., C, 3, 3) base <- end frame


def rpy_to_matrix(rpy: torch.Tensor) -> torch.Tensor:
    """R = Rz(yaw) Ry(pitch) Rx(roll) from (..., 3) [roll, pitch, yaw], as pin.rpy.rpyToMatrix."""
    sr, sp, sy = torch.sin(rpy).unbind(-1)
    cr, cp, cy = torch.cos(rpy).unbind(-1)
    rows = (
        (cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr),
        (sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr),
        (-sp, cp * sr, cp * cr),
    )
    return torch.stack([torch.stack(row, -1) for row in rows], -2)


def _revolute_axis(robot: Robot, joint_id: int) -> np.ndarray:
    """The joint's axis in its own frame, from its motion subspace (any 1-DoF revolute)."""
    joint = robot.model.joints[joint_id]
    name = robot.model.names[joint_id]
    if joint.nq != 1 or joint.nv != 1:
        raise PimannError(robot.urdf_path, f"joint {name!r} ({joint.shortname()}) is not revolute")
    data = joint.createData()
    joint.calc(data, np.zeros(robot.model.nq))
    motion = np.asarray(data.S).ravel()
    if np.linalg.norm(motion[:3]) > 1e-12:
        raise PimannError(robot.urdf_path, f"joint {name!r} ({joint.shortname()}) translates")
    return motion[3:] / np.linalg.norm(motion[3:])


class TorchKinematics(nn.Module):
    """Sole (or other) frames of the free-floating robot, vectorised over any batch shape.

    Each step of a chain applies the joint placement then the joint rotation,
    R_local(q) = P (I + sin q K + (1 - cos q) K^2) (Rodrigues), with P K and P K^2 precomputed,
    so one step costs one 3x3 product for all chains at once. Chains shorter than the longest
    are padded at their end with identity joints (no rotation, no offset, zero axis).

    `graph_safe`: take the constant-matrix products (module docstring) in place of cumsum and
    scatter_add; None: on CUDA tensors only. Chains whose joints are not contiguous in the
    study's order are gathered by a product with a constant selection matrix (index_select's
    deterministic backward syncs with the host).
    """

    def __init__(
        self,
        robot: Robot,
        dtype: torch.dtype = torch.float64,
        device: torch.device | str | None = None,
        frames: tuple[str, ...] = (LEFT_SOLE, RIGHT_SOLE),
        graph_safe: bool | None = None,
    ):
        super().__init__()
        self.graph_safe = graph_safe
        model = robot.model
        self.frames = tuple(frames)
        study_index = {name: i for i, name in enumerate(JOINT_NAMES)}
        root = model.getJointId("root_joint") if model.existJointName("root_joint") else 1
        chains, end_placements = [], []
        for frame in self.frames:
            frame_id = robot.frame_id(frame)
            joint_id = model.frames[frame_id].parentJoint
            chain = []
            while joint_id != root:
                if joint_id == 0:
                    raise PimannError(robot.urdf_path, f"frame {frame!r} is not below the base")
                chain.append(joint_id)
                joint_id = model.parents[joint_id]
            chains.append(chain[::-1])
            end_placements.append(model.frames[frame_id].placement)
        depth = max(len(c) for c in chains)
        n = len(chains)
        placement_rot = np.tile(np.eye(3), (n, depth, 1, 1))  # (C, L, 3, 3)
        rot_k = np.zeros((n, depth, 3, 3))
        rot_k2 = np.zeros((n, depth, 3, 3))
        axes = np.zeros((n, depth + 1, 3))  # P a: each axis in its parent joint's frame
        offsets = np.zeros((n, depth + 1, 3))  # joint origins in the parent's frame, then the end
        index = np.zeros((n, depth), dtype=np.int64)
        for c, chain in enumerate(chains):
            for k, joint_id in enumerate(chain):
                name = model.names[joint_id]
                if name not in study_index:
                    raise PimannError(robot.urdf_path, f"joint {name!r} is not a study joint")
                axis = _revolute_axis(robot, joint_id)
                placement = model.jointPlacements[joint_id]
                skew = pin.skew(axis)
                placement_rot[c, k] = placement.rotation
                rot_k[c, k] = placement.rotation @ skew
                rot_k2[c, k] = placement.rotation @ skew @ skew
                offsets[c, k] = placement.translation
                axes[c, k] = placement.rotation @ axis
                index[c, k] = study_index[name]
            offsets[c, depth] = end_placements[c].translation
        # what the frame after joint j carries into the base frame: the next joint's axis and
        # offset, and after the last joint the end frame's offset and rotation
        carry = np.zeros((n, depth, 3, 5))
        carry[:, :, :, 0] = axes[:, 1:]
        carry[:, :, :, 1] = offsets[:, 1:]
        carry[:, -1, :, 2:] = np.stack([p.rotation for p in end_placements])
        self.depth = depth
        buffers = {
            "placement_rot": placement_rot,
            "rot_k": rot_k,
            "rot_k2": rot_k2,
            "first": np.stack((axes[:, 0], offsets[:, 0]), 1)[:, :, None],  # (C, 2, 1, 3)
            "carry": carry,
        }
        for name, value in buffers.items():
            self.register_buffer(name, torch.as_tensor(value, dtype=dtype, device=device))
        self.register_buffer("index", torch.as_tensor(index, device=device))  # (C, L) study idx
        self.register_buffer("index_flat", self.index.reshape(-1))
        # the soles' chains are study joints 0..11 in order: a slice then, no gather
        flat = index.reshape(-1)
        contiguous = bool(np.all(np.diff(flat) == 1))
        self._slice = (int(flat[0]), len(flat)) if contiguous else None
        # constant 0/1 matrices of the graph-safe path: the gather (26, C L), the scatter of
        # the joint columns (C, L, 26; padding steps select nothing), the prefix sum (L+1)^2
        real = np.zeros((n, depth), dtype=bool)
        for c, chain in enumerate(chains):
            real[c, : len(chain)] = True
        select = np.zeros((N_JOINTS, n * depth))
        select[flat, np.arange(n * depth)] = 1.0
        scatter = np.zeros((n, depth, N_JOINTS))
        chain_i, step_i = np.nonzero(real)
        scatter[chain_i, step_i, index[real]] = 1.0
        constants = {
            "select": select,
            "scatter": scatter,
            "prefix": np.tril(np.ones((depth + 1,) * 2)),
        }
        for name, value in constants.items():
            tensor = torch.as_tensor(value, dtype=dtype, device=device)
            self.register_buffer(name, tensor, persistent=False)

    def _graph_safe(self, tensor: torch.Tensor) -> bool:
        """Whether to take the constant-matrix products: `graph_safe`, else on CUDA tensors."""
        return tensor.is_cuda if self.graph_safe is None else self.graph_safe

    def gather(self, values: torch.Tensor) -> torch.Tensor:
        """(..., 26) per-joint values -> (..., C, L) along the chains (padding repeats one)."""
        if self._slice is not None:
            values = values.narrow(-1, *self._slice)
        else:
            values = values @ self.select
        return values.unflatten(-1, (len(self.frames), self.depth))

    def chains(self, joints: torch.Tensor) -> ChainKinematics:
        """Joint axes and end frames of every chain in the base frame: the base pose cancels.

        One 3x3 product per joint depth builds the rotations after each joint; one batched
        product then carries every axis and offset into the base frame, and a cumulative sum
        gives the joint origins.
        """
        q = self.gather(joints)[..., None, None]  # (..., C, L, 1, 1)
        local = self.placement_rot + torch.sin(q) * self.rot_k + (1.0 - torch.cos(q)) * self.rot_k2
        locals_ = local.unbind(-3)
        rotations = [locals_[0]]
        for step in locals_[1:]:
            rotations.append(rotations[-1] @ step)
        moved = torch.stack(rotations, -3) @ self.carry  # (..., C, L, 3, 5)
        first = self.first.expand(moved.shape[:-4] + self.first.shape)  # (..., C, 2, 1, 3)
        moved_t = moved.transpose(-1, -2)  # (..., C, L, 5, 3)
        axes = torch.cat((first[..., 0, :, :], moved_t[..., :-1, 0, :]), -2)
        steps = torch.cat((first[..., 1, :, :], moved_t[..., :, 1, :]), -2)
        # (..., C, L + 1, 3) the joint origins, then the end frame's
        positions = self.prefix @ steps if self._graph_safe(steps) else steps.cumsum(-2)
        return ChainKinematics(
            joint_positions=positions[..., :-1, :],
            joint_axes=axes,
            frame_positions=positions[..., -1, :],
            frame_rotations=moved[..., -1, :, 2:],
        )

    def forward(
        self, base_position: torch.Tensor, base_rotation: torch.Tensor, joints: torch.Tensor
    ) -> dict[str, FrameKinematics]:
        """World placement and LOCAL Jacobian of each frame, like robot.frame_jacobian(q, f)."""
        chain = self.chains(joints)
        rot_t = chain.frame_rotations.transpose(-1, -2)  # (..., C, 3, 3) frame <- base
        p_frame = chain.frame_positions  # (..., C, 3)
        # joint columns: angular R_f^T w, linear R_f^T ((p_j - p_f) x w); rows @ R_f = R_f^T v
        lever = torch.linalg.cross(chain.joint_positions - p_frame[..., None, :], chain.joint_axes)
        columns = torch.cat((lever, chain.joint_axes), -2) @ chain.frame_rotations
        columns = columns.unflatten(-2, (2, self.depth)).transpose(-2, -1)  # (..., C, 2, 3, L)
        columns = columns.flatten(-3, -2)  # (..., C, 6, L)
        # base block: [[R^T, -R^T [p]x], [0, R^T]]
        skew = _skew_torch(p_frame)
        upper = torch.cat((rot_t, -rot_t @ skew), -1)
        lower = torch.cat((torch.zeros_like(rot_t), rot_t), -1)
        base_block = torch.cat((upper, lower), -2)  # (..., C, 6, 6)
        if self._graph_safe(columns):
            joint_block = columns @ self.scatter  # (..., C, 6, 26)
        else:
            joint_block = columns.new_zeros(columns.shape[:-1] + (N_JOINTS,))
            index = self.index.unsqueeze(-2).expand(columns.shape)
            joint_block = joint_block.scatter_add(-1, index, columns)
        jacobian = torch.cat((base_block, joint_block), -1)
        world_rot = base_rotation.unsqueeze(-3) @ chain.frame_rotations
        world_pos = base_position.unsqueeze(-2) + (
            base_rotation.unsqueeze(-3) @ p_frame[..., None]
        ).squeeze(-1)
        return {
            frame: FrameKinematics(
                world_pos[..., c, :], world_rot[..., c, :, :], jacobian[..., c, :, :]
            )
            for c, frame in enumerate(self.frames)
        }


def rotation_vee(rotation: torch.Tensor) -> torch.Tensor:
    """(..., 3) the vee of R's skew part, (R - R^T) / 2: sin(angle) times the axis, the
    rotation vector to second order (as pimann.core.rotations.vee of skew_part)."""
    r = rotation
    return 0.5 * torch.stack(
        (r[..., 2, 1] - r[..., 1, 2], r[..., 0, 2] - r[..., 2, 0], r[..., 1, 0] - r[..., 0, 1]), -1
    )


def _skew_torch(v: torch.Tensor) -> torch.Tensor:
    x, y, z = v.unbind(-1)
    zero = torch.zeros_like(x)
    return torch.stack(
        (
            torch.stack((zero, -z, y), -1),
            torch.stack((z, zero, -x), -1),
            torch.stack((-y, x, zero), -1),
        ),
        -2,
    )
