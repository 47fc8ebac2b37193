"""The drawing of the renderer (pimann.render.scene): the camera's projection and what a frame
shows, read back from its pixels."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.colors import to_rgb

from pimann.render.scene import (
    AZIMUTH_DEG,
    ELEVATION_DEG,
    LEFT_COLOUR,
    RIGHT_COLOUR,
    Scene,
    Skeleton,
    _Camera,
)

W, H = 240, 200


def test_the_camera_is_orthonormal_and_looks_down_from_its_direction():
    camera = _Camera()
    m = camera.matrix
    # rows u (right), v (up), depth (away from the camera): orthonormal, left-handed
    assert np.allclose(m @ m.T, np.eye(3)) and np.linalg.det(m) == pytest.approx(-1.0)
    az, el = np.radians(AZIMUTH_DEG), np.radians(ELEVATION_DEG)
    towards = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    assert np.allclose(camera.project(towards), [0.0, 0.0, -1.0])  # depth grows away from it
    up = camera.project([0.0, 0.0, 1.0])
    assert up[0] == pytest.approx(0.0, abs=1e-12) and up[1] == pytest.approx(np.cos(el))
    assert camera.project([0.0, 0.0, 0.0]) == pytest.approx(np.zeros(3))
    right = camera.project(np.cross(-towards, [0.0, 0.0, 1.0]) / np.cos(el))
    assert np.allclose(right, [1.0, 0.0, 0.0])  # horizontal, across the view: u only


def _pole(n=3, contacts=(True, False)):
    """A vertical two-bone pole at the origin, with two square soles beside it."""
    points = np.tile([[0.0, 0.0, 0.0], [0.0, 0.0, 0.6], [0.0, 0.0, 1.2]], (n, 1, 1))
    square = np.array([[-0.3, -0.2, 0], [0.3, -0.2, 0], [0.3, 0.2, 0], [-0.3, 0.2, 0]])
    feet = np.stack([square + [0, 0.5, 0], square - [0, 0.5, 0]])  # large: many pixels
    return Skeleton(
        title="pole",
        points=points,
        bones=np.array([[0, 1], [1, 2]]),
        bone_colours=["#ff8800", "#ff8800"],
        path=np.zeros((n, 2)),
        path_index=np.arange(n),
        feet=np.tile(feet, (n, 1, 1, 1)),
        contacts=np.tile(contacts, (n, 1)),
    )


def _near(frame, colour, tol=12):
    return np.all(np.abs(frame.astype(int) - np.array(to_rgb(colour)) * 255) <= tol, axis=-1)


def test_a_frame_shows_the_bones_upright_and_fills_only_the_feet_in_contact():
    scene = Scene([_pole(contacts=(False, True))], np.array([0.0, 0.02, 0.04]), W, H)
    frame = scene.draw(1)
    assert frame.shape == (H, W, 3) and frame.dtype == np.uint8
    bone = _near(frame, "#ff8800")
    rows, cols = np.nonzero(bone)
    assert bone.sum() > 100
    # vertical pole: a narrow column of pixels, 1.2 m tall on a view of VIEW_BELOW + VIEW_ABOVE
    assert cols.max() - cols.min() < 12 and (rows.max() - rows.min()) == pytest.approx(
        1.2 * np.cos(np.radians(ELEVATION_DEG)) * H / 2.4, rel=0.1
    )
    filled_right, filled_left = _near(frame, RIGHT_COLOUR).sum(), _near(frame, LEFT_COLOUR).sum()
    swapped = Scene([_pole(contacts=(True, False))], np.zeros(3), W, H).draw(1)
    assert _near(swapped, LEFT_COLOUR).sum() > 2 * filled_left  # the left sole now filled
    assert filled_right > 2 * _near(swapped, RIGHT_COLOUR).sum()


def test_two_subjects_share_one_frame_side_by_side():
    scene = Scene([_pole(), _pole()], np.array([0.0, 0.02, 0.04]), W, H)
    frame = scene.draw(0)
    cols = np.nonzero(_near(frame, "#ff8800"))[1]
    assert (cols < W / 2).any() and (cols >= W / 2).any()  # one pole in each half
    frames = list(scene.frames(3, "test"))
    assert len(frames) == 3 and all(f.shape == (H, W, 3) for f in frames)
    assert not np.array_equal(frames[0], frames[2])  # the clock moved on
