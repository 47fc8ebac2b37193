"""The MuJoCo ergoCub: built at run time from the `_minContacts` URDF, mapped to pinocchio by name.

MuJoCo reads the URDF once a `<mujoco><compiler .../></mujoco>` element is added; MjSpec then
adds what a URDF cannot say (free base, floor, position actuators, armature) and deletes the
joints the study locks, which welds their bodies to the parent. Joint and quaternion orders
differ from pinocchio's (MuJoCo w x y z), so every exchange goes through `SimModel`.
"""

from __future__ import annotations

import dataclasses
import re

import mujoco
import numpy as np

from pimann.core.errors import PimannError
from pimann.core.params import SimulateParams
from pimann.core.paths import robots_dir
from pimann.core.robot import JOINT_NAMES, MESH_DIRS, MODEL_FILES, Robot

BASE_BODY = "root_link"
FOOT_BODIES = ("l_ankle_2", "r_ankle_2")  # the foot boxes are fused into these bodies


def _gain(name: str, params: SimulateParams) -> float:
    if "shoulder" in name or "elbow" in name:
        return params.kp_arms
    if name.startswith("neck"):
        return params.kp_neck
    return params.kp_legs_torso


@dataclasses.dataclass
class SimModel:
    """A compiled MjModel plus the index maps between it and pinocchio's `Robot`."""

    model: mujoco.MjModel
    qpos_index: np.ndarray  # (26,) qpos address of each study joint
    dof_index: np.ndarray  # (26,) qvel address of each study joint
    foot_geoms: tuple[np.ndarray, np.ndarray]  # geom ids of the left / right foot boxes
    floor_geom: int
    foot_bodies: np.ndarray  # (2,) body ids of the feet
    foot_roots: np.ndarray  # (2,) their kinematic tree's root body (cfrc_ext's reference)

    def new_data(self) -> mujoco.MjData:
        return mujoco.MjData(self.model)

    def set_configuration(self, data: mujoco.MjData, robot: Robot, q: np.ndarray) -> None:
        """Write pinocchio's q (base xyzw) into MuJoCo's qpos (base wxyz), zero velocity."""
        position, quat_xyzw, joints = robot.split_configuration(q)
        data.qpos[:3] = position
        data.qpos[3:7] = np.roll(quat_xyzw, 1)
        data.qpos[self.qpos_index] = joints
        data.qvel[:] = 0.0
        data.ctrl[:] = joints
        mujoco.mj_forward(self.model, data)

    def configuration(self, data: mujoco.MjData, robot: Robot) -> np.ndarray:
        """pinocchio's q of the simulated state."""
        return robot.configuration(data.qpos[:3], np.roll(data.qpos[3:7], -1), self.joints(data))

    def joints(self, data: mujoco.MjData) -> np.ndarray:
        return data.qpos[self.qpos_index].copy()

    def base_height(self, data: mujoco.MjData) -> float:
        return float(data.qpos[2])

    def com(self, data: mujoco.MjData) -> np.ndarray:
        """Whole-body CoM (subtree of the world body), valid after mj_forward/mj_step."""
        return data.subtree_com[0].copy()

    def foot_forces(self, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray]:
        """Per foot: world-frame contact force on the foot (3,) and its CoP (3,), NaN if none.

        The sum over every contact between a foot's boxes and the floor (mj_contactForce gives
        the force in the contact frame, whose first axis is the normal).
        """
        forces = np.zeros((2, 3))
        moments = np.zeros((2, 3))  # sum of p * f_z, for the CoP on flat ground
        wrench = np.zeros(6)
        for i in range(data.ncon):
            contact = data.contact[i]
            geoms = (contact.geom1, contact.geom2)
            if self.floor_geom not in geoms:
                continue
            other = geoms[1] if geoms[0] == self.floor_geom else geoms[0]
            side = next((s for s in (0, 1) if other in self.foot_geoms[s]), None)
            if side is None:
                continue
            mujoco.mj_contactForce(self.model, data, i, wrench)
            frame = contact.frame.reshape(3, 3)  # rows: normal, tangent1, tangent2
            force = frame.T @ wrench[:3]  # force on geom2 by geom1, world frame
            if contact.geom1 == other:
                force = -force
            forces[side] += force
            moments[side] += contact.pos * force[2]
        cops = np.full((2, 3), np.nan)
        loaded = forces[:, 2] > 1e-6
        cops[loaded] = moments[loaded] / forces[loaded, 2:3]
        return forces, cops

    def zmp_from_contacts(self, data: mujoco.MjData) -> tuple[np.ndarray, float]:
        """Measured ZMP (x, y) and total normal force, contact by contact (slow reference)."""
        forces, cops = self.foot_forces(data)
        total = float(forces[:, 2].sum())
        if total < 1e-6:
            return np.full(2, np.nan), 0.0
        loaded = forces[:, 2] > 1e-6
        point = (cops[loaded, :2] * forces[loaded, 2:3]).sum(axis=0) / total
        return point, total

    def foot_normal_forces(self, data: mujoco.MjData) -> np.ndarray:
        """(2,) floor's normal force on the left / right foot; valid after `zmp` (cfrc_ext)."""
        return data.cfrc_ext[self.foot_bodies, 5].copy()

    def zmp(self, data: mujoco.MjData) -> tuple[np.ndarray, float]:
        """Measured ZMP (x, y) on the floor (z = 0) and the total normal force, vectorised.

        The feet are the only bodies that touch the floor, so their external wrenches
        (`cfrc_ext`, after mj_rnePostConstraint; torque then force, about the tree's CoM) are
        the contact wrenches. A Python loop over contacts costs more than the physics step.
        """
        mujoco.mj_rnePostConstraint(self.model, data)
        wrench = data.cfrc_ext[self.foot_bodies].sum(axis=0)
        torque, force = wrench[:3], wrench[3:]
        if force[2] < 1e-6:
            return np.full(2, np.nan), 0.0
        c = data.subtree_com[self.foot_roots[0]]
        x = c[0] - (torque[1] + c[2] * force[0]) / force[2]
        y = c[1] + (torque[0] - c[2] * force[1]) / force[2]
        return np.array([x, y]), float(force[2])


def _urdf_text(visual: bool = False) -> str:
    path = robots_dir() / MODEL_FILES["simulation"]
    if not path.is_file():
        raise PimannError(path, "simulation model not found (set PIMANN_SHARED?)")
    mesh_dir = robots_dir() / MESH_DIRS["simulation"]
    compiler = (
        f'<mujoco><compiler meshdir="{mesh_dir}" strippath="true" balanceinertia="true" '
        f'discardvisual="{str(not visual).lower()}"/></mujoco>'
    )
    text, count = re.subn(
        r"(<robot\b[^>]*>)", lambda m: m.group(1) + compiler, path.read_text(), count=1
    )
    if count != 1:
        raise PimannError(path, "no <robot> element")
    return text


def build_sim_model(params: SimulateParams, visual: bool = False) -> SimModel:
    """The MuJoCo ergoCub with a free base, a floor, and position actuators on the 26 joints.

    `visual` keeps the URDF's meshes for rendering (replaying states, not for simulating).
    """
    spec = mujoco.MjSpec.from_string(_urdf_text(visual))
    spec.option.timestep = params.timestep
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    for joint in list(spec.joints):
        if joint.name not in JOINT_NAMES:
            spec.delete(joint)
    base = spec.body(BASE_BODY)
    base.add_freejoint(name="base")
    spec.worldbody.add_geom(
        name="floor",
        type=mujoco.mjtGeom.mjGEOM_PLANE,
        size=[0.0, 0.0, 0.05],
        friction=[params.friction, 0.005, 0.0001],
    )
    if visual:  # a checkered floor shows the walk's progress on video
        spec.add_texture(
            name="grid",
            type=mujoco.mjtTexture.mjTEXTURE_2D,
            builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER,
            rgb1=[0.45, 0.5, 0.55],
            rgb2=[0.65, 0.7, 0.75],
            width=64,
            height=64,
        )
        material = spec.add_material(name="grid", texrepeat=[4.0, 4.0], texuniform=True)
        material.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = "grid"
        spec.geom("floor").material = "grid"
    for geom in spec.geoms:
        if geom.name != "floor":
            geom.friction = [params.friction, 0.005, 0.0001]
    for name in JOINT_NAMES:
        joint = spec.joint(name)
        joint.armature = params.armature
        kp = _gain(name, params)
        actuator = spec.add_actuator(name=name, target=name)
        actuator.trntype = mujoco.mjtTrn.mjTRN_JOINT
        actuator.set_to_position(kp=kp, kv=params.kv_ratio * kp)
    model = spec.compile()
    qpos_index = np.array([model.jnt_qposadr[model.joint(n).id] for n in JOINT_NAMES])
    dof_index = np.array([model.jnt_dofadr[model.joint(n).id] for n in JOINT_NAMES])
    foot_geoms = tuple(np.flatnonzero(model.geom_bodyid == model.body(b).id) for b in FOOT_BODIES)
    if any(len(g) == 0 for g in foot_geoms):
        raise PimannError(robots_dir() / MODEL_FILES["simulation"], "foot boxes not found")
    foot_bodies = np.array([model.body(b).id for b in FOOT_BODIES])
    return SimModel(
        model,
        qpos_index,
        dof_index,
        foot_geoms,
        model.geom("floor").id,
        foot_bodies,
        model.body_rootid[foot_bodies],
    )
