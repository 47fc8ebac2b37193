"""The MuJoCo ergoCub: joint/quaternion mapping to pinocchio, contacts, standing for 10 s."""

from __future__ import annotations

import mujoco
import numpy as np
import pinocchio as pin
import pytest
from builders import random_configuration

from pimann.core.params import load_params
from pimann.core.robot import JOINT_NAMES, LEFT_SOLE, RIGHT_SOLE, load_robot
from pimann.sim.model import build_sim_model
from pimann.sim.wbc import SOLE_HEIGHT, standing_pose


@pytest.fixture(scope="module")
def params():
    return load_params().simulate


@pytest.fixture(scope="module")
def sim(params):
    return build_sim_model(params)


@pytest.fixture(scope="module")
def sim_robot():
    return load_robot("simulation")


def test_model_has_the_study_joints(sim, params):
    model = sim.model
    assert model.nu == len(JOINT_NAMES) and model.nq == 7 + 26 and model.nv == 6 + 26
    assert [model.actuator(i).name for i in range(model.nu)] == list(JOINT_NAMES)
    assert model.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    knee = model.actuator("l_knee").id
    assert model.actuator_gainprm[knee, 0] == params.kp_legs_torso
    assert model.actuator_biasprm[knee, 2] == pytest.approx(-params.kv_ratio * params.kp_legs_torso)
    assert model.actuator_gainprm[model.actuator("r_elbow").id, 0] == params.kp_arms


def test_state_maps_to_pinocchio_by_name(sim, sim_robot, rng):
    """Same q in both: the root, the soles' boxes and the CoM agree with pinocchio."""
    data = sim.new_data()
    for _ in range(3):
        q = random_configuration(sim_robot, rng)
        sim.set_configuration(data, sim_robot, q)
        back = sim.configuration(data, sim_robot)
        np.testing.assert_allclose(back[7:], q[7:], atol=1e-12)
        assert abs(abs(np.dot(back[3:7], q[3:7])) - 1.0) < 1e-12
        pin.centerOfMass(sim_robot.model, sim_robot.data, q)
        np.testing.assert_allclose(sim.com(data), sim_robot.data.com[0], atol=1e-9)
        for side, frame in enumerate((LEFT_SOLE, RIGHT_SOLE)):
            sole = sim_robot.frame_placement(q, frame)
            for geom in sim.foot_geoms[side]:
                local = sole.actInv(data.geom_xpos[geom])
                # box centre: +-0.0596 m along the sole, its bottom SOLE_HEIGHT above the sole
                assert abs(abs(local[0]) - 0.0596) < 1e-3 and abs(local[1]) < 1e-6
                bottom = local[2] - sim.model.geom_size[geom, 2]
                assert bottom == pytest.approx(SOLE_HEIGHT, abs=1e-6)


def test_standing_pose_is_flat(sim_robot, params):
    q = standing_pose(sim_robot, params)
    for frame in (LEFT_SOLE, RIGHT_SOLE):
        sole = sim_robot.frame_placement(q, frame)
        np.testing.assert_allclose(sole.rotation, np.eye(3), atol=2e-3)
        assert sole.translation[2] == pytest.approx(-SOLE_HEIGHT, abs=1e-3)
    com = pin.centerOfMass(sim_robot.model, sim_robot.data, q)
    assert com[2] == pytest.approx(params.com_height, abs=5e-3)


def test_stands_for_ten_seconds(sim, sim_robot, params):
    """Position control on the flat standing pose: no fall, the base keeps its height."""
    q = standing_pose(sim_robot, params)
    data = sim.new_data()
    sim.set_configuration(data, sim_robot, q)
    start_height = sim.base_height(data)
    feet_start = [data.xpos[sim.model.geom_bodyid[g[0]]].copy() for g in sim.foot_geoms]
    heights = []
    for _ in range(10):
        for _ in range(int(round(1.0 / params.timestep))):
            mujoco.mj_step(sim.model, data)
        heights.append(sim.base_height(data))
    assert np.max(np.abs(np.array(heights) - start_height)) < 0.01
    # the floor carries the robot's weight, the ZMP sits between the feet
    zmp, normal = sim.zmp(data)
    weight = sim.model.body_subtreemass[0] * -sim.model.opt.gravity[2]
    assert normal == pytest.approx(weight, rel=0.01)
    np.testing.assert_allclose(zmp, sim.com(data)[:2], atol=0.01)  # static: ZMP under the CoM
    for start, geoms in zip(feet_start, sim.foot_geoms, strict=True):
        now = data.xpos[sim.model.geom_bodyid[geoms[0]]]
        assert np.linalg.norm(now[:2] - start[:2]) < 1e-3


def test_fast_zmp_matches_contact_forces(sim, sim_robot, params):
    """The cfrc_ext ZMP equals the ZMP summed contact by contact (mj_contactForce) while rocking."""
    data = sim.new_data()
    sim.set_configuration(data, sim_robot, standing_pose(sim_robot, params))
    data.ctrl[JOINT_NAMES.index("l_ankle_pitch")] += 0.05
    data.ctrl[JOINT_NAMES.index("r_ankle_roll")] -= 0.05
    compared = 0
    for step in range(400):
        mujoco.mj_step(sim.model, data)
        if step % 20:
            continue
        fast, normal = sim.zmp(data)
        slow, normal_slow = sim.zmp_from_contacts(data)
        assert normal == pytest.approx(normal_slow, rel=1e-9, abs=1e-9)
        if normal > 10.0:
            # contact points sit mid-penetration (~1e-4 m below z = 0): mm agreement
            np.testing.assert_allclose(fast, slow, atol=2e-3)
            compared += 1
    assert compared > 10
