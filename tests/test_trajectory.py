"""The HDF5 trajectory file: round trip, joint order by name, bad files, atomic writes."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from pimann.core.errors import PimannError
from pimann.core.robot import JOINT_NAMES
from pimann.core.trajectory import (
    Trajectory,
    iter_collection,
    read_trajectory,
    write_collection,
    write_trajectory,
)


def _trajectory(rng, n=20, **extra) -> Trajectory:
    quaternion = rng.normal(size=(n, 4))
    return Trajectory(
        time=np.arange(n) / 50.0,
        base_position=rng.normal(size=(n, 3)),
        base_quaternion_xyzw=quaternion / np.linalg.norm(quaternion, axis=1, keepdims=True),
        joint_positions=rng.normal(size=(n, 26)),
        source="clip_001",
        rate_hz=50.0,
        contacts=rng.random((n, 2)) > 0.5,
        **extra,
    )


def test_round_trip(tmp_path, rng):
    trajectory = _trajectory(rng, attrs={"mirrored": True, "pi_weight": 10.0})
    write_trajectory(tmp_path / "t.h5", trajectory)
    back = read_trajectory(tmp_path / "t.h5")
    for name in ("time", "base_position", "base_quaternion_xyzw", "joint_positions", "contacts"):
        np.testing.assert_array_equal(getattr(back, name), getattr(trajectory, name))
    assert back.source == "clip_001" and back.rate_hz == 50.0
    assert back.attrs == {"mirrored": True, "pi_weight": 10.0}
    with h5py.File(tmp_path / "t.h5") as file:
        assert [str(n) for n in file.attrs["joint_names"]] == list(JOINT_NAMES)


def test_collection(tmp_path, rng):
    clips = [("b", _trajectory(rng, 5)), ("a", _trajectory(rng, 7))]
    write_collection(tmp_path / "c.h5", clips)
    names = [name for name, _ in iter_collection(tmp_path / "c.h5")]
    assert names == ["a", "b"]
    assert len(read_trajectory(tmp_path / "c.h5", "a")) == 7
    with pytest.raises(PimannError, match="no group 'z'"):
        read_trajectory(tmp_path / "c.h5", "z")


def test_joints_in_another_order_are_mapped_by_name(tmp_path, rng):
    trajectory = _trajectory(rng)
    order = rng.permutation(26)
    with h5py.File(tmp_path / "p.h5", "w") as file:
        for name in ("time", "base_position", "base_quaternion_xyzw"):
            file[name] = getattr(trajectory, name)
        file["joint_positions"] = trajectory.joint_positions[:, order]
        file.attrs["joint_names"] = [JOINT_NAMES[i] for i in order]
    np.testing.assert_array_equal(
        read_trajectory(tmp_path / "p.h5").joint_positions, trajectory.joint_positions
    )


def test_unknown_joint_is_named(tmp_path, rng):
    write_trajectory(tmp_path / "t.h5", _trajectory(rng))
    with h5py.File(tmp_path / "t.h5", "a") as file:
        names = list(JOINT_NAMES)
        names[3] = "l_knee_2"
        file.attrs["joint_names"] = names
    with pytest.raises(PimannError, match=r"t.h5: .*unknown: \['l_knee_2'\]"):
        read_trajectory(tmp_path / "t.h5")


def test_nan_is_named_with_frame(rng):
    trajectory = _trajectory(rng)
    joints = trajectory.joint_positions.copy()
    joints[7, 3] = np.nan
    with pytest.raises(PimannError, match=r"clip_001 \(frame 7\): joint_positions holds NaN"):
        Trajectory(
            trajectory.time,
            trajectory.base_position,
            trajectory.base_quaternion_xyzw,
            joints,
            "clip_001",
            50.0,
        )


def test_not_hdf5_and_truncated(tmp_path, rng):
    (tmp_path / "x.h5").write_text("hello")
    with pytest.raises(PimannError, match="x.h5: not a readable HDF5 file"):
        read_trajectory(tmp_path / "x.h5")
    write_trajectory(tmp_path / "t.h5", _trajectory(rng, 500))
    data = (tmp_path / "t.h5").read_bytes()
    (tmp_path / "cut.h5").write_bytes(data[: len(data) // 2])
    with pytest.raises(PimannError, match="cut.h5"):
        read_trajectory(tmp_path / "cut.h5")


def test_failed_write_leaves_nothing(tmp_path, rng):
    good = _trajectory(rng)

    def clips():
        yield "a", good
        raise RuntimeError("stage crashed mid-way")

    with pytest.raises(RuntimeError):
        write_collection(tmp_path / "c.h5", clips())
    assert list(tmp_path.iterdir()) == []
