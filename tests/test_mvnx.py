"""MVNX: the genuine XSens export is read exactly, special frames skipped, bad copies rejected."""

from __future__ import annotations

import re

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pimann.core.errors import PimannError
from pimann.core.paths import shared_dir
from pimann.core.robot import SEGMENTS
from pimann.mocap.io import mocap_format, mocap_info, read_mocap
from pimann.mocap.mvnx import mvnx_info, read_mvnx

MVNX = shared_dir() / "data" / "xsens" / "mvnx" / "Meri-020.mvnx"
pytestmark = pytest.mark.skipif(not MVNX.is_file(), reason="shared MVNX sample not present")


def literal_frames(text: str) -> tuple[list[str], list[np.ndarray], list[np.ndarray]]:
    """Segment labels and the normal frames' numbers, read with regexes (not XML)."""
    labels = re.findall(r'<segment label="(\w+)" id="\d+">', text)
    frames = re.findall(
        r'<frame [^>]*type="normal">\s*<orientation>([^<]*)</orientation>\s*'
        r"<position>([^<]*)</position>",
        text,
    )
    orientations = [np.array([float(v) for v in o.split()]).reshape(-1, 4) for o, _ in frames]
    positions = [np.array([float(v) for v in p.split()]).reshape(-1, 3) for _, p in frames]
    return labels, orientations, positions


def quaternion_matrix(w: float, x: float, y: float, z: float) -> np.ndarray:
    """Closed-form rotation matrix of a (normalised) quaternion."""
    w, x, y, z = np.array([w, x, y, z]) / np.linalg.norm([w, x, y, z])
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])  # fmt: skip


def test_genuine_file_is_read_exactly():
    motion = read_mvnx(MVNX)
    labels, orientations, positions = literal_frames(MVNX.read_text())
    assert len(labels) == 23 and len(orientations) == 4
    assert motion.n_frames == 4
    assert motion.rate_hz == pytest.approx(240.0)
    np.testing.assert_allclose(motion.time, np.arange(4) / 240.0)
    for name in SEGMENTS:
        k, column = SEGMENTS.index(name), labels.index(name)
        for t in range(4):
            np.testing.assert_array_equal(motion.segment_positions[t, k], positions[t][column])
            w, x, y, z = orientations[t][column]
            np.testing.assert_allclose(
                motion.orientations[t, k], quaternion_matrix(w, x, y, z), atol=1e-12
            )
            reference = Rotation.from_quat([x, y, z, w]).as_matrix()
            np.testing.assert_allclose(motion.orientations[t, k], reference, atol=1e-12)
    # literal numbers from the file text: the first normal frame's Pelvis, not the npose/tpose
    np.testing.assert_array_equal(motion.pelvis_position[0], [0.212895, 0.092919, 0.930272])
    first = Rotation.from_quat([0.000878, -0.073481, 0.004489, 0.997286]).as_matrix()
    np.testing.assert_allclose(motion.segment("Pelvis")[0], first, atol=1e-12)


def test_info_lists_every_segment():
    info = mvnx_info(MVNX)
    assert info["format"] == "mvnx"
    assert info["frames"] == 4 and info["rate_hz"] == 240.0
    assert info["duration_s"] == pytest.approx(3 / 240)
    assert len(info["segments"]) == 23 and info["segments"][:2] == ["Pelvis", "L5"]
    assert set(SEGMENTS) <= set(info["segments"])


def test_missing_segment_raises_naming_file_and_segment(tmp_path):
    copy = tmp_path / "nofoot.mvnx"
    copy.write_text(MVNX.read_text().replace('label="LeftFoot"', 'label="LeftPaw"'))
    with pytest.raises(PimannError, match="LeftFoot") as error:
        read_mvnx(copy)
    assert str(copy) in str(error.value)


def test_short_frame_and_nan_raise_naming_the_frame(tmp_path):
    text = MVNX.read_text()
    frames = list(re.finditer(r'type="normal">\s*<orientation>([^<]*)</orientation>', text))
    start, end = frames[2].span(1)
    numbers = text[start:end].split()
    short = tmp_path / "short.mvnx"
    short.write_text(text[:start] + " ".join(numbers[:-4]) + text[end:])
    with pytest.raises(PimannError, match="88 numbers") as error:
        read_mvnx(short)
    assert error.value.frame == 2 and str(short) in str(error.value)
    numbers[1] = "nan"  # Pelvis; NaNs in segments the study ignores do not matter
    bad = tmp_path / "nan.mvnx"
    bad.write_text(text[:start] + " ".join(numbers) + text[end:])
    with pytest.raises(PimannError, match="NaN") as error:
        read_mvnx(bad)
    assert error.value.frame == 2


def test_not_xml_raises(tmp_path):
    path = tmp_path / "broken.mvnx"
    path.write_text(MVNX.read_text()[:5000])
    with pytest.raises(PimannError, match="not valid XML"):
        read_mvnx(path)


# The dispatcher (pimann.mocap.io) is tested here and in test_yarp_log.py.


def test_dispatcher_reads_mvnx_by_extension_and_by_content(tmp_path):
    by_extension = read_mocap(MVNX)
    renamed = tmp_path / "export.xml"
    renamed.write_bytes(MVNX.read_bytes())
    assert mocap_format(renamed) == "mvnx"
    np.testing.assert_array_equal(read_mocap(renamed).orientations, by_extension.orientations)
    assert mocap_info(renamed) == mvnx_info(MVNX)


def test_dispatcher_reads_bvh():
    clips = sorted((shared_dir() / "data" / "mocap" / "bandai-namco").rglob("*walk_*.bvh"))
    if not clips:
        pytest.skip("no shared BVH clip")
    info = mocap_info(clips[0])
    assert info["format"] == "bvh" and info["rate_hz"] == pytest.approx(30.0, rel=1e-3)
    assert {"Hips", "UpperLeg_L", "LowerArm_R"} <= set(info["segments"])
    assert read_mocap(clips[0]).n_frames == info["frames"] > 10


def test_dispatcher_rejects_unknown_files(tmp_path):
    path = tmp_path / "notes.txt"
    path.write_text("just some text\n1 2 3\n")
    with pytest.raises(PimannError, match="unknown mocap format") as error:
        read_mocap(path)
    assert str(path) in str(error.value)
    with pytest.raises(PimannError, match="not found"):
        mocap_info(tmp_path / "absent.log")
