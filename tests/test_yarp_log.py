"""XSens YARP logs: exact round trip, both bottle layouts, incomplete and bad frames."""

from __future__ import annotations

import logging

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pimann.core.errors import PimannError
from pimann.core.robot import SEGMENTS
from pimann.mocap.human_motion import HumanMotion
from pimann.mocap.io import mocap_format, mocap_info, read_mocap
from pimann.mocap.yarp_log import read_yarp_log, write_yarp_log, yarp_log_info


def random_motion(rng: np.random.Generator, n: int = 12) -> HumanMotion:
    rotations = Rotation.random(n * len(SEGMENTS), random_state=int(rng.integers(1 << 31)))
    return HumanMotion(
        time=1603973549.25 + np.arange(n) / 100.0 + rng.uniform(0, 1e-3, n),
        orientations=rotations.as_matrix().reshape(n, len(SEGMENTS), 3, 3),
        segment_positions=rng.normal(size=(n, len(SEGMENTS), 3)),
        source="random",
    )


@pytest.fixture
def log_lines(tmp_path, rng) -> tuple[HumanMotion, list[str]]:
    motion = random_motion(rng)
    path = tmp_path / "walk.log"
    write_yarp_log(path, motion)
    return motion, path.read_text().splitlines()


def write_lines(path, lines: list[str]):
    path.write_text("\n".join(lines) + "\n")
    return path


def test_round_trip_is_exact(tmp_path, rng):
    motion = random_motion(rng)
    path = tmp_path / "walk.log"
    write_yarp_log(path, motion)
    back = read_yarp_log(path)
    np.testing.assert_array_equal(back.time, motion.time)
    np.testing.assert_array_equal(back.segment_positions, motion.segment_positions)
    np.testing.assert_allclose(back.orientations, motion.orientations, atol=1e-14)
    assert back.source == str(path) and back.mirrored is False


def test_values_are_read_from_the_documented_layout(log_lines):
    motion, lines = log_lines
    tokens = lines[3].split()
    assert tokens[0] == "3" and float(tokens[1]) == motion.time[3]
    # the T8 group: key, ("T8" status), (w x y z), (x y z)
    at = tokens.index("XsensSuit::vLink::T8")
    assert tokens[at + 1] == '(("T8"'
    numbers = [float(t.strip("()")) for t in tokens[at + 3 : at + 10]]
    w, x, y, z = numbers[:4]
    expected = Rotation.from_matrix(motion.segment("T8")[3])
    assert (Rotation.from_quat([x, y, z, w]) * expected.inv()).magnitude() < 1e-12
    np.testing.assert_array_equal(numbers[4:], motion.segment_positions[3, SEGMENTS.index("T8")])


def test_flat_map_layout_and_extra_entries_are_read(tmp_path):
    """The other YARP bottle form: full name repeated inside the group, more fields after."""
    rotations = Rotation.from_euler("z", np.linspace(0, 1, len(SEGMENTS))[:, None])
    lines = []
    for frame in range(3):
        parts = [f'{frame} {10.0 + 0.01 * frame} "XsensSuit"']
        parts.append('("XsensSuit::vLink::L5" ("XsensSuit::vLink::L5" 1 1 0 0 0 9 9 9))')
        for k, name in enumerate(SEGMENTS):
            x, y, z, w = rotations[k].as_quat()
            parts.append(
                f'("XsensSuit::vLink::{name}" ("XsensSuit::vLink::{name}" 1 {w} {x} {y} {z} '
                f"{k} {frame} {-k} 0.5 0.5 0.5))"
            )
        parts.append('("XsensSuit::vSJoint::jL5S1" ("XsensSuit::vSJoint::jL5S1" 1 1 0 0 0))')
        lines.append(" ".join(parts))
    motion = read_yarp_log(write_lines(tmp_path / "flat.log", lines))
    np.testing.assert_allclose(motion.time, [10.0, 10.01, 10.02])
    np.testing.assert_allclose(motion.orientations[1], rotations.as_matrix(), atol=1e-15)
    k = np.arange(len(SEGMENTS))
    np.testing.assert_array_equal(motion.segment_positions[2], np.column_stack([k, 2 + 0 * k, -k]))
    info = yarp_log_info(tmp_path / "flat.log")
    assert info["frames"] == 3 and info["format"] == "yarp-log"
    assert info["segments"][0] == "L5" and set(SEGMENTS) <= set(info["segments"])
    assert info["rate_hz"] == pytest.approx(100.0)


def test_incomplete_frames_are_dropped_with_a_warning(tmp_path, log_lines, caplog):
    motion, lines = log_lines
    lines[4] = lines[4].replace("XsensSuit::vLink::LeftFoot", "XsensSuit::vLink::LeftToe")
    lines[7] = lines[7].split(" XsensSuit::vLink::Head")[0]  # frame cut before Head
    lines.insert(2, "")  # blank lines are skipped
    with caplog.at_level(logging.WARNING):
        back = read_yarp_log(write_lines(tmp_path / "holes.log", lines))
    keep = [k for k in range(motion.n_frames) if k not in (4, 7)]
    np.testing.assert_array_equal(back.time, motion.time[keep])
    assert "dropped 2 frame(s)" in caplog.text


def test_truncated_last_line_is_dropped(tmp_path, log_lines, caplog):
    motion, lines = log_lines
    text = "\n".join(lines)
    cut = text[: text.rfind("XsensSuit::vLink::RightForeArm") + 40]  # mid-number, no newline
    path = tmp_path / "cut.log"
    path.write_text(cut)
    with caplog.at_level(logging.WARNING):
        back = read_yarp_log(path)
    assert back.n_frames == motion.n_frames - 1
    assert "dropped the last line" in caplog.text


def test_segment_absent_from_the_whole_log_raises(tmp_path, log_lines):
    _, lines = log_lines
    lines = [line.replace("vLink::RightLowerLeg", "vLink::RightShin") for line in lines]
    path = write_lines(tmp_path / "noshin.log", lines)
    with pytest.raises(PimannError, match="RightLowerLeg") as error:
        read_yarp_log(path)
    assert str(path) in str(error.value)


def test_no_complete_frame_raises(tmp_path, log_lines):
    _, lines = log_lines
    lines = [
        line.replace("vLink::Head", "vLink::Skull") if k % 2 else line.replace("vLink::T8", "vT")
        for k, line in enumerate(lines)
    ]
    with pytest.raises(PimannError, match="no frame holds all 13"):
        read_yarp_log(write_lines(tmp_path / "never.log", lines))


def test_nan_raises_naming_file_and_frame(tmp_path, log_lines):
    _, lines = log_lines
    tokens = lines[5].split(" ")
    at = tokens.index("XsensSuit::vLink::LeftUpperArm")
    tokens[at + 4] = "nan"  # the quaternion's x
    lines[5] = " ".join(tokens)
    path = write_lines(tmp_path / "nan.log", lines)
    with pytest.raises(PimannError, match="LeftUpperArm holds NaN") as error:
        read_yarp_log(path)
    assert error.value.frame == 5 and str(path) in str(error.value)


def test_malformed_middle_line_and_bad_quaternion_raise(tmp_path, log_lines):
    _, lines = log_lines
    broken = list(lines)
    broken[3] = broken[3].replace('(("Head" 1) (', '(("Head" 1) (x')
    with pytest.raises(PimannError, match=r"malformed entry .*Head") as error:
        read_yarp_log(write_lines(tmp_path / "bad.log", broken))
    assert error.value.frame == 3
    zero = list(lines)
    tokens = zero[6].split(" ")
    at = tokens.index("XsensSuit::vLink::Pelvis")
    tokens[at + 3 : at + 7] = ["(0.0", "0.0", "0.0", "0.0)"]
    zero[6] = " ".join(tokens)
    with pytest.raises(PimannError, match="Pelvis quaternion norm") as error:
        read_yarp_log(write_lines(tmp_path / "zero.log", zero))
    assert error.value.frame == 6


def test_missing_file_raises(tmp_path):
    with pytest.raises(PimannError, match="not found"):
        read_yarp_log(tmp_path / "absent.log")


def test_dispatcher_recognises_a_log_by_content(tmp_path, rng):
    motion = random_motion(rng)
    path = tmp_path / "session_data"  # no extension: yarpdatadumper writes `data.log` or none
    write_yarp_log(path, motion)
    assert mocap_format(path) == "yarp-log"
    np.testing.assert_array_equal(read_mocap(path).segment_positions, motion.segment_positions)
    info = mocap_info(path)
    assert info == yarp_log_info(path) and info["segments"] == list(SEGMENTS)
    assert info["frames"] == motion.n_frames
