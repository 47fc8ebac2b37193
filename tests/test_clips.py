"""The data set's takes and clips: selection over every source, cutting at standing pauses,
and a take's clips (and mirrors) kept on one side of the train/test split."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from pimann.core.errors import PimannError
from pimann.core.params import load_params
from pimann.core.paths import REPO_ROOT
from pimann.core.robot import N_JOINTS, SEGMENTS
from pimann.core.trajectory import Trajectory
from pimann.learn.features import split_sources
from pimann.mocap.clips import (
    Take,
    cut_take,
    pause_centres,
    select_takes,
    slice_motion,
    source_takes,
    take_clips,
)
from pimann.mocap.human_motion import HumanMotion
from pimann.mocap.mirror import mirror_trajectory as mirror


@pytest.fixture(scope="module")
def data():
    return load_params().data


def walking_motion(speed: np.ndarray, rate_hz: float = 30.0, feet: bool = False) -> HumanMotion:
    """A motion whose pelvis moves along x at `speed` (m/s, per frame), upright segments."""
    n = len(speed)
    time = np.arange(n) / rate_hz
    positions = np.zeros((n, len(SEGMENTS), 3))
    positions[:, :, 0] = np.concatenate([[0.0], np.cumsum(speed[:-1]) / rate_hz])[:, None]
    positions[:, SEGMENTS.index("Pelvis"), 2] = 0.9
    foot_points = np.repeat(positions[:, None, None, 0], 2, axis=1).repeat(2, axis=2)
    return HumanMotion(
        time=time,
        orientations=np.broadcast_to(np.eye(3), (n, len(SEGMENTS), 3, 3)).copy(),
        segment_positions=positions,
        source="/somewhere/take.bvh",
        foot_points=foot_points if feet else None,
    )


def test_selection_by_content_style_and_spread(data):
    bandai = data.sources["bandai_namco"]
    every = source_takes("bandai_namco", dataclasses.replace(bandai, max_takes=None), data)
    assert len(every) == 720
    assert {t.content for t in every} == set(bandai.contents)
    assert {t.source for t in every} == {"bandai_namco"}
    few = source_takes("bandai_namco", dataclasses.replace(bandai, max_takes=12), data)
    assert len(few) == 12
    assert {t.content for t in few} == set(bandai.contents)  # every kind of walking
    assert few == source_takes("bandai_namco", dataclasses.replace(bandai, max_takes=12), data)
    styled = dataclasses.replace(bandai, styles=["elderly"], max_takes=None)
    elderly = source_takes("bandai_namco", styled, data)
    assert elderly and {t.style for t in elderly} == {"elderly"}
    assert all("dataset-2" in t.name for t in elderly)
    backward = dataclasses.replace(bandai, contents=["walk-back"], max_takes=None)
    assert {t.content for t in source_takes("bandai_namco", backward, data)} == {"walk-back"}


def test_every_source_glob_matches_and_quick_profile_is_small(data, tmp_path):
    raw = yaml.safe_load((REPO_ROOT / "params.yaml").read_text())
    raw["profile"] = "paper"  # every take of every source
    paper_path = tmp_path / "params.yaml"
    paper_path.write_text(yaml.safe_dump(raw))
    paper = load_params(paper_path).data
    takes = select_takes(paper)
    assert {t.source for t in takes} == set(paper.sources)
    assert len({t.name for t in takes}) == len(takes)
    idle = [t for t in takes if t.source == "reactidle"]
    assert len(idle) == 10
    assert all(t.content is None and t.clip_s == paper.sources["reactidle"].clip_s for t in idle)
    if load_params().profile == "quick":  # the repository's params, whatever profile they pick
        quick = select_takes(data)
        counts = {k: sum(t.source == k for t in quick) for k in data.sources}
        assert counts == {"bandai_namco": 60, "avatargovr": 1, "motionmatching": 1, "reactidle": 1}
        assert all(counts.values())  # the quick set draws from every source (issue #9)


def test_glob_matching_nothing_names_source_and_glob(data):
    missing = dataclasses.replace(data.sources["reactidle"], path="data/mocap/none/*.bvh")
    broken = dataclasses.replace(data, sources={**data.sources, "idle2": missing})
    with pytest.raises(PimannError, match=r"none/\*\.bvh: data.sources.idle2: .*matches no file"):
        select_takes(broken)


def test_labels_that_disagree_with_the_name_are_reported(tmp_path, data):
    folder = tmp_path / "dataset-A"
    (folder / "cfg").mkdir(parents=True)
    (folder / "data").mkdir()
    (folder / "cfg/content_label.txt").write_text("dataset-1_walk\ndataset-1_run\n")
    (folder / "cfg/style_label.txt").write_text("dataset-1_normal\n")
    (folder / "data/dataset-1_walk_normal_001.bvh").write_text("")
    (folder / "data/dataset-1_walk_normal_001.json").write_text(
        json.dumps({"content": 1, "style": 0})
    )
    source = dataclasses.replace(
        data.sources["bandai_namco"], path=str(tmp_path / "*/data/*.bvh"), max_takes=None
    )
    with pytest.raises(PimannError, match="disagree") as error:
        source_takes("mine", source, data)
    assert "dataset-1_walk_normal_001.json" in str(error.value)


def test_cut_at_standing_pauses():
    rate = 30.0
    speed = np.full(int(60 * rate), 1.2)
    speed[int(17 * rate) : int(19 * rate)] = 0.02  # pause around 18 s
    speed[int(44 * rate) : int(45 * rate)] = 0.0  # pause around 44.5 s
    motion = walking_motion(speed, rate)
    np.testing.assert_allclose(motion.time[pause_centres(motion)], [18.0, 44.5], atol=0.1)
    spans = cut_take(motion, 20.0)
    assert len(spans) == 3
    assert spans[0][0] == 0 and spans[-1][1] == motion.n_frames
    assert all(a[1] == b[0] for a, b in zip(spans, spans[1:], strict=False))
    cuts = motion.time[[b for _, b in spans[:-1]]]
    np.testing.assert_allclose(cuts, [18.0, 44.5], atol=0.1)


def test_cut_evenly_without_pauses_and_keep_short_takes_whole():
    motion = walking_motion(np.full(1800, 1.0))  # 60 s at 30 fps, never standing
    spans = cut_take(motion, 20.0)
    np.testing.assert_allclose([b - a for a, b in spans], [600, 600, 600], atol=1)
    assert cut_take(motion, None) == [(0, 1800)]
    assert cut_take(motion, 70.0) == [(0, 1800)]
    # a pause near the start is not taken: clips stay at least a few seconds long
    speed = np.full(1800, 1.0)
    speed[30:60] = 0.0
    assert min(b - a for a, b in cut_take(walking_motion(speed), 20.0)) >= 4 * 30


def test_clip_names_and_slices_keep_foot_points():
    motion = walking_motion(np.full(1800, 1.0), feet=True)
    take = Take(Path("/x/long_take.bvh"), "src", None, None, None, clip_s=20.0)
    clips = take_clips(take, motion, take.clip_s)
    assert [c.name for c in clips] == ["long_take_c01", "long_take_c02", "long_take_c03"]
    assert clips[1].start_s == pytest.approx(20.0)
    assert [c.name for c in take_clips(take, motion, None)] == ["long_take"]
    part = slice_motion(motion, 600, 1200)
    assert part.n_frames == 600 and part.foot_points.shape == (600, 2, 2, 3)
    np.testing.assert_array_equal(part.foot_points, motion.foot_points[600:1200])
    np.testing.assert_array_equal(part.time, motion.time[600:1200])


def _fake_retarget(motion, params):
    n = motion.n_frames
    return Trajectory(
        time=motion.time - motion.time[0],
        base_position=np.zeros((n, 3)),
        base_quaternion_xyzw=np.tile([0.0, 0.0, 0.0, 1.0], (n, 1)),
        joint_positions=np.zeros((n, N_JOINTS)),
        source=Path(motion.source).name,
        rate_hz=params.rate_hz,
        attrs={"mirrored": False},
    )


def test_retarget_clip_labels_clips_and_the_split_keeps_takes_together(monkeypatch):
    import pimann.retarget as retarget
    import pimann.retarget.quality as quality

    params = load_params()
    motions = {
        "walk_a.bvh": walking_motion(np.full(50 * 60, 1.0), rate_hz=50.0),  # 60 s: 3 clips
        "walk_b.bvh": walking_motion(np.full(50 * 8, 1.0), rate_hz=50.0),  # 8 s: whole
    }
    for name in ("walk_c.bvh", "walk_d.bvh", "walk_e.bvh"):
        motions[name] = walking_motion(np.full(50 * 45, 1.0), rate_hz=50.0)
    monkeypatch.setattr(retarget, "read_take", lambda take: motions[take.path.name])
    monkeypatch.setattr(retarget, "retarget_motion", _fake_retarget)
    monkeypatch.setattr(quality, "frame_measures", lambda human, trajectory, p: {})
    collection = []
    for name in motions:
        take = Take(Path("/data") / name, "mine", None, "walk", "happy", clip_s=20.0)
        for clip_name, trajectory, _, seconds in retarget.retarget_clip(take, params):
            assert seconds >= 0.0
            collection += [(clip_name, trajectory), (f"{clip_name}_mirror", mirror(trajectory))]
    names = [n for n, _ in collection]
    assert names[:6] == [
        "walk_a_c01",
        "walk_a_c01_mirror",
        "walk_a_c02",
        "walk_a_c02_mirror",
        "walk_a_c03",
        "walk_a_c03_mirror",
    ]
    first = dict(collection)["walk_a_c02"]
    assert first.source == "walk_a.bvh"
    assert first.attrs["dataset"] == "mine" and first.attrs["take"] == "walk_a"
    assert (first.attrs["content"], first.attrs["style"]) == ("walk", "happy")
    assert first.attrs["clip_start_s"] == pytest.approx(20.0)
    assert first.time[0] == 0.0
    for seed in range(5):
        test = split_sources([t for _, t in collection], 0.3, seed)
        sides: dict[str, set[bool]] = {}
        for _, trajectory in collection:
            sides.setdefault(trajectory.attrs["take"], set()).add(trajectory.source in test)
        assert all(len(side) == 1 for side in sides.values())
        assert {True, False} == set().union(*sides.values())
