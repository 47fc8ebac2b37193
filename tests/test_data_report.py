"""The data report on synthetic trajectories with closed-form answers (real ergoCub FK)."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
from builders import EVALUATE_PARAMS, RATE, make_trajectory

from pimann.core.params import load_params
from pimann.core.robot import STANDING_JOINTS
from pimann.core.trajectory import Trajectory, write_collection
from pimann.evaluate import data_report as dr
from pimann.evaluate import data_report_output as dro
from pimann.evaluate.metrics import trajectory_metrics
from pimann.learn import motion_classes as mc


@pytest.fixture(scope="module")
def params():
    return dataclasses.replace(load_params(), evaluate=EVALUATE_PARAMS)


def line(speed: float, direction: float, seconds: float, start=(0.0, 0.0)) -> np.ndarray:
    """(T, 2) positions moving at `speed` along the world angle `direction`."""
    t = np.arange(round(seconds * RATE)) / RATE
    return np.asarray(start) + speed * t[:, None] * [math.cos(direction), math.sin(direction)]


def classes_of(trajectory: Trajectory) -> set[str]:
    return set(np.asarray(dr.CLASSES)[dr.motion_classes(trajectory)])


# ----------------------------------------------------------------------------- classes


@pytest.mark.parametrize(
    ("angle", "expected"),
    [(0.0, "forward"), (math.pi, "backward"), (math.pi / 2, "side"), (-math.pi / 2, "side"),
     (math.pi / 4, "diagonal"), (-3 * math.pi / 4, "diagonal")],
)  # fmt: skip
def test_constant_velocity_is_classified_in_the_heading_frame(angle, expected):
    heading = 0.7  # the classes are relative to the heading, not to the world axes
    trajectory = make_trajectory(line(0.8, heading + angle, 4.0), yaw=heading)
    assert classes_of(trajectory) == {expected}
    velocity, yaw_rate = mc.base_motion(trajectory)
    np.testing.assert_allclose(
        velocity, np.tile([0.8 * math.cos(angle), 0.8 * math.sin(angle)], (200, 1)), atol=1e-9
    )
    np.testing.assert_allclose(yaw_rate, 0.0, atol=1e-9)


def test_standing_turning_and_turning_in_place():
    still = np.zeros((200, 2))
    assert classes_of(make_trajectory(still, yaw=0.3)) == {"standing"}
    spin = 0.5 * np.arange(200) / RATE
    assert classes_of(make_trajectory(still, yaw=spin)) == {"turning_in_place"}
    # forward along a circle: yaw rate 0.5 rad/s at 0.8 m/s
    path = np.column_stack([np.sin(spin), 1 - np.cos(spin)]) * 0.8 / 0.5
    assert classes_of(make_trajectory(path, yaw=spin)) == {"turning"}
    # a slow drift of the base below 0.1 m/s is standing
    assert classes_of(make_trajectory(line(0.05, 0.0, 4.0))) == {"standing"}


def test_transitions_drop_short_runs():
    moving = np.zeros(100, bool)
    moving[20:50] = True  # a start at 20, a stop at 50
    moving[60:63] = True  # jitter: 3 frames
    moving[80:] = True  # a start at 80
    moving[90:92] = False  # jitter inside the walk
    starts, stops = dr.transitions(moving, min_frames=5)
    assert starts.tolist() == [20, 80]
    assert stops.tolist() == [50]
    assert [len(a) for a in dr.transitions(moving, min_frames=40)] == [0, 0]


def test_start_stop_sequence_is_counted(params):
    """stand 2 s, walk 3 s, stand 2 s (with a 0.3 s weight shift of 5 cm), walk 2 s."""
    parts = [np.zeros((100, 2)), line(0.8, 0.0, 3.0)]
    parts.append(np.tile(parts[-1][-1] + [0.8 / RATE, 0], (100, 1)))
    parts[-1][40:55, 1] += np.linspace(0.0, 0.05, 15)
    parts[-1][55:, 1] += 0.05
    parts.append(line(0.8, 0.0, 2.0, start=parts[-1][-1] + [0.8 / RATE, 0]))
    trajectory = make_trajectory(np.concatenate(parts))
    frames = dr.clip_frames("clip", trajectory, params)
    assert frames["start"].sum() == 2
    assert frames["stop"].sum() == 1
    minutes = dr.summarise(frames)["minutes"]
    assert minutes["forward"] == pytest.approx(5.0 / 60.0, abs=1.5 / 60.0)
    assert minutes["standing"] == pytest.approx(4.0 / 60.0, abs=1.5 / 60.0)


# ----------------------------------------------------------------------------- foot metrics


def test_sliding_of_a_foot_sliding_at_a_known_speed(params):
    """Both feet on the floor slide at u: the per-500-frame total is 500 u / sqrt(3)."""
    u, n = 0.3, 600  # 12 s: enough for a per-class figure
    contacts = np.zeros((n, 2), bool)
    contacts[:, 0] = True  # the file: left always, right every other 25 frames
    contacts[(np.arange(n) // 25) % 2 == 0, 1] = True
    trajectory = make_trajectory(line(u, 0.0, n / RATE), contacts=contacts)
    frames = dr.clip_frames("clip", trajectory, params)
    summary = dr.summarise(frames)
    rule, file = summary["sliding"]["evaluate_rule"], summary["sliding"]["file_contacts"]
    # the evaluate stage's velocity level: the base holds the lower foot and the still joints
    # carry the other with it, so a rigid glide does not slide (the glides below see it)
    assert rule["linear"] == pytest.approx(0.0, abs=1e-9)
    assert rule["angular"] == pytest.approx(0.0, abs=1e-9)
    assert file["linear"] == pytest.approx(0.0, abs=1e-9)
    assert rule["per_class"]["forward"]["linear"] == pytest.approx(rule["linear"])
    # the file's right foot is down every other 25 frames: half the frames have both down
    assert file["per_class"]["forward"]["double_support"] == pytest.approx(0.5, abs=0.02)
    # the glide percentile sees the same sliding feet
    assert summary["glides"]["p95_m_s"] == pytest.approx(u, rel=1e-6)
    assert summary["glides"]["fraction_above_target"] == 1.0
    # L_B of a rigidly moving robot with still joints: |v|^2 / 6 for either support
    assert summary["l_b"]["lower_sole"]["mean"] == pytest.approx(u * u / 6, rel=1e-4)
    assert summary["l_b"]["lower_sole"]["samples"] == n - 51 - 61  # the windows drop the ends
    settled = summary["l_b"]["data_contacts"]["mean"]
    assert settled == pytest.approx(u * u / 6, rel=1e-4)


def test_sliding_is_the_evaluate_stage_metric(robot, params, rng):
    """Per clip, the frames sum to pimann.evaluate.metrics' total RMSE, under either contact
    rule."""
    n = 150
    joints = STANDING_JOINTS + 0.1 * np.sin(np.arange(n)[:, None] / 9.0 + rng.uniform(0, 6, 26))
    contacts = rng.random((n, 2)) < 0.6
    trajectory = make_trajectory(
        line(0.4, 0.2, n / RATE), yaw=0.2, contacts=contacts, joints=joints
    )
    frames = dr.clip_frames("clip", trajectory, params)
    file = trajectory_metrics(trajectory, robot, params.evaluate, params.contacts)
    detected = trajectory_metrics(
        dataclasses.replace(trajectory, contacts=None), robot, params.evaluate, params.contacts
    )
    assert detected["contacts_source"] == "detected"
    for kind in ("linear", "angular"):
        assert frames[f"{kind}_file_contacts"].sum() == pytest.approx(
            file[f"support_rmse_{kind}_total"], rel=1e-12
        )
        assert frames[f"{kind}_evaluate_rule"].sum() == pytest.approx(
            detected[f"support_rmse_{kind}_total"], rel=1e-12
        )


def test_gliding_touchdown_appears_in_the_glide_percentile(params):
    """Fly fast at 10 cm, come down vertically, glide 0.4 s at u on the floor, stand."""
    u = 0.5
    fly = line(3.0, 0.0, 0.5)
    down = np.tile(fly[-1] + [3.0 / RATE, 0], (25, 1))
    glide = line(u, 0.0, 0.4, start=down[-1] + [u / RATE, 0])
    stand = np.tile(glide[-1] + [u / RATE, 0], (150, 1))
    xy = np.concatenate([fly, down, glide, stand])
    z = np.concatenate([np.full(25, 0.1), np.linspace(0.1, 0.0, 26)[1:], np.zeros(170)])
    frames = dr.clip_frames("clip", make_trajectory(xy, z=z), params)
    glides = dr.glides(frames)
    assert glides["p95_m_s"] == pytest.approx(u, rel=1e-6)  # not 3 m/s: flying corners are out
    # all 8 corners of the glide's 20 frames and of the two frames that blend it with the
    # touchdown and the stand (u / 2), among every corner sample within 5 mm of the floor
    assert glides["fraction_above_target"] == pytest.approx(22 * 8 / glides["samples"])
    still = dr.glides(dr.clip_frames("clip", make_trajectory(np.zeros((100, 2))), params))
    assert still["p95_m_s"] == pytest.approx(0.0, abs=1e-9)


def test_double_support_fraction_of_walking_frames(params):
    n = 300
    phase = np.arange(n) % 10  # both feet 3 frames in 10, then left 2, then right 5
    contacts = np.column_stack([phase < 5, (phase < 3) | (phase >= 5)])
    walk = make_trajectory(line(0.8, 0.0, n / RATE), contacts=contacts)
    stand = make_trajectory(np.zeros((100, 2)), contacts=np.zeros((100, 2), bool))
    frames = dr.collection_frames([("walk", walk), ("stand", stand)], params)
    double = dr.summarise(frames)["double_support"]
    assert double["file_contacts"] == pytest.approx(0.3)  # standing frames are left out
    assert double["evaluate_rule"] == pytest.approx(1.0)  # both feet stay on the floor


def test_floor_reports_a_sole_in_the_floor_and_flight(params):
    """The standing robot sunk 2 cm for 10 of 100 frames (its soles rest at 0 otherwise), and
    no foot down by the file's flags for 5 of them."""
    z = np.zeros(100)
    z[40:50] = -0.02
    contacts = np.ones((100, 2), bool)
    contacts[60:65] = False
    frames = dr.clip_frames(
        "clip", make_trajectory(np.zeros((100, 2)), z=z, contacts=contacts), params
    )
    floor = dr.floor(frames)
    resting = frames["lowest_corner"].iloc[0]  # the standing pose's soles: within 0.1 mm of 0
    assert abs(resting) < 1e-4
    assert floor["lowest_corner_m"] == pytest.approx(resting - 0.02, abs=1e-9)
    assert floor["below_floor_share"] == pytest.approx(0.1)
    assert floor["flight_share"] == pytest.approx(0.05)
    bare = dr.floor(dr.clip_frames("clip", make_trajectory(np.zeros((20, 2))), params))
    assert bare["flight_share"] is None and bare["below_floor_share"] == 0.0


def test_below_the_floor_is_the_retarget_quality_check_threshold():
    from pimann.retarget.quality import FLOOR_TOLERANCE

    assert dr.BELOW_FLOOR == -FLOOR_TOLERANCE


# ----------------------------------------------------------------------------- the report


def test_report_per_source_with_mirrors_and_outputs(params, tmp_path):
    walk = make_trajectory(
        line(0.8, 0.0, 6.0),
        contacts=np.ones((300, 2), bool),
        dataset="bandai_namco",
        content="walk",
    )
    mirror = dataclasses.replace(walk, attrs={**walk.attrs, "mirrored": True})
    side = make_trajectory(
        line(0.3, math.pi / 2, 6.0),
        contacts=np.ones((300, 2), bool),
        dataset="avatargovr",
        content="",
    )
    collection = tmp_path / "walking.h5"
    write_collection(collection, [("walk", walk), ("walk_mirror", mirror), ("side", side)])
    report = dr.data_report(collection, params)
    sources = report["sources"]
    assert list(sources) == ["avatargovr", "bandai_namco", "total"]
    bandai = sources["bandai_namco"]
    assert (bandai["clips"], bandai["clips_with_mirrors"]) == (1, 2)
    assert bandai["minutes"]["forward"] == pytest.approx(0.1)
    assert bandai["minutes_with_mirrors"]["forward"] == pytest.approx(0.2)
    assert bandai["label_minutes"] == {"walk": pytest.approx(0.1)}
    assert sources["avatargovr"]["minutes"]["side"] == pytest.approx(0.1)
    assert sources["total"]["label_minutes"]["unlabelled"] == pytest.approx(0.1)
    assert report["profile"] == params.profile
    assert "bandai_namco" in report["params"]["data"]["sources"]
    table = dro.report_table(report)
    assert "| bandai_namco |" in table and "authors" in table
    paths = [tmp_path / "out" / n for n in ("report.json", "report.md", "report.png")]
    dro.write_report(report, *paths, params.figures)
    assert json.loads(paths[0].read_text())["sources"]["total"]["frames"] == 600
    assert paths[1].read_text() == table
    assert paths[2].stat().st_size > 1000


def test_clips_without_dataset_attr_are_all(params):
    frames = dr.collection_frames([("c", make_trajectory(np.zeros((100, 2))))], params)
    assert set(frames["dataset"]) == {dr.ALL}
    summary = dr.summarise(frames)
    assert summary["sliding"]["file_contacts"] is None  # no flags in the file
    assert summary["l_b"]["data_contacts"]["samples"] == 0


def test_data_report_stage_tracks_only_the_metric_keys_it_reads() -> None:
    """dvc.yaml's data_report params name exactly the evaluate keys the report records, and
    each is a field of the evaluate section, so editing what the claims feature never reruns it."""
    import yaml

    from pimann.core.params import load_params
    from pimann.core.paths import PACKAGE_CHECKOUT

    stages = yaml.safe_load((PACKAGE_CHECKOUT / "dvc.yaml").read_text())["stages"]
    listed = [p for p in stages["data_report"]["params"] if str(p).startswith("evaluate")]
    assert listed == [f"evaluate.{key}" for key in dr.METRIC_KEYS]
    evaluate = load_params(PACKAGE_CHECKOUT / "params.yaml").evaluate
    assert all(hasattr(evaluate, key) for key in dr.METRIC_KEYS)
