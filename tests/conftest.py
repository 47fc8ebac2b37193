"""Shared fixtures: the real ergoCub model from the shared folder, seeded generators, and the
small training's params and dataset (test_train, test_sweep)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from builders import SMALL_MODEL, synthetic_collection

from pimann.core.params import SimulateParams, load_params
from pimann.core.paths import SHARED_ENV, shared_dir
from pimann.core.robot import Robot, load_robot
from pimann.learn.dataset import write_dataset
from pimann.learn.features import build_dataset
from pimann.sim.synthetic import standing_feet
from pimann.sim.wbc import standing_pose


def pytest_configure(config: pytest.Config) -> None:
    """The tests read the robot and the mocap in place: without the shared folder, one line."""
    if not (shared_dir() / "robots").is_dir():
        pytest.exit(f"{shared_dir()}: no shared folder with robots/ here; set ${SHARED_ENV}", 2)


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


REAL_WALK = "Bandai-Namco-Research-Motiondataset-1/data/dataset-1_walk_normal_001.bvh"
REAL_BACKWARD = "Bandai-Namco-Research-Motiondataset-1/data/dataset-1_walk-back_active_001.bvh"


@pytest.fixture(scope="session")
def real_walks():
    """{name: trajectory}: two real Bandai Namco clips (forward, backward) retargeted as the
    retarget stage does it, and the forward one's mirror (about 4 s of CPU)."""
    from pimann.core.paths import mocap_dir
    from pimann.mocap.mirror import mirror_trajectory
    from pimann.retarget import retarget_file

    params = load_params()
    root = mocap_dir() / "bandai-namco/dataset"
    forward = retarget_file(root / REAL_WALK, params)
    return {
        "walk": forward,
        "walk_mirrored": mirror_trajectory(forward),
        "walk_back": retarget_file(root / REAL_BACKWARD, params),
    }


@pytest.fixture(scope="module")
def params():
    """The small training's params (test_train, test_sweep) on the paper's layout (130
    inputs, 100 outputs: no gait phase, the sizes these tests name); a test module's own
    `params` fixture overrides this one."""
    base = load_params()
    train = dataclasses.replace(base.train, epochs=4, batch_size=64, device="cpu")
    features = dataclasses.replace(base.features, gait_phase=False)
    return dataclasses.replace(base, model=SMALL_MODEL, train=train, features=features)


@pytest.fixture(scope="module")
def dataset_path(tmp_path_factory, params):
    """A tiny dataset: 4 synthetic sources and their 'mirrors', ~50 samples each."""
    dataset = build_dataset(synthetic_collection(n_sources=4, frames=160), params.features, "full")
    path = tmp_path_factory.mktemp("features") / "full.h5"
    write_dataset(path, dataset)
    return path
