"""ergoCub: the one place that knows the 26-joint order, the frames and the standing pose.

pinocchio orders joints by the kinematic tree (torso roll before pitch, neck after the left
arm), not in the study's order. Everything outside this module speaks the study's order
(`JOINT_NAMES`); `Robot` maps to and from pinocchio's vectors by name.
"""

from __future__ import annotations

from functools import cache
from pathlib import Path

import numpy as np
import pinocchio as pin

from pimann.core.errors import PimannError
from pimann.core.paths import robots_dir

JOINT_NAMES: tuple[str, ...] = (
    "l_hip_pitch",
    "l_hip_roll",
    "l_hip_yaw",
    "l_knee",
    "l_ankle_pitch",
    "l_ankle_roll",
    "r_hip_pitch",
    "r_hip_roll",
    "r_hip_yaw",
    "r_knee",
    "r_ankle_pitch",
    "r_ankle_roll",
    "torso_pitch",
    "torso_roll",
    "torso_yaw",
    "neck_pitch",
    "neck_roll",
    "neck_yaw",
    "l_shoulder_pitch",
    "l_shoulder_roll",
    "l_shoulder_yaw",
    "l_elbow",
    "r_shoulder_pitch",
    "r_shoulder_roll",
    "r_shoulder_yaw",
    "r_elbow",
)
N_JOINTS = len(JOINT_NAMES)
# indices of the 12 leg joints (hips, knees, ankles) in JOINT_NAMES, for gait diagnostics
LEG_JOINTS = [
    k for k, name in enumerate(JOINT_NAMES) if name[2:].startswith(("hip", "knee", "ankle"))
]

STANDING_JOINTS = np.array(
    [
        -0.1092,
        0.0189,
        0.0716,
        -0.0714,
        -0.0932,
        -0.0208,
        -0.1051,
        0.0326,
        0.0739,
        -0.0879,
        -0.1038,
        -0.0337,
        0.1519,
        0.0003,
        -0.0079,
        -0.0007,
        -0.0017,
        -0.0009,
        -0.0355,
        0.1000,
        -0.2207,
        0.0450,
        -0.0415,
        0.1000,
        -0.2240,
        0.0455,
    ]
)
STANDING_BASE_HEIGHT = 0.7748
STANDING_BASE_QUATERNION_XYZW = np.array([0.0, -0.0399893, 0.0, 0.9992001])

# The 13 XSens segments the study uses; each has a `data_<Segment>` frame on the xsens model.
SEGMENTS: tuple[str, ...] = (
    "Pelvis",
    "T8",
    "Head",
    "LeftUpperLeg",
    "LeftLowerLeg",
    "LeftFoot",
    "RightUpperLeg",
    "RightLowerLeg",
    "RightFoot",
    "LeftUpperArm",
    "LeftForeArm",
    "RightUpperArm",
    "RightForeArm",
)

BASE_FRAME = "root_link"
LEFT_SOLE = "l_sole"
RIGHT_SOLE = "r_sole"
CHEST_FRAME = "chest"

# The one foot geometry of every stage: ergoCub's sole is the rectangle spanned by the two
# foot collision boxes of the simulation URDF, +-0.118 m long and +-0.05 m wide about the
# sole frame. Retargeting pins it, generation rolls on it, contacts and metrics watch its
# lowest corner, MuJoCo collides with it and the renderer draws it. (The authors' evaluation
# used smaller corners, +-0.08 x +-0.03 m; for a flat foot both give the same heights.)
SOLE_HALF_LENGTH = 0.118
SOLE_HALF_WIDTH = 0.05
SOLE_CORNERS = np.array(
    [
        [x, y, 0.0]
        for x in (SOLE_HALF_LENGTH, -SOLE_HALF_LENGTH)
        for y in (SOLE_HALF_WIDTH, -SOLE_HALF_WIDTH)
    ]
)


def corner_offsets(rotations: np.ndarray, corners: np.ndarray = SOLE_CORNERS) -> np.ndarray:
    """(..., C, 3) the sole corners from the sole origin in world axes (R c), for sole
    rotations (..., 3, 3): every stage that asks where a sole meets the floor asks it here."""
    return np.swapaxes(rotations @ corners.T, -1, -2)


# What each robot variant reads from the shared robots folder: its URDF, and the mesh folder
# MuJoCo loads with it (pinocchio builds kinematics only and reads no mesh). The DVC stages
# list these files as deps (tests/test_dvc_deps.py finds every use of these names).
MODEL_FILES = {
    "retarget": "ergoCubGazeboV1_xsens/ergoCubGazeboV1_xsens.urdf",
    "simulation": "ergoCub/robots/ergoCubGazeboV1_3_minContacts/model.urdf",
}
# MuJoCo finds the simulation model's meshes here by file name (pimann.sim.model: strippath);
# pinocchio builds no geometry, so it reads the URDFs alone
MESH_DIRS = {"simulation": "ergoCub/meshes/simmechanics"}


def mirror_joint_name(name: str) -> str:
    """The name of the joint on the other side (`l_knee` <-> `r_knee`); others unchanged."""
    if name.startswith("l_"):
        return "r_" + name[2:]
    if name.startswith("r_"):
        return "l_" + name[2:]
    return name


class Robot:
    """ergoCub with a free-flyer base, reduced to the study's 26 joints (the rest locked at 0).

    Configuration q = [base position (3), base quaternion xyzw (4), joints in pinocchio order];
    velocity v = [base linear, base angular (body frame), joint velocities in pinocchio order].
    Use `configuration` / `split_configuration` to speak the study's joint order.
    """

    def __init__(self, urdf_path: Path):
        if not urdf_path.is_file():
            raise PimannError(urdf_path, "robot model not found (set PIMANN_SHARED?)")
        self.urdf_path = urdf_path
        self.package_dir = robots_dir()
        full = pin.buildModelFromUrdf(str(urdf_path), pin.JointModelFreeFlyer())
        keep = set(JOINT_NAMES)
        missing = keep - set(full.names)
        if missing:
            raise PimannError(urdf_path, f"model lacks joints {sorted(missing)}")
        locked = [
            full.getJointId(name)
            for name in full.names[2:]  # skip universe and the free flyer
            if name not in keep
        ]
        self.model: pin.Model = pin.buildReducedModel(full, locked, pin.neutral(full))
        self.data: pin.Data = self.model.createData()
        # index of each study joint in pinocchio's q and v vectors
        self.q_index = np.array([self.model.idx_qs[self.model.getJointId(n)] for n in JOINT_NAMES])
        self.v_index = np.array([self.model.idx_vs[self.model.getJointId(n)] for n in JOINT_NAMES])
        self.velocity_order = np.concatenate([np.arange(6), self.v_index])
        self.joint_lower = self.model.lowerPositionLimit[self.q_index].copy()
        self.joint_upper = self.model.upperPositionLimit[self.q_index].copy()
        self.total_mass = float(pin.computeTotalMass(self.model))

    @property
    def joint_names(self) -> tuple[str, ...]:
        return JOINT_NAMES

    def frame_id(self, name: str) -> int:
        if not self.model.existFrame(name):
            raise PimannError(self.urdf_path, f"no frame named {name!r}")
        return self.model.getFrameId(name)

    def configuration(self, base_position, base_quaternion_xyzw, joint_positions) -> np.ndarray:
        """pinocchio q from a base pose and joints in the study's order."""
        q = np.zeros(self.model.nq)
        q[:3] = base_position
        quaternion = np.asarray(base_quaternion_xyzw, dtype=float)
        q[3:7] = quaternion / np.linalg.norm(quaternion)
        q[self.q_index] = joint_positions
        return q

    def split_configuration(self, q) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(base position, base quaternion xyzw, joints in the study's order) from q."""
        q = np.asarray(q)
        return q[:3].copy(), q[3:7].copy(), q[self.q_index].copy()

    def standing_configuration(self) -> np.ndarray:
        return self.configuration(
            [0.0, 0.0, STANDING_BASE_HEIGHT], STANDING_BASE_QUATERNION_XYZW, STANDING_JOINTS
        )

    def velocity(self, base_linear, base_angular, joint_velocities) -> np.ndarray:
        """pinocchio v from a body-frame base twist and joint velocities in the study's order."""
        v = np.zeros(self.model.nv)
        v[:3] = base_linear
        v[3:6] = base_angular
        v[self.v_index] = joint_velocities
        return v

    def frame_placement(self, q, frame: str) -> pin.SE3:
        pin.framesForwardKinematics(self.model, self.data, np.asarray(q, dtype=float))
        return self.data.oMf[self.frame_id(frame)].copy()

    def frame_jacobian(
        self, q, frame: str, reference: pin.ReferenceFrame = pin.LOCAL
    ) -> np.ndarray:
        """6 x (6 + 26) Jacobian, columns [base twist (body frame), joints in study order]."""
        q = np.asarray(q, dtype=float)
        jacobian = pin.computeFrameJacobian(
            self.model, self.data, q, self.frame_id(frame), reference
        )
        return jacobian[:, self.velocity_order]


@cache
def load_robot(variant: str = "retarget") -> Robot:
    """The ergoCub model; `retarget` has the `data_*` XSens frames, `simulation` the foot boxes."""
    if variant not in MODEL_FILES:
        raise PimannError(None, f"unknown robot variant {variant!r}; known: {sorted(MODEL_FILES)}")
    return Robot(robots_dir() / MODEL_FILES[variant])
