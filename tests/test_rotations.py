"""The heading-frame rotations against scipy's Rotation."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from pimann.core.rotations import from_heading_frame, to_heading_frame


def test_heading_frame_matches_scipy(rng):
    yaw = rng.uniform(-np.pi, np.pi, (4, 5))
    vectors = rng.normal(size=(4, 5, 3))
    turn = Rotation.from_euler("z", yaw.reshape(-1, 1))
    world = turn.apply(vectors.reshape(-1, 3)).reshape(vectors.shape)
    np.testing.assert_allclose(from_heading_frame(vectors, yaw), world, atol=1e-12)
    np.testing.assert_allclose(to_heading_frame(world, yaw), vectors, atol=1e-12)
    np.testing.assert_allclose(to_heading_frame(world[..., :2], yaw), vectors[..., :2], atol=1e-12)


def test_heading_frame_broadcasts_and_keeps_its_input(rng):
    vectors = rng.normal(size=(6, 2))
    kept = vectors.copy()
    assert to_heading_frame(vectors, 0.3).shape == (6, 2)
    assert from_heading_frame(vectors[0], np.zeros(6)).shape == (6, 2)
    np.testing.assert_array_equal(vectors, kept)
    np.testing.assert_allclose(to_heading_frame([1.0, 0.0], np.pi / 2), [0.0, -1.0], atol=1e-15)
