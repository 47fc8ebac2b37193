"""Contact detection: Schmitt trigger timing, hysteresis, and the sole corners' heights."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from builders import CONTACT_PARAMS

from pimann.core.contacts import (
    FEET,
    SchmittTrigger,
    contacts_from_heights,
    detect_contacts,
    foot_kinematics,
    lowest_corner_heights,
    trajectory_configurations,
)
from pimann.core.errors import PimannError
from pimann.core.params import ContactParams
from pimann.core.robot import SOLE_CORNERS
from pimann.core.trajectory import Trajectory

PARAMS = CONTACT_PARAMS
DT = 0.02  # 50 Hz


def test_switching_times_of_a_synthetic_signal():
    heights = np.zeros(60)
    heights[10:30] = 0.05  # lift-off at frame 10: condition holds at 10, 11, 12 -> off at 12
    heights[40] = 0.05  # one-frame glitch: no switch
    heights[45:47] = 0.05  # two frames (0.02 s held): no switch
    heights[50:] = 0.05  # off at 52
    expected = np.ones(60, dtype=bool)
    expected[12:32] = False  # back down at 30 -> on again at 32
    expected[52:] = False
    np.testing.assert_array_equal(contacts_from_heights(heights, DT, PARAMS), expected)


def test_delay_scales_with_the_rate():
    heights = np.r_[np.zeros(5), np.full(20, 0.1)]
    contacts = contacts_from_heights(heights, 0.01, PARAMS)  # 100 Hz: 0.04 s = 4 steps
    assert np.flatnonzero(~contacts)[0] == 5 + 4
    immediate = ContactParams(**{**vars(PARAMS), "switch_time": 0.0})
    assert np.flatnonzero(~contacts_from_heights(heights, 0.01, immediate))[0] == 5


def test_hysteresis_band_keeps_the_state():
    params = ContactParams(**{**vars(PARAMS), "on_height": 0.01, "off_height": 0.03})
    # 0.02 lies in the band: it neither switches a contact off nor a swing foot on
    heights = np.r_[np.zeros(3), np.full(5, 0.02), np.full(5, 0.05), np.full(5, 0.02)]
    contacts = contacts_from_heights(heights, DT, params)
    np.testing.assert_array_equal(contacts[:8], True)
    assert not contacts[-1]
    np.testing.assert_array_equal(contacts[8:10], True)  # still in contact during the delay


def test_streaming_matches_batch_and_feet_are_independent(rng):
    heights = np.abs(np.cumsum(rng.normal(0, 0.01, size=(300, 2)), axis=0))
    batch = contacts_from_heights(heights, DT, PARAMS, initial=True)
    for foot in range(2):
        trigger = SchmittTrigger.from_params(PARAMS, DT, initial=True)
        streamed = [trigger.update(h) for h in heights[:, foot]]
        assert all(isinstance(s, bool) for s in streamed)
        np.testing.assert_array_equal(streamed, batch[:, foot])
    assert batch.any() and not batch.all()  # the signal crosses the threshold both ways


def test_initial_state_from_first_sample_or_given():
    assert contacts_from_heights(np.full(3, 0.1), DT, PARAMS)[0] == False  # noqa: E712
    assert contacts_from_heights(np.full(3, 0.1), DT, PARAMS, initial=True)[:2].all()


def test_bad_trigger_settings_are_rejected():
    with pytest.raises(PimannError, match="off height"):
        SchmittTrigger(0.03, 0.02, 0.04, DT)
    with pytest.raises(PimannError, match="period"):
        SchmittTrigger(0.02, 0.02, 0.04, 0.0)
    with pytest.raises(PimannError, match="NaN"):
        contacts_from_heights(np.array([0.0, np.nan]), DT, PARAMS)


def _trajectory(robot, base_positions, rate=50.0):
    q = robot.standing_configuration()
    _, quaternion, joints = robot.split_configuration(q)
    n = len(base_positions)
    return Trajectory(
        time=np.arange(n) / rate,
        base_position=base_positions,
        base_quaternion_xyzw=np.tile(quaternion, (n, 1)),
        joint_positions=np.tile(joints, (n, 1)),
        source="test",
        rate_hz=rate,
    )


def test_corner_heights_match_pinocchio(robot, rng):
    from builders import random_configuration

    configurations = np.array([random_configuration(robot, rng) for _ in range(5)])
    kinematics = foot_kinematics(robot, configurations)
    for k, q in enumerate(configurations):
        for f, frame in enumerate(FEET):
            placement = robot.frame_placement(q, frame)
            corner_z = [placement.act(c)[2] for c in SOLE_CORNERS]
            assert kinematics.heights[k, f] == pytest.approx(min(corner_z), abs=1e-12)
            np.testing.assert_allclose(kinematics.positions[k, f], placement.translation)
    np.testing.assert_allclose(
        lowest_corner_heights(kinematics.positions[0], kinematics.rotations[0]),
        kinematics.heights[0],
    )


def test_detect_contacts_on_the_robot(robot):
    standing = robot.standing_configuration()
    q0 = standing.copy()
    lowest = foot_kinematics(robot, q0[None]).heights.min()
    base = np.tile(standing[:3] - [0, 0, lowest], (40, 1))  # lowest corner exactly on the floor
    base[15:25, 2] += 0.1  # jump: both feet 10 cm up for 10 frames
    trajectory = _trajectory(robot, base)
    assert trajectory_configurations(robot, trajectory).shape == (40, robot.model.nq)
    contacts = detect_contacts(robot, trajectory, PARAMS)
    expected = np.ones(40, dtype=bool)
    expected[17:27] = False
    np.testing.assert_array_equal(contacts, np.stack([expected, expected], axis=1))


def test_sole_pitch_of_a_pitched_sole(robot):
    q = robot.standing_configuration()
    # rotate the whole robot about the world y axis by 0.3 rad: each sole pitches by ~0.3
    rotation = pin.utils.rotate("y", 0.3) @ pin.Quaternion(q[3:7]).matrix()
    q[3:7] = pin.Quaternion(rotation).coeffs()
    kinematics = foot_kinematics(robot, q[None])
    flat = foot_kinematics(robot, robot.standing_configuration()[None])
    np.testing.assert_allclose(kinematics.pitches - flat.pitches, 0.3, atol=0.01)


def test_lowest_corner_is_the_min_over_every_corner(robot, rng):
    """The lowest corner of either foot, as retarget.quality and the data report read it, is
    the minimum over all world corners p + R c, to the bit (adding p keeps the order)."""
    from builders import random_configuration

    from pimann.core.robot import corner_offsets

    configurations = np.array([random_configuration(robot, rng) for _ in range(8)])
    feet = foot_kinematics(robot, configurations)
    corners = feet.positions[:, :, None] + corner_offsets(feet.rotations)  # (T, 2, C, 3)
    np.testing.assert_array_equal(
        lowest_corner_heights(feet.positions, feet.rotations).min(axis=1),
        corners[..., 2].min(axis=(1, 2)),
    )
