"""Shared fixtures: the real ergoCub model from the shared folder, seeded generators."""

from __future__ import annotations

import numpy as np
import pytest

from pimann.robot import Robot, load_robot


@pytest.fixture(scope="session")
def robot() -> Robot:
    return load_robot("retarget")


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(1234)


def random_configuration(robot: Robot, rng: np.random.Generator) -> np.ndarray:
    """A configuration with a random base pose and joints inside their limits."""
    joints = rng.uniform(robot.joint_lower, robot.joint_upper)
    quaternion = rng.normal(size=4)
    return robot.configuration(rng.normal(size=3), quaternion, joints)
