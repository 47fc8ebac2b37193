"""The paper's metrics on trajectories built so that the right answer is known."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pinocchio as pin
import pytest
from builders import CONTACT_PARAMS, EVALUATE_PARAMS, random_configuration

from pimann.core.contacts import FEET, foot_kinematics, trajectory_configurations
from pimann.core.errors import PimannError
from pimann.core.params import EvaluateParams
from pimann.core.robot import JOINT_NAMES, SOLE_HALF_LENGTH
from pimann.core.trajectory import Trajectory, write_collection, write_trajectory
from pimann.evaluate.metrics import (
    aggregate,
    in_representation,
    metrics_for_file,
    trajectory_metrics,
    trajectory_time_series,
)
from pimann.evaluate.sliding import manifold_velocities

PARAMS = EVALUATE_PARAMS
CONTACTS = CONTACT_PARAMS
RATE = 50.0
FRAMES = 150
SQRT3 = np.sqrt(3.0)


def _joint(name):
    return JOINT_NAMES.index(name)


def stance_trajectory(
    robot, slide=0.0, spin=0.0, frames=FRAMES, rate=RATE, joint_velocities=False, tip=0.0
):
    """Left foot on the floor (sliding along its x at `slide` m/s, turning about its z at
    `spin` rad/s, tipped `tip` rad onto its heel), the right leg swinging high, the body
    moving: the base comes from the sole by inverse placement, base = oMsole * (baseMsole)^-1."""
    t = np.arange(frames) / rate
    _, _, standing = robot.split_configuration(robot.standing_configuration())
    phase = 2 * np.pi * 1.0 * t
    offsets = np.zeros((frames, len(JOINT_NAMES)))
    d_offsets = np.zeros_like(offsets)
    moves = {  # joint: (mean, amplitude) of a 1 Hz sine
        "l_hip_pitch": (0.0, 0.15),
        "l_knee": (-0.2, 0.15),
        "l_ankle_pitch": (0.0, 0.1),
        "l_hip_roll": (0.0, 0.05),
        "r_hip_pitch": (-0.5, 0.2),
        "r_knee": (-0.8, 0.2),
        "torso_pitch": (0.0, 0.1),
        "l_shoulder_pitch": (0.0, 0.3),
    }
    for name, (mean, amplitude) in moves.items():
        offsets[:, _joint(name)] = mean + amplitude * np.sin(phase)
        d_offsets[:, _joint(name)] = amplitude * 2 * np.pi * np.cos(phase)
    joints = standing + offsets
    sole_rotation0 = pin.utils.rotate("z", 0.4)
    base_positions, quaternions = [], []
    identity = np.array([0.0, 0.0, 0.0, 1.0])
    left = robot.frame_id(FEET[0])
    for k in range(frames):
        q_local = robot.configuration(np.zeros(3), identity, joints[k])
        base_M_sole = robot.frame_placement(q_local, FEET[0])
        world_M_sole = pin.SE3(
            sole_rotation0 @ pin.utils.rotate("z", spin * t[k]) @ pin.utils.rotate("y", -tip),
            np.array([0.3, -0.2, SOLE_HALF_LENGTH * np.sin(tip)])
            + sole_rotation0[:, 0] * slide * t[k],
        )  # tipped: the heel's corners on the floor, the origin above it
        world_M_base = world_M_sole * base_M_sole.inverse()
        base_positions.append(world_M_base.translation)
        quaternions.append(pin.Quaternion(world_M_base.rotation).coeffs())
    assert left >= 0
    return Trajectory(
        time=t,
        base_position=np.array(base_positions),
        base_quaternion_xyzw=np.array(quaternions),
        joint_positions=joints,
        source="stance",
        rate_hz=rate,
        joint_velocities=d_offsets if joint_velocities else None,
    )


def line_trajectory(robot, heading=0.5, distance=1.5, lateral=0.0, turn=0.0, frames=100):
    """The standing robot translated along its heading (plus a lateral offset and a turn)."""
    q = robot.standing_configuration()
    _, quaternion, joints = robot.split_configuration(q)
    s = np.linspace(0.0, 1.0, frames)
    forward = np.array([np.cos(heading), np.sin(heading), 0.0])
    left = np.array([-np.sin(heading), np.cos(heading), 0.0])
    positions = q[:3] + s[:, None] * (distance * forward + lateral * left)
    start = pin.Quaternion(quaternion).matrix()
    quaternions = [
        pin.Quaternion(pin.utils.rotate("z", heading + turn * sk) @ start).coeffs() for sk in s
    ]
    return Trajectory(
        time=s * 10.0,
        base_position=positions,
        base_quaternion_xyzw=np.array(quaternions),
        joint_positions=np.tile(joints, (frames, 1)),
        source="line",
        rate_hz=(frames - 1) / 10.0,
    )


def test_still_support_foot_has_zero_rmse(robot):
    metrics = trajectory_metrics(stance_trajectory(robot), robot, PARAMS, CONTACTS)
    assert metrics["joint_velocity_gap_rms"] is None  # no joint velocities in the file
    assert metrics["contacts_source"] == "detected"
    # the left foot is in contact throughout, the right one never
    assert metrics["contact_fraction_left"] == 1.0 and metrics["contact_fraction_right"] == 0.0
    # finite-difference error only (~1e-4 m/s a frame at 50 Hz; 1 cm/s of sliding sums to 0.87)
    assert metrics["support_rmse_linear_left"] < 0.02
    assert metrics["support_rmse_angular_left"] < 0.02
    assert metrics["support_rmse_linear_mean_per_contact_frame"] < 2e-4
    assert metrics["support_rmse_linear_right"] == 0.0
    assert metrics["skating_ratio"] == 0.0
    assert metrics["contact_foot_speed_mean"] < 1e-4
    # the body did move: the base is not still
    series = trajectory_time_series(stance_trajectory(robot), robot, PARAMS, CONTACTS)
    assert np.ptp(series["base_x"]) > 0.03 and series["right_foot_height"].min() > 0.05


def test_rmse_grows_with_injected_sliding(robot):
    """The position level reads a slide of the whole robot; the velocity level, whose base
    keeps the lowest foot still (the authors' code), cannot: the joints do not slide the foot."""
    speeds = [0.0, 0.01, 0.05, 0.2]
    totals = []
    for speed in speeds:
        metrics = trajectory_metrics(stance_trajectory(robot, slide=speed), robot, PARAMS, CONTACTS)
        # a rigid slide at `speed` along the sole's x: RMS over 3 components = speed / sqrt(3)
        expected = FRAMES * speed / SQRT3
        assert metrics["support_rmse_linear_position_left"] == pytest.approx(expected, abs=0.02)
        assert metrics["support_rmse_linear_position_total"] == pytest.approx(
            expected / 2, abs=0.01
        )
        assert metrics["support_rmse_angular_position_left"] < 0.02
        assert metrics["contact_foot_speed_mean_position"] == pytest.approx(speed, abs=1e-4)
        assert metrics["support_rmse_linear_left"] < 1e-9  # the support sole, held still
        totals.append(metrics["support_rmse_linear_position_total"])
    assert np.all(np.diff(totals) > 0)


def test_a_sole_on_its_heel_is_down_by_the_corner_rule_only(robot):
    """The left sole tipped 0.4 rad onto its heel, sliding: its lowest corner is on the floor
    (the evaluate rule: down), its origin 4.6 cm above it (the authors' rule: not down)."""
    metrics = trajectory_metrics(
        stance_trajectory(robot, slide=0.05, tip=0.4), robot, PARAMS, CONTACTS
    )
    series = trajectory_time_series(stance_trajectory(robot, tip=0.4), robot, PARAMS, CONTACTS)
    assert series["left_foot_height"].abs().max() < 1e-9
    assert metrics["contact_fraction_left"] == 1.0
    expected = FRAMES * 0.05 / SQRT3
    assert metrics["support_rmse_linear_position_left"] == pytest.approx(expected, abs=0.02)
    assert metrics["support_rmse_linear_position_origin_contacts_left"] == 0.0
    flat = trajectory_metrics(stance_trajectory(robot, slide=0.05), robot, PARAMS, CONTACTS)
    assert flat["support_rmse_linear_position_origin_contacts_left"] == pytest.approx(
        flat["support_rmse_linear_position_left"], rel=1e-12
    )  # a flat sole: both rules agree


def test_turning_foot_counts_in_angular_rmse(robot):
    spin = 0.5  # rad/s about the sole's z: the sole origin stays put
    metrics = trajectory_metrics(stance_trajectory(robot, spin=spin), robot, PARAMS, CONTACTS)
    expected = FRAMES * spin / SQRT3
    assert metrics["support_rmse_angular_position_left"] == pytest.approx(expected, rel=1e-3)
    assert metrics["support_rmse_linear_position_left"] < 0.05  # vs 43 rad/s-frames of turning
    assert metrics["support_rmse_angular_left"] < 1e-9  # velocity level: the support sole held


def test_world_representation_is_the_velocity_at_the_origin(robot):
    """The authors' inertial-fixed sole velocity: a sole turning in place at p reads -w x p."""
    spin = 0.5
    world = EvaluateParams(**{**vars(PARAMS), "foot_velocity_frame": "world"})
    metrics = trajectory_metrics(stance_trajectory(robot, spin=spin), robot, world, CONTACTS)
    lever = np.hypot(0.3, 0.2)  # the sole stands at (0.3, -0.2, 0)
    expected = FRAMES * spin * lever / SQRT3
    assert metrics["support_rmse_linear_position_left"] == pytest.approx(expected, rel=2e-3)
    assert metrics["support_rmse_angular_position_left"] == pytest.approx(
        FRAMES * spin / SQRT3, rel=1e-3
    )


def test_world_columns_whatever_the_params(robot):
    """The authors' representation is reported beside ours: a sole turning in place at p."""
    spin = 0.5
    metrics = trajectory_metrics(stance_trajectory(robot, spin=spin), robot, PARAMS, CONTACTS)
    lever = np.hypot(0.3, 0.2)
    # local_world_aligned: the origin is still
    assert metrics["support_rmse_linear_position_left"] < 0.05
    expected = FRAMES * spin * lever / SQRT3
    assert metrics["support_rmse_linear_position_world_left"] == pytest.approx(expected, rel=2e-3)
    assert metrics["support_rmse_linear_world_left"] < 1e-9  # velocity level: held still


def test_world_representation_matches_pinocchio(robot, rng):
    """v - omega x p of the LOCAL_WORLD_ALIGNED velocity is pinocchio's WORLD frame velocity."""
    model, data = robot.model, robot.model.createData()
    for _ in range(3):
        q, v = random_configuration(robot, rng), rng.normal(size=model.nv)
        pin.forwardKinematics(model, data, q, v)
        for frame in FEET:
            frame_id = robot.frame_id(frame)
            position = pin.updateFramePlacement(model, data, frame_id).translation
            local = pin.getFrameVelocity(model, data, frame_id, pin.LOCAL_WORLD_ALIGNED).vector
            world = pin.getFrameVelocity(model, data, frame_id, pin.WORLD).vector
            np.testing.assert_allclose(
                in_representation(local, position, "world"), world, atol=1e-10
            )
            assert in_representation(local, position, "local_world_aligned") is local


def _still_feet_joint_velocities(robot, trajectory) -> np.ndarray:
    """Leg joint velocities that cancel the base's motion at both soles (J_legs qd = -J_base v)."""
    model, data = robot.model, robot.model.createData()
    q = trajectory_configurations(robot, trajectory)
    v = manifold_velocities(model, q, trajectory.time)
    out = np.zeros((len(q), len(JOINT_NAMES)))
    for k in range(len(q)):
        pin.computeJointJacobians(model, data, q[k])
        pin.updateFramePlacements(model, data)
        for frame, prefix in zip(FEET, ("l_", "r_"), strict=True):
            jacobian = pin.getFrameJacobian(
                model, data, robot.frame_id(frame), pin.LOCAL_WORLD_ALIGNED
            )
            legs = [
                j
                for j, name in enumerate(JOINT_NAMES)
                if name.startswith(prefix) and any(p in name for p in ("hip", "knee", "ankle"))
            ]
            columns = jacobian[:, robot.v_index[legs]]
            out[k, legs] = np.linalg.lstsq(columns, -jacobian[:, :6] @ v[k, :6], rcond=None)[0]
    return out


def test_position_level_ignores_the_predicted_joint_velocities(robot):
    """The standing robot slides along its heading at 0.15 m/s while the file's joint
    velocities claim still feet: the velocity level (what the joint velocities make the feet
    do) reads ~0, the position level (the feet a robot would track) reads the known speed."""
    trajectory = line_trajectory(robot, distance=1.5, frames=100)  # 1.5 m in 10 s
    trajectory.joint_velocities = _still_feet_joint_velocities(robot, trajectory)
    metrics = trajectory_metrics(trajectory, robot, PARAMS, CONTACTS)
    assert metrics["contact_fraction_left"] == 1.0 and metrics["contact_fraction_right"] == 1.0
    assert metrics["support_rmse_linear_total"] < 1e-6
    assert metrics["support_rmse_angular_total"] < 1e-6
    expected = 100 * 0.15 / SQRT3
    assert metrics["support_rmse_linear_position_total"] == pytest.approx(expected, rel=1e-6)
    assert metrics["support_rmse_angular_position_total"] < 1e-6
    assert metrics["contact_foot_speed_mean_position"] == pytest.approx(0.15, rel=1e-6)
    assert metrics["contact_foot_speed_mean"] < 1e-6


def test_levels_agree_when_the_base_keeps_the_foot_still(robot):
    """With the joints' true derivatives in the file and a base that holds the left sole still
    (the velocity level's construction exactly), both levels read the same sole velocities, the
    swinging right sole's too; slide the whole robot and only the position level moves; zero
    file velocities and only the velocity level does."""
    still = stance_trajectory(robot, joint_velocities=True)
    series = trajectory_time_series(still, robot, PARAMS, CONTACTS)
    for side in ("left", "right"):
        np.testing.assert_allclose(
            series[f"{side}_rms_linear"], series[f"{side}_rms_linear_position"], atol=5e-3
        )
    assert series["right_rms_linear"].max() > 0.1  # the right sole swings
    metrics = trajectory_metrics(still, robot, PARAMS, CONTACTS)
    assert metrics["joint_velocity_gap_rms"] < 0.01  # finite-difference error only

    slid = trajectory_metrics(
        stance_trajectory(robot, slide=0.05, joint_velocities=True), robot, PARAMS, CONTACTS
    )
    assert slid["support_rmse_linear_left"] == pytest.approx(0.0, abs=1e-9)
    expected = FRAMES * 0.05 / SQRT3
    assert slid["support_rmse_linear_position_left"] == pytest.approx(expected, abs=2e-2)

    true_velocities = still.joint_velocities.copy()
    still.joint_velocities = np.zeros_like(true_velocities)
    wrong = trajectory_time_series(still, robot, PARAMS, CONTACTS)
    assert wrong[["left_rms_linear", "right_rms_linear"]].to_numpy().max() == 0.0
    np.testing.assert_array_equal(
        wrong["right_rms_linear_position"], series["right_rms_linear_position"]
    )
    gap = trajectory_metrics(still, robot, PARAMS, CONTACTS)["joint_velocity_gap_rms"]
    assert gap == pytest.approx(np.sqrt(np.mean(true_velocities**2)), rel=0.02)


def test_still_foot_residual_is_second_order_in_the_frame_period(robot):
    """What the position level leaves for a still foot is finite-difference error: doubling
    the rate quarters it."""
    residuals = []
    for rate in (50.0, 100.0):
        trajectory = stance_trajectory(robot, frames=int(2 * rate), rate=rate)
        series = trajectory_time_series(trajectory, robot, PARAMS, CONTACTS)
        residuals.append(series["left_rms_linear_position"].max())
    assert residuals[1] < 0.3 * residuals[0]


def test_file_joint_velocities_and_contacts_are_used(robot):
    trajectory = stance_trajectory(robot, joint_velocities=True)
    trajectory.contacts = np.ones((FRAMES, 2), dtype=bool)  # the file: both feet down
    metrics = trajectory_metrics(trajectory, robot, PARAMS, CONTACTS)
    assert metrics["joint_velocities_source"] == "file"
    assert metrics["contacts_source"] == "file"
    series = trajectory_time_series(trajectory, robot, PARAMS, CONTACTS)
    right = metrics["support_rmse_linear_right"]
    assert right == pytest.approx(series["right_rms_linear"].sum(), rel=1e-12)
    assert right > 10.0  # the swinging sole counts as down
    # the velocity level is linear in the file's joint velocities
    trajectory.joint_velocities = 2.0 * trajectory.joint_velocities
    doubled = trajectory_metrics(trajectory, robot, PARAMS, CONTACTS)
    assert doubled["support_rmse_linear_right"] == pytest.approx(2.0 * right, rel=1e-9)
    trajectory.contacts = np.zeros((FRAMES, 2), dtype=bool)  # nothing in contact: nothing counts
    metrics = trajectory_metrics(trajectory, robot, PARAMS, CONTACTS)
    assert metrics["contacts_source"] == "file"
    assert metrics["support_rmse_linear_total"] == 0.0
    assert metrics["contact_foot_speed_mean"] is None


def test_skating_ratio_threshold(robot):
    # 2.5 cm per frame at 20 fps is 0.5 m/s
    below = trajectory_metrics(stance_trajectory(robot, slide=0.4), robot, PARAMS, CONTACTS)
    above = trajectory_metrics(stance_trajectory(robot, slide=0.6), robot, PARAMS, CONTACTS)
    assert below["skating_ratio"] == 0.0
    assert above["skating_ratio"] == pytest.approx(1.0)  # the low left foot skates throughout


def test_frame_velocity_matches_differences_of_the_sole_placement(robot, rng):
    """getFrameVelocity (LOCAL_WORLD_ALIGNED) with v from manifold differences of q agrees with
    differences of the sole placement itself (log6 of successive placements)."""
    rate, frames = 1000.0, 41
    t = np.arange(frames) / rate
    q0 = random_configuration(robot, rng)
    direction = rng.normal(size=robot.model.nv)
    configurations = np.array([pin.integrate(robot.model, q0, direction * np.sin(tk)) for tk in t])
    velocities = manifold_velocities(robot.model, configurations, t)
    feet = foot_kinematics(robot, configurations, velocities)
    k = frames // 2
    for f, frame in enumerate(FEET):
        before, now, after = (
            robot.frame_placement(configurations[j], frame) for j in (k - 1, k, k + 1)
        )
        local = (
            pin.log6(now.inverse() * after).vector - pin.log6(now.inverse() * before).vector
        ) * (rate / 2)
        world = np.r_[now.rotation @ local[:3], now.rotation @ local[3:]]
        np.testing.assert_allclose(feet.velocities[k, f], world, atol=1e-5 * np.abs(world).max())
        # and J(q) v with the Jacobian in the same representation
        jacobian = robot.frame_jacobian(configurations[k], frame, pin.LOCAL_WORLD_ALIGNED)
        v_study = velocities[k][robot.velocity_order]
        np.testing.assert_allclose(feet.velocities[k, f], jacobian @ v_study, atol=1e-10)


def test_manifold_velocities_of_an_uneven_clock(robot, rng):
    """Central differences on an uneven time grid recover a constant velocity exactly."""
    q0 = random_configuration(robot, rng)
    v = np.zeros(robot.model.nv)
    v[6:] = rng.normal(size=robot.model.nv - 6)
    v[:6] = rng.normal(size=6)
    t = np.cumsum(rng.uniform(0.01, 0.03, size=20))
    configurations = np.array([pin.integrate(robot.model, q0, v * tk) for tk in t])
    np.testing.assert_allclose(
        manifold_velocities(robot.model, configurations, t), np.tile(v, (20, 1)), atol=1e-9
    )


def test_drift_of_a_straight_line_is_zero(robot):
    metrics = trajectory_metrics(line_trajectory(robot), robot, PARAMS, CONTACTS)
    assert metrics["drift_x"] == pytest.approx(1.5)
    assert metrics["drift_y"] == pytest.approx(0.0, abs=1e-12)
    assert metrics["drift_yaw"] == pytest.approx(0.0, abs=1e-12)
    assert metrics["touchdowns"] == 0 and metrics["walks"] is False  # 1.5 m, but a glide


def test_walking_takes_the_distance_on_steps(robot):
    """walks: forward travel >= walk_distance (1 m) with at least two touchdowns."""

    def stepping(distance, steps):
        trajectory = line_trajectory(robot, distance=distance)
        contacts = np.ones((len(trajectory.time), 2), dtype=bool)
        for k in range(steps):  # each step: one foot up for 10 frames, then down again
            contacts[10 + 20 * k : 20 + 20 * k, k % 2] = False
        return trajectory_metrics(
            dataclasses.replace(trajectory, contacts=contacts), robot, PARAMS, CONTACTS
        )

    assert stepping(1.5, 2)["touchdowns"] == 2 and stepping(1.5, 2)["walks"] is True
    assert stepping(1.5, 1)["walks"] is False
    assert stepping(0.5, 4)["walks"] is False


def test_drift_of_a_known_offset_and_turn(robot):
    trajectory = line_trajectory(robot, heading=2.8, lateral=-0.3, turn=4.0)  # past +-pi
    metrics = trajectory_metrics(trajectory, robot, PARAMS, CONTACTS)
    assert metrics["drift_y"] == pytest.approx(-0.3)
    assert metrics["drift_yaw"] == pytest.approx(4.0)  # unwrapped
    assert metrics["drift_roll"] == pytest.approx(0.0, abs=1e-9)
    series = trajectory_time_series(trajectory, robot, PARAMS, CONTACTS)
    np.testing.assert_allclose(series["base_y"], np.linspace(0, -0.3, len(series)), atol=1e-12)
    assert series["base_yaw"].is_monotonic_increasing


def test_time_series_columns(robot):
    series = trajectory_time_series(stance_trajectory(robot), robot, PARAMS, CONTACTS)
    assert len(series) == FRAMES and series["time"].iloc[0] == 0.0
    for column in ["base_x", "base_yaw", "left_foot_height", "right_sole_pitch", "left_contact"]:
        assert column in series
    assert series["left_contact"].all() and not series["right_contact"].any()


def test_aggregate_over_seeds():
    runs = {
        seed: {"rmse": value, "walks": value > 2, "source": "x", "maybe": None if seed == 0 else 1}
        for seed, value in enumerate([1.0, 2.0, 3.0, 4.0, 10.0])
    }
    summary = aggregate(runs)
    assert "source" not in summary
    assert summary["rmse"]["median"] == 3.0 and summary["rmse"]["mean"] == 4.0
    assert summary["rmse"]["iqr"] == pytest.approx(
        np.subtract(*np.percentile([1, 2, 3, 4, 10], [75, 25]))
    )
    assert summary["rmse"]["min"] == 1.0 and summary["rmse"]["max"] == 10.0
    assert summary["walks"]["mean"] == pytest.approx(0.6)
    assert summary["maybe"]["n"] == 4  # None in the first run: the other four
    assert aggregate(list(runs.values())) == summary


def test_metrics_for_file_and_collection(robot, tmp_path):
    single = tmp_path / "one.h5"
    write_trajectory(single, line_trajectory(robot))
    metrics = metrics_for_file(single, robot, PARAMS, CONTACTS)
    json.dumps(metrics)  # serialisable
    assert metrics["drift_x"] == pytest.approx(1.5)
    collection = tmp_path / "many.h5"
    write_collection(collection, [("a", line_trajectory(robot)), ("b", stance_trajectory(robot))])
    both = metrics_for_file(collection, robot, PARAMS, CONTACTS)
    assert set(both) == {"a", "b"} and both["b"]["contact_fraction_left"] == 1.0
    with pytest.raises(PimannError, match="not found"):
        metrics_for_file(tmp_path / "missing.h5", robot, PARAMS, CONTACTS)


def test_errors_inside_a_file_name_the_file_and_the_group(robot, tmp_path):
    bad = line_trajectory(robot)
    bad.time[5] = bad.time[4]  # raised deep in the metrics, about the trajectory
    single = tmp_path / "one.h5"
    write_trajectory(single, bad)
    with pytest.raises(PimannError, match=rf"^{single} \(frame 5\): .*not strictly increasing"):
        metrics_for_file(single, robot, PARAMS, CONTACTS)
    collection = tmp_path / "many.h5"
    write_collection(collection, [("good", line_trajectory(robot)), ("bad", bad)])
    with pytest.raises(PimannError, match=rf"^{collection} \(frame 5\): group 'bad': "):
        metrics_for_file(collection, robot, PARAMS, CONTACTS)


def test_about_names_the_outer_file_and_keeps_the_frame():
    from pimann.core.errors import about

    with pytest.raises(PimannError) as caught, about("run.h5", "simulate run x"):
        raise PimannError(None, "DCM/ZMP plan not solved", frame=3)
    assert str(caught.value) == "run.h5 (frame 3): simulate run x: DCM/ZMP plan not solved"
    with pytest.raises(PimannError) as caught, about("outer.h5"):
        raise PimannError("inner.bvh", "truncated")
    assert str(caught.value) == "outer.h5: truncated [inner.bvh]"


def test_bad_time_is_named(robot):
    trajectory = line_trajectory(robot)
    trajectory.time[5] = trajectory.time[4]
    with pytest.raises(PimannError, match=r"frame 5.*not strictly increasing"):
        trajectory_metrics(trajectory, robot, PARAMS, CONTACTS)


def test_configurations_match_robot_configuration(robot):
    trajectory = line_trajectory(robot, frames=3)
    q = trajectory_configurations(robot, trajectory)
    expected = robot.configuration(
        trajectory.base_position[1],
        trajectory.base_quaternion_xyzw[1],
        trajectory.joint_positions[1],
    )
    np.testing.assert_allclose(q[1], expected)


def _split(metrics, name):
    return metrics[f"support_rmse_linear_position_{name}_total"]


def test_foot_split_of_a_single_support_is_the_lower_foot(robot):
    metrics = trajectory_metrics(stance_trajectory(robot, slide=0.05), robot, PARAMS, CONTACTS)
    assert _split(metrics, "other_foot") == 0.0  # the right leg swings high
    assert _split(metrics, "lower_foot") == pytest.approx(
        metrics["support_rmse_linear_position_total"], rel=1e-12
    )
    assert _split(metrics, "lower_foot") == pytest.approx(FRAMES * 0.05 / SQRT3 / 2, abs=0.01)


@pytest.mark.parametrize(("lateral", "rise"), [(0.0, 0.0), (0.4, 0.0), (0.0, 0.015)])
def test_foot_split_of_a_gliding_or_rising_double_support(robot, lateral, rise):
    """Both feet down, the robot moved rigidly: a glide of `distance` (and `lateral`) over
    10 s is horizontal for both feet, a rise of 1.5 cm (under the contact rule's 2 cm) vertical."""
    distance = 0.0 if rise else 1.5
    trajectory = line_trajectory(robot, distance=distance, lateral=lateral)
    frames = len(trajectory)
    trajectory.base_position[:, 2] += np.linspace(0.0, rise, frames)
    metrics = trajectory_metrics(trajectory, robot, PARAMS, CONTACTS)
    assert metrics["contact_fraction_left"] == metrics["contact_fraction_right"] == 1.0
    speed = np.hypot(distance, lateral) / 10.0
    per_foot = frames * np.hypot(speed, rise / 10.0) / SQRT3  # each foot, every frame
    lower, other = _split(metrics, "lower_foot"), _split(metrics, "other_foot")
    # the lower foot of each frame is one foot, the other the other: half of each foot's sum
    assert lower + other == pytest.approx(metrics["support_rmse_linear_position_total"], 1e-12)
    assert lower + other == pytest.approx(per_foot, rel=1e-6)
    assert other == pytest.approx(per_foot / 2, rel=1e-6)
    horizontal, vertical = (_split(metrics, f"other_foot_{p}") for p in ("horizontal", "vertical"))
    assert horizontal == pytest.approx(frames * speed / SQRT3 / 2, rel=1e-6, abs=1e-9)
    assert vertical == pytest.approx(frames * rise / 10.0 / SQRT3 / 2, rel=1e-6, abs=1e-9)
