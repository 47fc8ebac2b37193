"""Shared fixtures: the real ergoCub model from the shared folder, seeded generators."""

from __future__ import annotations

import numpy as np
import pytest

from pimann.params import ContactParams, EvaluateParams, SimulateParams, load_params
from pimann.robot import Robot, load_robot
from pimann.sim.synthetic import standing_feet
from pimann.sim.wbc import standing_pose

# The repository's evaluation settings, spelled out so the tests do not move with params.yaml.
CONTACT_PARAMS = ContactParams(on_height=0.02, off_height=0.02, switch_time=0.04)
EVALUATE_PARAMS = EvaluateParams(
    pi_weight=10.0,
    skating_height=0.05,
    skating_speed_per_frame=0.025,
    skating_rate_hz=20.0,
    walk_distance=1.0,
    foot_velocity_frame="local_world_aligned",
)


@pytest.fixture(scope="session")
def robot() -> Robot:
    return load_robot("retarget")


@pytest.fixture(scope="session")
def sim_robot() -> Robot:
    return load_robot("simulation")


@pytest.fixture(scope="session")
def sim_params() -> SimulateParams:
    return load_params().simulate


@pytest.fixture(scope="session")
def stance(sim_robot, sim_params) -> tuple[np.ndarray, np.ndarray]:
    """The simulation robot's standing configuration and its feet (x, y, yaw)."""
    q0 = standing_pose(sim_robot, sim_params)
    return q0, standing_feet(sim_robot, q0)


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(1234)


def random_configuration(robot: Robot, rng: np.random.Generator) -> np.ndarray:
    """A configuration with a random base pose and joints inside their limits."""
    joints = rng.uniform(robot.joint_lower, robot.joint_upper)
    quaternion = rng.normal(size=4)
    return robot.configuration(rng.normal(size=3), quaternion, joints)


REAL_WALK = "Bandai-Namco-Research-Motiondataset-1/data/dataset-1_walk_normal_001.bvh"
REAL_BACKWARD = "Bandai-Namco-Research-Motiondataset-1/data/dataset-1_walk-back_active_001.bvh"


@pytest.fixture(scope="session")
def real_walks():
    """{name: trajectory}: two real Bandai Namco clips (forward, backward) retargeted as the
    retarget stage does it, and the forward one's mirror (about 4 s of CPU)."""
    from pimann.mocap.mirror import mirror_trajectory
    from pimann.paths import mocap_dir
    from pimann.retarget import retarget_file

    params = load_params()
    root = mocap_dir() / "bandai-namco/dataset"
    forward = retarget_file(root / REAL_WALK, params)
    return {
        "walk": forward,
        "walk_mirrored": mirror_trajectory(forward),
        "walk_back": retarget_file(root / REAL_BACKWARD, params),
    }
