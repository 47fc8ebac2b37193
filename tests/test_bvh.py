"""BVH reader: closed-form kinematics on synthetic files, the error contract on a real clip
(calibration and skeletons: test_skeletons.py)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pimann.core.errors import PimannError
from pimann.core.paths import mocap_dir
from pimann.mocap.bvh import detect_unit, forward_kinematics, parse_bvh, read_bvh, world_axes

CHANNELS = "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation"
REAL_CLIP = "Bandai-Namco-Research-Motiondataset-1/data/dataset-1_walk_normal_001.bvh"


def bvh_text(names: list[str], offsets: np.ndarray, frames: np.ndarray, n_frames=None) -> str:
    """A chain of joints (each the child of the previous), 6 channels each."""
    lines = ["HIERARCHY"]
    for depth, (name, offset) in enumerate(zip(names, offsets, strict=True)):
        kind = "ROOT" if depth == 0 else "JOINT"
        lines += [f"{kind} {name}", "{", "OFFSET " + " ".join(map(str, offset)), CHANNELS]
    lines += ["End Site", "{", "OFFSET 0 0 0", "}"] + ["}"] * len(names)
    count = len(frames) if n_frames is None else n_frames
    lines += ["MOTION", f"Frames:\t{count}", "Frame Time:\t0.0333333"]
    lines += [" ".join(f"{v:.10g}" for v in row) for row in frames]
    return "\n".join(lines) + "\n"


def test_forward_kinematics_matches_closed_form(tmp_path):
    # root at (1, 2, 3) turned Rz(90) Rx(90); child offset (0, 0, 10) ends at root + (10, 0, 0)
    # (the other product order, Rx Rz, would put it at root + (0, -10, 0)).
    offsets = np.array([[0.0, 0, 0], [0, 0, 10]])
    frame = np.array([1, 2, 3, 90, 90, 0, 0, 0, 10, 0, 0, 0])
    path = tmp_path / "two.bvh"
    path.write_text(bvh_text(["A", "B"], offsets, frame[None]))
    rotations, positions = forward_kinematics(parse_bvh(path))
    np.testing.assert_allclose(positions[0, 1], [11, 2, 3], atol=1e-9)
    rz = Rotation.from_euler("z", 90, degrees=True).as_matrix()
    expected = rz @ Rotation.from_euler("x", 90, degrees=True).as_matrix()
    np.testing.assert_allclose(rotations[0, 0], expected, atol=1e-12)
    np.testing.assert_allclose(rotations[0, 1], expected, atol=1e-12)


def test_end_sites_are_parsed(tmp_path):
    offsets = np.array([[0.0, 0, 0], [0, 0, 10]])
    path = tmp_path / "two.bvh"
    path.write_text(bvh_text(["A", "B"], offsets, np.zeros((1, 12))))
    joints = parse_bvh(path).joints
    assert joints[0].end_site is None
    np.testing.assert_array_equal(joints[1].end_site, [0, 0, 0])


@pytest.mark.parametrize(
    ("leg", "unit"), [(0.8, 1.0), (85.0, 0.01), (900.0, 0.001), (15.0, 0.0564)]
)
def test_length_unit_from_the_leg(leg, unit):
    assert detect_unit("x.bvh", leg) == pytest.approx(unit, rel=1e-3)


def test_unknown_length_unit_asks_for_unit_to_m():
    with pytest.raises(PimannError, match="set unit_to_m in params data.skeletons"):
        detect_unit("x.bvh", 5.0)


@pytest.mark.parametrize("up", [[0, 1, 0], [0, -1, 0], [0, 0, 1], [-1, 0, 0]])
def test_world_axes_turn_the_up_axis_to_z(up):
    matrix = world_axes(np.array(up, float) + 0.1)
    np.testing.assert_allclose(matrix @ up, [0, 0, 1])
    assert np.linalg.det(matrix) == pytest.approx(1.0)


def write_real_copy(tmp_path, edit) -> str:
    lines = (mocap_dir() / "bandai-namco/dataset" / REAL_CLIP).read_text().splitlines()
    path = tmp_path / "bad.bvh"
    path.write_text("\n".join(edit(lines)) + "\n")
    return path


def motion_start(lines):
    return lines.index("MOTION") + 3


@pytest.mark.parametrize(
    ("edit", "problem", "frame"),
    [
        (lambda ls: ls[:-5], "truncated", 190),
        (lambda ls: ls[:-1] + [" ".join(ls[-1].split()[:-3])], "values, expected", 194),
        (
            lambda ls: (
                ls[: motion_start(ls) + 7]
                + [ls[motion_start(ls) + 7].replace("0 0 0", "0 nan 0", 1)]
                + ls[motion_start(ls) + 8 :]
            ),
            "NaN",
            7,
        ),
        (lambda ls: [x.replace("Head", "Skull") for x in ls], "no joint for Head", None),
    ],
    ids=["truncated", "short-line", "nan", "missing-joint"],
)
def test_bad_input_names_file_frame_and_problem(tmp_path, edit, problem, frame):
    path = write_real_copy(tmp_path, edit)
    with pytest.raises(PimannError) as error:
        read_bvh(path)
    assert problem in str(error.value)
    assert "bad.bvh" in str(error.value)
    assert error.value.frame == frame
