"""The standing pose of generation (pimann.learn.standing): the medoid of the data's standing
frames."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pimann.core.robot import STANDING_JOINTS
from pimann.core.trajectory import Trajectory
from pimann.learn.standing import MIN_STANDING_FRAMES, StandingPose, data_standing

RATE = 50.0


def clip(frames: int, speed: float, joints: np.ndarray, pitch: float, noise: float = 0.0):
    """A clip moving forward at `speed` with constant joints (+ seeded noise) and base pitch."""
    rng = np.random.default_rng(0)
    time = np.arange(frames) / RATE
    position = np.stack([speed * time, np.zeros(frames), np.full(frames, 0.7)], axis=1)
    quaternion = np.tile(Rotation.from_euler("y", pitch).as_quat(), (frames, 1))
    joint_positions = joints + noise * rng.standard_normal((frames, len(joints)))
    return Trajectory(time, position, quaternion, joint_positions, source="s", rate_hz=RATE)


def test_the_medoid_of_the_standing_frames_is_one_real_frame():
    standing_joints = STANDING_JOINTS + 0.3
    clips = [
        clip(300, 0.0, standing_joints, 0.04, noise=0.01),  # standing
        clip(300, 0.9, STANDING_JOINTS - 0.5, -0.2),  # walking: never counted
    ]
    pose = data_standing(clips)
    assert pose.origin.startswith("data")
    # one of the standing clip's own frames, close to its median
    assert np.min(np.abs(clips[0].joint_positions - pose.joints).sum(axis=1)) == 0.0
    np.testing.assert_allclose(pose.joints, standing_joints, atol=0.04)
    np.testing.assert_allclose(pose.roll_pitch, [0.0, 0.04], atol=1e-9)
    assert StandingPose.from_json(pose.to_json()).joints.tolist() == pose.joints.tolist()


def test_without_standing_frames_the_nominal_pose_is_kept():
    pose = data_standing([clip(300, 0.9, STANDING_JOINTS - 0.5, 0.0)])
    assert pose.origin == "robot"
    np.testing.assert_array_equal(pose.joints, STANDING_JOINTS)
    assert (
        data_standing([clip(MIN_STANDING_FRAMES - 1, 0.0, STANDING_JOINTS, 0.0)]).origin == "robot"
    )
    assert StandingPose.from_json(None).origin == "robot"


def test_a_recorded_pose_of_other_sizes_or_nan_is_refused():
    good = StandingPose.nominal().to_json()
    for change in (
        {"joints": [0.1, 0.2]},
        {"roll_pitch": [0.0]},
        {"roll_pitch": [float("nan"), 0.0]},
    ):
        with pytest.raises(ValueError, match="standing pose"):
            StandingPose.from_json({**good, **change})
    with pytest.raises(KeyError):
        StandingPose.from_json({"joints": good["joints"]})
