"""Rendering: real pinocchio kinematics drawn with matplotlib, files read back with imageio."""

from __future__ import annotations

import functools

import imageio.v3 as iio
import numpy as np
import pytest
from builders import CONTACT_PARAMS
from matplotlib.colors import to_rgb

from pimann.core.errors import PimannError
from pimann.core.robot import (
    JOINT_NAMES,
    SEGMENTS,
    STANDING_BASE_HEIGHT,
    STANDING_BASE_QUATERNION_XYZW,
    STANDING_JOINTS,
)
from pimann.core.trajectory import Trajectory, write_trajectory
from pimann.mocap.human_motion import HumanMotion
from pimann.render.beside_mocap import render_file as _render_file
from pimann.render.trajectory import (
    LEFT_COLOUR,
    RIGHT_COLOUR,
    human_skeleton,
    match_frames,
    robot_skeleton,
)
from pimann.render.trajectory import render_trajectory as _render_trajectory

# the repository's contact rule, for the trajectories without contact flags
render_file = functools.partial(_render_file, contacts=CONTACT_PARAMS)
render_trajectory = functools.partial(_render_trajectory, contacts=CONTACT_PARAMS)

W, H = 320, 240


def standing(n: int = 5, rate: float = 50.0, lift: float = 0.0, knee: float = 0.0) -> Trajectory:
    """The standing pose, base moving forward 1 cm a frame (raised by `lift`, knees bent)."""
    joints = np.tile(STANDING_JOINTS, (n, 1))
    for side in ("l", "r"):
        joints[:, JOINT_NAMES.index(f"{side}_knee")] += knee
    base = np.column_stack([0.01 * np.arange(n), np.zeros(n), np.full(n, STANDING_BASE_HEIGHT)])
    base[:, 2] += lift
    return Trajectory(
        time=np.arange(n) / rate,
        base_position=base,
        base_quaternion_xyzw=np.tile(STANDING_BASE_QUATERNION_XYZW, (n, 1)),
        joint_positions=joints,
        source="synthetic",
        rate_hz=rate,
    )


def colour_pixels(image: np.ndarray, colour: str) -> int:
    target = np.array(to_rgb(colour)) * 255
    return int((np.abs(image.astype(float) - target).max(axis=-1) < 40).sum())


def test_png_strip_size_and_robot_drawn(tmp_path, robot):
    out = render_trajectory(standing(), tmp_path / "s.png", strip_frames=3, width=W, height=H)
    image = iio.imread(out)
    assert image.shape[:2] == (H, 3 * W + 2 * 3)  # 3 frames and 2 separators
    for k in range(3):
        frame = image[:, k * (W + 3) : k * (W + 3) + W, :3]
        assert colour_pixels(frame, LEFT_COLOUR) > 50
        assert colour_pixels(frame, RIGHT_COLOUR) > 50
    assert not list(tmp_path.glob(".s.png*"))  # no temporary left behind


def test_pose_changes_picture_and_is_deterministic(tmp_path, robot):
    paths = [tmp_path / f"{k}.png" for k in range(3)]
    render_trajectory(standing(1), paths[0], strip_frames=1, width=W, height=H)
    render_trajectory(standing(1), paths[1], strip_frames=1, width=W, height=H)
    render_trajectory(standing(1, knee=-1.0), paths[2], strip_frames=1, width=W, height=H)
    a, b, c = (iio.imread(p) for p in paths)
    assert np.array_equal(a, b)
    assert (np.abs(a.astype(int) - c.astype(int)).max(axis=-1) > 30).sum() > 100


def test_gif_frame_count_and_rate(tmp_path, robot):
    out = render_trajectory(standing(7), tmp_path / "a.gif", every_n_frames=2, width=W, height=H)
    frames = iio.imread(out, index=None)
    assert frames.shape[:3] == (4, H, W)  # frames 0, 2, 4, 6
    assert iio.immeta(out, index=0)["duration"] == pytest.approx(1000 / 25, abs=1)


def test_mp4_frame_count(tmp_path, robot):
    pytest.importorskip("imageio_ffmpeg")
    out = render_trajectory(standing(6), tmp_path / "a.mp4", every_n_frames=1, width=W, height=H)
    assert iio.imread(out, index=None, plugin="FFMPEG").shape[:3] == (6, H, W)


@pytest.mark.parametrize("name", ["a.jpg", "noextension"])
def test_bad_extension_names_file(tmp_path, name):
    with pytest.raises(PimannError, match=name):
        render_trajectory(standing(), tmp_path / name)
    assert not list(tmp_path.iterdir())


def test_robot_skeleton_matches_pinocchio(robot):
    traj = standing(3, knee=-0.5)
    skeleton = robot_skeleton(traj, np.array([0, 2]), robot, CONTACT_PARAMS)
    q = robot.configuration(
        traj.base_position[2], traj.base_quaternion_xyzw[2], traj.joint_positions[2]
    )
    for side, frame in enumerate(("l_sole", "r_sole")):
        sole = robot.frame_placement(q, frame).translation
        np.testing.assert_allclose(skeleton.feet[1, side].mean(axis=0), sole, atol=1e-12)
        assert np.any(np.linalg.norm(skeleton.points[1] - sole, axis=1) < 1e-12)
    head = robot.frame_placement(q, "head").translation
    assert skeleton.points[1][:, 2].max() == pytest.approx(head[2] + 0.2, abs=0.02)
    # every bone joins two points of the same subject: lengths do not change with the pose
    lengths = np.linalg.norm(np.diff(skeleton.points[:, skeleton.bones], axis=2), axis=-1)
    np.testing.assert_allclose(lengths[0], lengths[1], atol=1e-9)


def side_of_bones(skeleton) -> dict[str, np.ndarray]:
    """y of each bone's child end, grouped by its colour (the subject faces +x at y = 0)."""
    ends = skeleton.points[0][skeleton.bones[:, 1], 1]
    colours = np.array(skeleton.bone_colours)
    return {c: ends[colours == c] for c in (LEFT_COLOUR, RIGHT_COLOUR)}


def test_left_is_blue_right_is_red(robot):
    robot_sides = side_of_bones(robot_skeleton(standing(1), np.array([0]), robot, CONTACT_PARAMS))
    human_sides = side_of_bones(human_skeleton(tpose_human(1), np.array([0])))
    for sides in (robot_sides, human_sides):
        assert len(sides[LEFT_COLOUR]) >= 6 and np.all(sides[LEFT_COLOUR] > 0.03)
        assert len(sides[RIGHT_COLOUR]) >= 6 and np.all(sides[RIGHT_COLOUR] < -0.03)


def test_contacts_from_height_when_not_given(robot):
    on_floor = robot_skeleton(standing(1), np.array([0]), robot, CONTACT_PARAMS)
    lifted = robot_skeleton(standing(1, lift=0.1), np.array([0]), robot, CONTACT_PARAMS)
    assert on_floor.contacts.tolist() == [[True, True]]
    assert lifted.contacts.tolist() == [[False, False]]
    given = standing(2)
    given.contacts = np.array([[True, False], [False, True]])
    assert robot_skeleton(given, np.array([1]), robot).contacts.tolist() == [[False, True]]


def tpose_human(n: int = 9, rate: float = 100.0, start: float = 3.0) -> HumanMotion:
    """Identity orientations (T-pose), segments at rough human heights, walking along x."""
    layout = {
        "Pelvis": (0, 0, 0.95),
        "T8": (0, 0, 1.25),
        "Head": (0, 0, 1.55),
        "LeftUpperLeg": (0, 0.09, 0.92),
        "LeftLowerLeg": (0, 0.09, 0.48),
        "LeftFoot": (0, 0.09, 0.08),
        "RightUpperLeg": (0, -0.09, 0.92),
        "RightLowerLeg": (0, -0.09, 0.48),
        "RightFoot": (0, -0.09, 0.08),
        "LeftUpperArm": (0, 0.2, 1.4),
        "LeftForeArm": (0, 0.5, 1.4),
        "RightUpperArm": (0, -0.2, 1.4),
        "RightForeArm": (0, -0.5, 1.4),
    }
    positions = np.array([layout[s] for s in SEGMENTS], dtype=float)
    positions = positions + np.arange(n)[:, None, None] * np.array([0.02, 0.0, 0.0])
    return HumanMotion(
        time=start + np.arange(n) / rate,
        orientations=np.tile(np.eye(3), (n, len(SEGMENTS), 1, 1)),
        segment_positions=positions,
        source="tpose",
    )


def test_human_skeleton_ends_follow_segment_frames():
    human = tpose_human()
    skeleton = human_skeleton(human, np.array([0]))
    points = skeleton.points[0]
    forearm = points[SEGMENTS.index("LeftForeArm")]
    scale = (0.44 + 0.40) / 0.88  # the legs measured here over the reference 0.88 m
    hand = points[len(SEGMENTS) + 1]  # "LeftHand", T-pose: along the forearm's +y
    np.testing.assert_allclose(hand, forearm + [0.0, 0.22 * scale, 0.0], atol=1e-12)
    assert len(skeleton.bones) == len(skeleton.bone_colours)


def test_match_frames_by_time():
    source = 3.0 + np.arange(9) / 100.0
    # same clock: nearest sample; disjoint clocks (robot from 0): aligned at the start
    np.testing.assert_array_equal(match_frames([3.0, 3.021, 3.049], source), [0, 2, 5])
    np.testing.assert_array_equal(match_frames([0.0, 0.02, 0.04, 0.2], source), [0, 2, 4, 8])


def test_render_file_with_human_beside(tmp_path, robot):
    path = tmp_path / "t.h5"
    write_trajectory(path, standing(4))
    out = render_file(path, tmp_path / "t.png", strip_frames=2, width=W, height=H)
    assert iio.imread(out).shape[:2] == (H, 2 * W + 3)
    both = render_trajectory(
        standing(4), tmp_path / "b.png", tpose_human(), strip_frames=1, width=2 * W, height=H
    )
    image = iio.imread(both)[..., :3]
    # the human's arms are horizontal (T-pose): blue/red in the right panel, at arm height
    right_panel = image[:, W:]
    assert colour_pixels(right_panel, LEFT_COLOUR) > 30
    assert colour_pixels(right_panel, RIGHT_COLOUR) > 30


def test_nothing_to_render(tmp_path):
    with pytest.raises(PimannError, match="nothing to render"):
        render_trajectory(None, tmp_path / "x.png")


def test_strip_wraps_into_rows(tmp_path, robot):
    """6 frames in rows of 4: two rows, the last two places white (one row was 5775 px)."""
    out = render_trajectory(
        standing(12), tmp_path / "w.png", strip_frames=6, strip_columns=4, width=W, height=H
    )
    image = iio.imread(out)[..., :3]
    assert image.shape[:2] == (2 * H + 3, 4 * W + 3 * 3)
    second_row = image[H + 3 :]
    for k in range(4):
        tile = second_row[:, k * (W + 3) : k * (W + 3) + W]
        assert (colour_pixels(tile, LEFT_COLOUR) > 50) == (k < 2), k
    assert (second_row[:, 2 * (W + 3) :] >= 120).all()  # white places and grey separators


def test_default_strip_is_twelve_frames_in_three_rows(tmp_path, robot):
    out = render_trajectory(standing(40), tmp_path / "d.png")
    assert iio.imread(out).shape[:2] == (3 * 320 + 2 * 3, 4 * 480 + 3 * 3)


def test_frame_rate_samples_the_clip(tmp_path, robot):
    """frame_rate: frames per second of the clip, played in real time (50 Hz clip, 10 fps)."""
    out = render_trajectory(standing(11), tmp_path / "r.gif", frame_rate=10.0, width=W, height=H)
    assert iio.imread(out, index=None).shape[0] == 3  # samples 0, 5, 10
    assert iio.immeta(out, index=0)["duration"] == pytest.approx(100, abs=1)


def test_cli_render_frames_and_fps(tmp_path, robot):
    from pimann.cli import main

    path = tmp_path / "t.h5"
    write_trajectory(path, standing(10))
    size = ["--width", str(W), "--height", str(H)]
    strip = tmp_path / "s.png"
    assert (
        main(["render", str(path), "-o", str(strip), "--frames", "5", "--columns", "3", *size]) == 0
    )
    assert iio.imread(strip).shape[:2] == (2 * H + 3, 3 * W + 2 * 3)
    gif = tmp_path / "a.gif"
    assert main(["render", str(path), "-o", str(gif), "--fps", "25", *size]) == 0
    assert iio.imread(gif, index=None).shape[0] == 5  # every second sample of 10
