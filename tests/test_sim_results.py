"""Simulation outputs: the result file, the ZMP-outside-support figure, `pimann simulate`, video."""

from __future__ import annotations

import dataclasses
import json

import h5py
import imageio.v3 as iio
import numpy as np
import pinocchio as pin
import pytest

import pimann.sim  # noqa: F401 -- headless GL backend before mujoco loads
from pimann.cli import main
from pimann.core.robot import JOINT_NAMES
from pimann.core.trajectory import read_trajectory, write_trajectory
from pimann.report.figures import _read_sim
from pimann.sim.closed_loop import simulate_plan
from pimann.sim.dcm import plan_dcm
from pimann.sim.simulation_files import (
    CONTACT_FORCE_N,
    distance_outside_polygon,
    foot_rectangle,
    read_simulation,
    write_simulation,
    zmp_outside_support,
)
from pimann.sim.synthetic import standing_feet, stepping_plan, stepping_trajectory
from pimann.sim.video import render_simulation
from pimann.sim.wbc import standing_pose

RECTANGLE = np.array([[0.0, 0.0], [0.2, 0.0], [0.2, 0.1], [0.0, 0.1]])


@pytest.fixture(scope="module")
def walk(sim_robot, sim_params):
    """Two real steps in MuJoCo (2.6 s): a SimulationResult with touchdowns and a swing."""
    q0 = standing_pose(sim_robot, sim_params)
    plan = stepping_plan(standing_feet(sim_robot, q0), 2, 0.1, single=0.5, start=0.8, end=0.3)
    dcm = plan_dcm(plan, sim_params, pin.centerOfMass(sim_robot.model, sim_robot.data, q0))
    return simulate_plan(plan, dcm, sim_params, q0, robot=sim_robot)


@pytest.mark.parametrize(
    "point, expected",
    [
        ((0.1, 0.05), 0.0),  # inside
        ((0.2, 0.05), 0.0),  # on an edge
        ((0.21, 0.05), 0.01),  # 1 cm beyond the front edge
        ((0.1, -0.01), 0.01),  # 1 cm beyond the side
        ((0.23, 0.14), 0.05),  # beyond a corner: 3-4-5
        ((-0.03, -0.04), 0.05),
    ],
)
def test_distance_outside_rectangle(point, expected):
    for polygon in (RECTANGLE, RECTANGLE[::-1], RECTANGLE[[2, 0, 3, 1]]):  # any vertex order
        assert distance_outside_polygon(np.array(point), polygon) == pytest.approx(expected)


def test_distance_outside_two_feet_hull():
    """Between two feet is inside their hull (double support); beside both is not."""
    left = foot_rectangle(np.array([0.0, 0.1]), 0.0, 0.1, 0.05)
    right = foot_rectangle(np.array([0.0, -0.1]), 0.0, 0.1, 0.05)
    feet = np.concatenate([left, right])
    assert distance_outside_polygon(np.array([0.05, 0.0]), feet) == 0.0
    assert distance_outside_polygon(np.array([0.0, 0.0]), left) == pytest.approx(0.05)
    assert distance_outside_polygon(np.array([0.12, 0.0]), feet) == pytest.approx(0.02)
    assert np.isnan(distance_outside_polygon(np.array([0.0, 0.0]), np.empty((0, 2))))
    assert np.isnan(distance_outside_polygon(np.array([np.nan, 0.0]), feet))


def test_foot_rectangle_turns_with_yaw():
    corners = foot_rectangle(np.array([1.0, 2.0]), np.pi / 2, 0.1, 0.05)
    assert sorted(map(tuple, np.round(corners, 12))) == [
        (0.95, 1.9),
        (0.95, 2.1),
        (1.05, 1.9),
        (1.05, 2.1),
    ]


def test_zmp_stays_in_support_while_walking(walk, sim_params):
    """A physical ZMP cannot leave the support polygon: the estimate stays within 5 mm."""
    outside = zmp_outside_support(walk, sim_params)
    assert not walk.fallen and outside.shape == walk.time.shape
    assert np.nanmax(outside) < 0.005
    # a ZMP 1 m to the left: 1 m less the support's reach left of it (< 0.35 m: two feet)
    far = dataclasses.replace(walk, zmp_measured=walk.zmp_measured + [0.0, 1.0])
    assert (
        0.65
        < np.nanmin(zmp_outside_support(far, sim_params))
        <= np.nanmax(zmp_outside_support(far, sim_params))
        < 1.0
    )


def test_result_file_round_trip(walk, sim_params, tmp_path):
    path = tmp_path / "run-mixed.h5"
    summary = write_simulation(path, walk, sim_params, source="synthetic", attrs={"model": "w10"})
    data, attrs = read_simulation(path)
    trajectory = read_trajectory(path)  # the simulated robot, as the trajectory contract says
    np.testing.assert_array_equal(trajectory.time, walk.time)
    np.testing.assert_array_equal(trajectory.joint_positions, walk.joints_measured)
    np.testing.assert_array_equal(trajectory.base_position, walk.base_pose[:, :3])
    np.testing.assert_array_equal(trajectory.base_quaternion_xyzw, walk.base_pose[:, 3:])
    np.testing.assert_array_equal(trajectory.contacts, walk.foot_forces > CONTACT_FORCE_N)
    np.testing.assert_array_equal(trajectory.com_position, walk.com_world)
    assert trajectory.rate_hz == pytest.approx(sim_params.control_rate_hz)
    assert trajectory.attrs["model"] == "w10" and not trajectory.contacts.all()
    for name in (
        "joints_reference",
        "joints_generated",
        "com_reference",
        "zmp_measured",
        "zmp_reference",
        "soles_measured",
    ):
        np.testing.assert_allclose(data[name], getattr(walk, name), rtol=1e-6, atol=1e-6)
    np.testing.assert_array_equal(data["joints_measured"], walk.joints_measured)
    np.testing.assert_array_equal(data["foot_slip"], walk.foot_slip_per_foot)
    assert attrs["fall"] == walk.fallen is False
    for key in (
        "success",
        "distance_walked_m",
        "joint_rmse_rad",
        "zmp_outside_max_m",
        "real_time_factor",
        "foot_slip_left_m",
    ):
        assert attrs[key] == pytest.approx(summary[key])
    assert summary["joint_rmse_rad"] == pytest.approx(
        np.sqrt(np.mean((walk.joints_measured - walk.joints_reference) ** 2))
    )
    assert summary["steps"] == 2 and summary["success"]
    # 2 steps of 0.1 m: the path between the feet advances half a step, 0.05 m
    assert summary["distance_planned_m"] == pytest.approx(0.05, abs=1e-6)
    assert summary["distance_walked_m"] == pytest.approx(0.05, abs=0.01)
    figure = _read_sim(path)  # what the joint-tracking figure reads
    assert list(figure["names"]) == list(JOINT_NAMES)
    assert figure["joints_measured"].shape == (len(walk.time), 26)


def test_result_file_decimated(walk, sim_params, tmp_path):
    path = tmp_path / "half.h5"
    write_simulation(path, walk, sim_params, rate_hz=50.0)
    data, _ = read_simulation(path)
    np.testing.assert_allclose(np.diff(data["time"]), 0.02, atol=1e-9)
    np.testing.assert_array_equal(data["joints_measured"], walk.joints_measured[::2])


def test_cli_simulate_bad_file(tmp_path, capsys):
    bad = tmp_path / "broken.h5"
    bad.write_bytes(b"not an hdf5 file")
    assert main(["simulate", str(bad), "-o", str(tmp_path / "out.h5")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(bad) in err
    assert not (tmp_path / "out.h5").exists()


def test_cli_simulate_no_contacts_names_file(tmp_path, capsys, sim_robot, sim_params):
    q0 = standing_pose(sim_robot, sim_params)
    plan = stepping_plan(standing_feet(sim_robot, q0), 2, 0.1)
    trajectory = dataclasses.replace(stepping_trajectory(sim_robot, sim_params, plan, 10.0))
    trajectory.contacts = None
    path = tmp_path / "nocontacts.h5"
    write_trajectory(path, trajectory)
    assert main(["simulate", str(path), "-o", str(tmp_path / "out.h5")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(path) in err and "contacts" in err


def test_cli_simulate_runs(tmp_path, capsys, sim_robot, sim_params):
    q0 = standing_pose(sim_robot, sim_params)
    plan = stepping_plan(standing_feet(sim_robot, q0), 2, 0.1, single=0.35, double=0.1)
    source = tmp_path / "walk.h5"
    write_trajectory(source, stepping_trajectory(sim_robot, sim_params, plan, 25.0))
    out, strip = tmp_path / "sim.h5", tmp_path / "sim.png"
    argv = ["simulate", str(source), "-o", str(out), "--duration", "1.5", "--video", str(strip)]
    assert main(argv) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["simulated_s"] == pytest.approx(1.5) and not summary["fallen"]
    with h5py.File(out) as file:
        assert file.attrs["source"] == str(source) and len(file["time"]) == 150
    h, w = sim_params.video_height, sim_params.video_width
    assert iio.imread(strip).shape[:2] == (3 * h + 2 * 3, 4 * w + 3 * 3)  # 12 frames, rows of 4


def _picture_has_subject(picture: np.ndarray) -> bool:
    """Not one flat colour: something is drawn."""
    return picture.reshape(-1, picture.shape[-1]).std(axis=0).max() > 5.0


@pytest.mark.parametrize("use_mujoco", [False, True])
def test_render_produces_a_file(walk, sim_params, tmp_path, use_mujoco):
    """Stick-figure fallback and MuJoCo (or its fallback where no GL works) both draw."""
    path = tmp_path / "run.h5"
    write_simulation(path, walk, sim_params)
    strip = tmp_path / f"strip-{use_mujoco}.png"
    render_simulation(
        read_trajectory(path),
        strip,
        sim_params,
        width=160,
        height=120,
        strip_frames=3,
        use_mujoco=use_mujoco,
    )
    picture = iio.imread(strip)
    assert picture.shape[0] == 120 and picture.shape[1] >= 3 * 160
    assert _picture_has_subject(picture)


def test_a_failed_run_is_recorded_and_the_stage_finishes(tmp_path, sim_robot, sim_params):
    from pimann.core.params import SimulateRun, load_params
    from pimann.core.rollout_files import RolloutKey, rollout_path
    from pimann.sim.run_list import simulate_runs

    q0 = standing_pose(sim_robot, sim_params)
    plan = stepping_plan(standing_feet(sim_robot, q0), 2, 0.1, single=0.35, double=0.1)
    bad = stepping_trajectory(sim_robot, sim_params, plan, 25.0)
    bad.contacts = None  # footsteps cannot be extracted: the run fails
    rollouts = tmp_path / "rollouts"
    runs = [SimulateRun("w10", seed, "forward", True, False) for seed in (0, 1)]
    for run in runs:
        path = rollout_path(rollouts, RolloutKey(run.model, run.seed, run.scenario, run.steering))
        path.parent.mkdir(parents=True)
        write_trajectory(path, bad)
    params = load_params()
    params = dataclasses.replace(params, simulate=dataclasses.replace(sim_params, runs=runs))
    summary_path = tmp_path / "summary.json"
    record = simulate_runs(rollouts, tmp_path / "sim", summary_path, params)
    assert record["failed_runs"] == ["w10-0-forward-steering", "w10-1-forward-steering"]
    failure = record["runs"]["w10-0-forward-steering"]
    assert failure["success"] is False
    assert failure["failed"].startswith(str(rollouts / "w10" / "0" / "forward-steering.h5"))
    assert "simulate run w10-0-forward-steering" in failure["failed"]
    assert "contacts" in failure["failed"]
    assert json.loads(summary_path.read_text())["failed_runs"] == record["failed_runs"]
    assert (tmp_path / "sim").is_dir() and not list((tmp_path / "sim").iterdir())
