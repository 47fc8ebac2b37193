"""Autoregressive generation and steering: real pinocchio, real generate() code path.

The drift and stop checks use an analytic gait "network": a torch module that maps x to a
consistent y (a stepping gait whose phase is carried in the input's neck joints and whose
step length follows the velocities in the input window), so the outcome is known. The
contact check trains a tiny MANN on features of that gait and rolls it out.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pinocchio as pin
import pytest
import torch
from builders import IDENTITY, LAYOUT, GaitModel, roll
from scipy.spatial.transform import Rotation

from pimann.core.contacts import detect_contacts, foot_kinematics, trajectory_configurations
from pimann.core.errors import PimannError
from pimann.core.params import ModelParams, MotionSegment, StandSegment, load_params
from pimann.core.robot import JOINT_NAMES, STANDING_JOINTS
from pimann.core.rotations import matrix_to_rpy, yaw_of
from pimann.core.trajectory import read_trajectory
from pimann.generate.future_window import interpolation
from pimann.generate.rollout_batch import (
    generate,
    generate_file,
    generate_rollout,
    scenario_steps,
)
from pimann.learn.feature_layout import Normalisation
from pimann.learn.features import clip_features
from pimann.learn.mann import MANN

FORWARD = [MotionSegment(10.0, 0.5, 0.0, 0.0)]


@pytest.fixture(scope="module")
def params():
    return load_params()


def test_scenario_steps_follow_the_segments():
    scenario = [StandSegment(0.5, True), MotionSegment(1.0, 0.5, 0.0, 0.0)]
    steps = scenario_steps(scenario, 50.0)
    assert len(steps) == 75 and (steps[:25] == 0).all() and (steps[25:] == 1).all()


def test_future_window_interpolation_matches_numpy(rng):
    knots = np.array([0.0, 8, 17, 25, 33, 42, 50])  # the paper's output window at 50 Hz
    targets = np.array([-3.0, 9, 18, 26, 34, 43, 51])
    values = rng.normal(size=(len(knots), 3))
    expected = np.stack([np.interp(targets, knots, values[:, c]) for c in range(3)], 1)
    np.testing.assert_allclose(interpolation(targets, knots) @ values, expected, atol=1e-12)


def test_gait_walks_forward_with_alternating_contacts(robot, params):
    rollout = roll(GaitModel(robot), FORWARD, params, False, robot)
    trajectory = rollout.trajectory
    assert len(trajectory) == 501 and trajectory.attrs["steering"] is False
    # the network's commanded 0.5 m/s, realised by leg odometry alone
    speed = (trajectory.base_position[-1, 0] - trajectory.base_position[50, 0]) / 9.0
    assert 0.3 < speed < 0.7
    # leg odometry keeps the support foot's lowest corner on the ground (independent FK)
    heights = foot_kinematics(robot, trajectory_configurations(robot, trajectory)).heights
    np.testing.assert_allclose(heights[1:].min(axis=1), 0.0, atol=1e-9)
    # contacts from the streaming trigger equal the whole-trajectory detection
    np.testing.assert_array_equal(
        trajectory.contacts, detect_contacts(robot, trajectory, params.contacts)
    )
    swings = [np.flatnonzero(np.diff(trajectory.contacts[:, f].astype(int)) == -1) for f in (0, 1)]
    assert min(len(s) for s in swings) >= 8  # ~one lift-off per foot and second
    assert (np.diff(rollout.support) != 0).sum() >= 16


class RecordingGait(GaitModel):
    """The gait model, keeping every input it is given (physical units: identity stats)."""

    def __init__(self, robot):
        super().__init__(robot)
        self.inputs: list[torch.Tensor] = []

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        self.inputs.append(x.detach().clone())
        return super().forward(x)


@pytest.mark.parametrize("start", ["zero", "command"])
def test_start_history_feeds_the_command_or_standing_at_a_start(robot, params, start):
    scenario = [StandSegment(0.5, True), MotionSegment(2.0, 0.4, -0.1, 0.2)]
    model = RecordingGait(robot)
    trajectory = roll(model, scenario, params, False, robot, start_history=start).trajectory
    first = model.inputs[0][0].numpy()  # the first network step, from standing
    linear = first[LAYOUT.x_slices["base_linear_window"]].reshape(-1, 3)
    angular = first[LAYOUT.x_slices["base_angular_window"]].reshape(-1, 3)
    # the base starts at standing yaw 0 with the standing pitch: the command in the base frame
    rotation = Rotation.from_quat(trajectory.base_quaternion_xyzw[25]).as_matrix()
    expected_linear = np.array([0.4, -0.1, 0.0]) @ rotation
    expected_angular = rotation[2] * 0.2
    if start == "zero":
        np.testing.assert_array_equal(linear, 0.0)
        np.testing.assert_array_equal(angular, 0.0)
    else:
        np.testing.assert_allclose(
            linear, np.broadcast_to(expected_linear, linear.shape), atol=1e-6
        )
        np.testing.assert_allclose(
            angular, np.broadcast_to(expected_angular, angular.shape), atol=1e-6
        )
    # a held command from the start: the gait model's speed is the command from the first step
    speed = np.linalg.norm(trajectory.base_position[-1, :2] - trajectory.base_position[25, :2])
    assert (speed > 0.5) if start == "command" else (speed > 0.3)


def test_orientation_integrates_the_angular_velocity(robot, params):
    scenario = [MotionSegment(4.0, 0.3, 0.0, 0.25)]
    trajectory = roll(GaitModel(robot), scenario, params, False, robot).trajectory
    from scipy.spatial.transform import Rotation

    yaw = np.unwrap(yaw_of(Rotation.from_quat(trajectory.base_quaternion_xyzw).as_matrix()))
    # the window's future mean reaches the command within the first second
    rate = np.diff(yaw[100:]) * 50.0
    np.testing.assert_allclose(rate, 0.25, atol=0.01)


def test_steering_cuts_lateral_and_yaw_drift(robot, params):
    biased = GaitModel(robot, bias=(0.02, 0.1))
    drifts = {}
    for steering in (False, True):
        trajectory = roll(biased, FORWARD, params, steering, robot).trajectory
        rpy = matrix_to_rpy(
            np.stack(
                [pin.Quaternion(*q[[3, 0, 1, 2]]).matrix() for q in trajectory.base_quaternion_xyzw]
            )
        )
        drifts[steering] = abs(trajectory.base_position[-1, 1]), abs(rpy[-1, 2])
    (lateral_free, yaw_free), (lateral_steered, yaw_steered) = drifts[False], drifts[True]
    assert yaw_free > 1.0 and lateral_free > 1.0  # the bias makes the free rollout curve
    assert lateral_steered * 5 < lateral_free
    assert yaw_steered * 5 < yaw_free


def test_goal_stop_returns_to_standing(robot, params):
    scenario = [MotionSegment(3.0, 0.5, 0.0, 0.0), StandSegment(3.0, True)]
    model = GaitModel(robot, bias=(0.02, 0.05))
    rollout = roll(model, scenario, params, True, robot)
    trajectory = rollout.trajectory
    walking = int(np.flatnonzero(~rollout.stopped)[0])  # frame 0 is standing still
    stop = walking + int(np.flatnonzero(rollout.stopped[walking:])[0])
    assert 150 < stop < 250  # walked through the motion segment, stopped during 'stand'
    # at the stop the base is within the radius of the goal (the commanded path's end) or
    # past it along the commanded direction (x); one frame earlier the command still held
    offset = trajectory.base_position[stop, :2] - rollout.goals[stop, :2]
    assert np.hypot(*offset) <= params.rollout.goal_radius or offset[0] >= 0
    assert stop == 151 or np.hypot(*offset) <= params.rollout.goal_radius
    # the path runs along x from the start at the commanded 0.5 m/s for 3 s
    np.testing.assert_allclose(rollout.goals[stop, :2], [1.5, 0.0], atol=0.02)
    blend = int(round(params.rollout.stop_blend_s * 50))
    np.testing.assert_array_equal(
        trajectory.joint_positions[stop + blend :],
        np.broadcast_to(STANDING_JOINTS, (len(trajectory) - stop - blend, 26)),
    )
    assert rollout.stopped[stop:].all()
    assert trajectory.base_position[-1, 0] > 1.0  # it did walk
    np.testing.assert_allclose(
        np.diff(trajectory.base_position[stop + blend :], axis=0), 0, atol=1e-12
    )
    assert trajectory.contacts[-1].all()


def test_unreached_goal_stops_after_the_timeout(robot, params):
    scenario = [MotionSegment(1.0, 0.5, 0.0, 0.0), StandSegment(3.0, True)]
    stuck = GaitModel(robot, stride=0.0)  # steps in place: never reaches the goal
    rollout = roll(stuck, scenario, params, True, robot)
    stops = np.flatnonzero(np.diff(rollout.stopped.astype(int)) == 1) + 1
    timeout = int(round(params.rollout.stop_timeout_s * 50))
    assert list(stops) == [51 + timeout]  # 'stand' starts at frame 51
    np.testing.assert_allclose(rollout.goals[-1, :2], [0.5, 0.0], atol=1e-9)  # 1 s x 0.5 m/s
    assert np.abs(rollout.trajectory.base_position[:, 0]).max() < 0.2
    np.testing.assert_array_equal(rollout.trajectory.joint_positions[-1], STANDING_JOINTS)


def test_stand_without_steering_stops_at_once(robot, params):
    scenario = [StandSegment(0.5, True), MotionSegment(2.0, 0.5, 0.0, 0.0), StandSegment(1.0, True)]
    rollout = roll(GaitModel(robot), scenario, params, False, robot)
    assert rollout.stopped[:26].all() and not rollout.stopped[26:126].any()
    assert rollout.stopped[126:].all()
    np.testing.assert_array_equal(
        rollout.trajectory.joint_positions[:26], np.broadcast_to(STANDING_JOINTS, (26, 26))
    )


@pytest.fixture
def one_thread():
    """Tiny batches train far faster on one thread (and do not fight other processes)."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def test_trained_mann_steps_with_switching_contacts(robot, params, one_thread):
    data = roll(GaitModel(robot), FORWARD, params, False, robot).trajectory
    x, y, _ = clip_features(data, LAYOUT)
    stats = Normalisation.fit(x, y)
    xn = torch.tensor(stats.normalise_x(x), dtype=torch.float32)
    yn = torch.tensor(stats.normalise_y(y), dtype=torch.float32)
    torch.manual_seed(0)
    small = ModelParams(2, 8, 2, 64, 2, 0.0, "elu")
    model = MANN(LAYOUT.input_dim, LAYOUT.output_dim, small, seeds=[0])
    optimiser = torch.optim.Adam(model.parameters(), lr=3e-3)
    for _ in range(1500):  # 400 steps (loss 4e-4) gave a model whose rollout diverged
        optimiser.zero_grad()
        loss = torch.mean((model(xn) - yn) ** 2)
        loss.backward()
        optimiser.step()
    assert loss.item() < 0.05
    trajectory = roll(
        model, [MotionSegment(1.0, 0.5, 0.0, 0.0)], params, True, robot, stats=stats
    ).trajectory
    assert len(trajectory) == 51
    assert np.abs(trajectory.joint_positions).max() < np.pi  # in its range, not diverging
    for foot in (0, 1):  # each foot lifts off at least once
        assert not trajectory.contacts[:, foot].all()
    assert trajectory.contacts.any(axis=1).all()  # never both feet in the air
    assert trajectory.base_position[-1, 0] > 0.03  # accelerating from standing


def test_generate_file_writes_atomically_and_names_bad_scenarios(robot, params, tmp_path):
    from pimann.learn.model_files import save_model

    torch.manual_seed(0)
    small = ModelParams(2, 8, 2, 16, 2, 0.0, "elu")
    model = MANN(LAYOUT.input_dim, LAYOUT.output_dim, small, seeds=[3])
    stats = Normalisation(IDENTITY.x_mean, IDENTITY.x_std, IDENTITY.y_mean, IDENTITY.y_std * 0.01)
    meta = {
        "pi_weight": 10.0,
        "seed": 3,
        "variant": "full",
        "params": {"model": dataclasses.asdict(small)},
    }
    save_model(tmp_path / "model", model, LAYOUT, stats, meta)
    short = dataclasses.replace(
        params,
        rollout=dataclasses.replace(
            params.rollout, scenarios={"short": [MotionSegment(0.4, 0.5, 0.0, 0.0)]}
        ),
    )
    out = tmp_path / "out.h5"
    with pytest.raises(PimannError, match="params.yaml.*'nope'"):
        generate_file(tmp_path / "model", "nope", out, True, short)
    assert not out.exists()
    generate_file(tmp_path / "model", "short", out, False, short)
    trajectory = read_trajectory(out)
    assert len(trajectory) == 21 and trajectory.contacts.shape == (21, 2)
    assert trajectory.attrs["steering"] is False or trajectory.attrs["steering"] == 0
    assert trajectory.attrs["pi_weight"] == 10.0 and trajectory.attrs["seed"] == 3
    assert "short" in trajectory.source and trajectory.joint_velocities.shape == (21, 26)
    again = generate(
        model.eval(),
        LAYOUT,
        stats,
        [MotionSegment(0.4, 0.5, 0.0, 0.0)],
        short.rollout,
        False,
        robot,
        contact_params=params.contacts,
    )
    np.testing.assert_allclose(again.joint_positions, trajectory.joint_positions, atol=1e-6)


def test_ground_projected_baseline_keeps_yaw_only(robot, params):
    layout = dataclasses.replace(LAYOUT, variant="ground_projected")
    trajectory = roll(
        GaitModel(robot), [MotionSegment(2.0, 0.4, 0.0, 0.3)], params, True, robot, layout=layout
    ).trajectory
    quaternions = trajectory.base_quaternion_xyzw
    np.testing.assert_allclose(quaternions[:, :2], 0.0, atol=1e-12)  # rotations about z only
    yaw = 2 * np.arctan2(quaternions[:, 2], quaternions[:, 3])
    assert 0.3 < yaw[-1] < 0.7  # turned at about the commanded 0.3 rad/s for 2 s


def test_a_rollout_starts_and_stops_in_the_given_standing_pose(robot, params):
    from pimann.learn.standing import StandingPose

    nominal = StandingPose.nominal()
    joints = nominal.joints.copy()
    joints[JOINT_NAMES.index("l_shoulder_yaw")] += 0.5  # as the data's people stand
    joints[JOINT_NAMES.index("r_knee")] -= 0.1
    standing = StandingPose(joints, np.array([0.0, 0.05]), "test")
    scenario = [StandSegment(0.2, True), MotionSegment(1.0, 0.4, 0.0, 0.0), StandSegment(1.0, True)]
    rollout = generate_rollout(
        GaitModel(robot),
        LAYOUT,
        IDENTITY,
        scenario,
        params.rollout,
        False,
        robot,
        contact_params=params.contacts,
        standing=standing,
    )
    trajectory = rollout.trajectory
    np.testing.assert_array_equal(trajectory.joint_positions[0], joints)
    np.testing.assert_array_equal(trajectory.joint_positions[-1], joints)  # stopped: back in it
    rpy = matrix_to_rpy(Rotation.from_quat(trajectory.base_quaternion_xyzw[[0, -1]]).as_matrix())
    np.testing.assert_allclose(rpy[:, :2], [[0.0, 0.05], [0.0, 0.05]], atol=1e-9)
    # the lowest sole corner on the floor from the first frame (independent FK)
    heights = foot_kinematics(robot, trajectory_configurations(robot, trajectory)).heights
    assert abs(heights[0].min()) < 1e-9
