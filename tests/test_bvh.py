"""BVH reader: closed-form kinematics on synthetic files, calibration checks on a real clip."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pimann.errors import PimannError
from pimann.mocap.bvh import BVH_TO_WORLD, forward_kinematics, parse_bvh, read_bvh
from pimann.params import load_params
from pimann.paths import mocap_dir
from pimann.robot import SEGMENTS

CHANNELS = "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation"
REAL_CLIP = "Bandai-Namco-Research-Motiondataset-1/data/dataset-1_walk_normal_001.bvh"


@pytest.fixture(scope="module")
def skeleton():
    params = load_params()
    return params.data.skeletons[params.data.skeleton]


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


def chain_skeleton(skeleton, names):
    """The real calibration on a synthetic chain whose joints stand for the segments."""
    return dataclasses.replace(skeleton, segments=dict(zip(SEGMENTS, names, strict=True)))


def test_read_bvh_calibrates_and_converts_units(tmp_path, skeleton, rng):
    names = [f"J{k}" for k in range(len(SEGMENTS))]
    offsets = np.tile([0.0, 10.0, 0.0], (len(names), 1))
    angles = rng.uniform(-60, 60, size=(4, len(names), 3))
    frames = np.concatenate([np.tile(offsets, (4, 1, 1)), angles], axis=2)
    frames[:, 0, :3] = [[5, 90, -300 + 10 * t] for t in range(4)]
    path = tmp_path / "chain.bvh"
    path.write_text(bvh_text(names, offsets, frames.reshape(4, -1)))
    motion = read_bvh(path, chain_skeleton(skeleton, names))
    local = Rotation.from_euler("ZXY", angles.reshape(-1, 3), degrees=True).as_matrix()
    local = local.reshape(4, len(names), 3, 3)
    world = np.empty_like(local)
    position = np.empty((4, len(names), 3))
    world[:, 0], position[:, 0] = local[:, 0], frames[:, 0, :3]
    for k in range(1, len(names)):
        world[:, k] = world[:, k - 1] @ local[:, k]
        position[:, k] = position[:, k - 1] + world[:, k - 1] @ offsets[k]
    # Pelvis: XSens x, y, z = BVH local Z, -Y, X
    pelvis_axes = np.array([[0.0, 0, 1], [0, -1, 0], [1, 0, 0]]).T
    np.testing.assert_allclose(
        motion.segment("Pelvis"), BVH_TO_WORLD @ world[:, 0] @ pelvis_axes, atol=1e-12
    )
    np.testing.assert_allclose(
        motion.segment_positions, position @ BVH_TO_WORLD.T * 0.01, atol=1e-12
    )
    # robot coordinates: [Z, X, Y] / 100
    np.testing.assert_allclose(motion.pelvis_position[1], [-2.9, 0.05, 0.9], atol=1e-12)
    np.testing.assert_allclose(np.diff(motion.time), 0.0333333)
    for rotation in motion.orientations.reshape(-1, 3, 3):
        np.testing.assert_allclose(rotation @ rotation.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(rotation) == pytest.approx(1.0)


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
        (lambda ls: [x.replace("Head", "Skull") for x in ls], "lacks joints ['Head']", None),
    ],
    ids=["truncated", "short-line", "nan", "missing-joint"],
)
def test_bad_input_names_file_frame_and_problem(tmp_path, skeleton, edit, problem, frame):
    path = write_real_copy(tmp_path, edit)
    with pytest.raises(PimannError) as error:
        read_bvh(path, skeleton)
    assert problem in str(error.value)
    assert "bad.bvh" in str(error.value)
    assert error.value.frame == frame


def test_real_clip_calibration(skeleton):
    """SPEC 3.1 checks: knee flexes about the thigh's y axis, ankle and trunk near neutral."""
    motion = read_bvh(mocap_dir() / "bandai-namco/dataset" / REAL_CLIP, skeleton)
    assert motion.n_frames == 195
    assert motion.rate_hz == pytest.approx(30.0, rel=1e-4)
    for side in ("Left", "Right"):
        thigh, shank = motion.segment(f"{side}UpperLeg"), motion.segment(f"{side}LowerLeg")
        knee = Rotation.from_matrix(np.swapaxes(thigh, 1, 2) @ shank).as_rotvec()
        angle = np.linalg.norm(knee, axis=1)
        flexed = angle > np.radians(10)
        off_axis = np.degrees(np.arccos(knee[flexed, 1] / angle[flexed]))  # flexion is +y
        assert np.median(off_axis) < 0.5
        foot = motion.segment(f"{side}Foot")
        ankle = Rotation.from_matrix(np.swapaxes(shank, 1, 2) @ foot).as_rotvec()
        assert abs(np.degrees(ankle[:, 1].mean())) < 6.0
        # flat feet: the foot's x axis is horizontal in the median frame
        assert abs(np.degrees(np.median(np.arcsin(foot[:, 2, 0])))) < 2.0
    trunk_tilt = np.degrees(np.arccos(motion.segment("T8")[:, 2, 2]))
    assert trunk_tilt.mean() < 4.0
    # walks forward along +x by about 8 m at pelvis height ~0.9 m, left foot at +y
    assert motion.pelvis_position[-1, 0] - motion.pelvis_position[0, 0] > 6.0
    assert 0.8 < motion.pelvis_position[:, 2].mean() < 1.0
    left, right = SEGMENTS.index("LeftFoot"), SEGMENTS.index("RightFoot")
    lateral = (
        np.swapaxes(motion.segment("Pelvis"), 1, 2)
        @ (motion.segment_positions[:, left] - motion.segment_positions[:, right])[..., None]
    )
    assert np.median(lateral[:, 1, 0]) > 0.0


def test_select_clips_spreads_over_contents_and_checks_labels(tmp_path):
    import json

    from pimann.mocap.clips import select_clips

    data = load_params().data
    every = select_clips(dataclasses.replace(data, max_clips=None))
    assert len(every) == 720
    assert {c.content for c in every} == set(data.contents)
    few = select_clips(dataclasses.replace(data, max_clips=12))
    assert len(few) == 12
    assert {c.content for c in few} == set(data.contents)  # every kind of walking
    styled = select_clips(dataclasses.replace(data, styles=["elderly"], max_clips=None))
    assert styled and {c.style for c in styled} == {"elderly"}
    assert {c.dataset for c in styled} == {2}
    # a label file that disagrees with the file name is reported, naming the file
    folder = tmp_path / "dataset-A"
    (folder / "cfg").mkdir(parents=True)
    (folder / "data").mkdir()
    (folder / "cfg/content_label.txt").write_text("dataset-1_walk\ndataset-1_run\n")
    (folder / "cfg/style_label.txt").write_text("dataset-1_normal\n")
    (folder / "data/dataset-1_walk_normal_001.bvh").write_text("")
    (folder / "data/dataset-1_walk_normal_001.json").write_text(
        json.dumps({"content": 1, "style": 0})
    )
    with pytest.raises(PimannError, match="disagree") as error:
        select_clips(dataclasses.replace(data, mocap_root=str(tmp_path)))
    assert "dataset-1_walk_normal_001.json" in str(error.value)
