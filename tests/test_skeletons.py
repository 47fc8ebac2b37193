"""Any BVH skeleton: recognised by its joint names, its axes calibrated from the motion."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pimann.cli import main
from pimann.core.errors import PimannError
from pimann.core.params import SkeletonParams, load_params
from pimann.core.paths import mocap_dir
from pimann.core.robot import SEGMENTS
from pimann.core.trajectory import read_trajectory
from pimann.mocap.bvh import bvh_landmarks, parse_bvh, read_bvh
from pimann.mocap.skeletons import calibrate_segments, recognise_skeleton

BANDAI = (
    "bandai-namco/dataset/Bandai-Namco-Research-Motiondataset-1/data/dataset-1_walk_normal_001.bvh"
)


@dataclasses.dataclass
class Joint:
    name: str
    parent: int
    offset: np.ndarray  # cm, in the parent's local axes
    end_site: np.ndarray | None = None


def humanoid() -> list[Joint]:
    """An upright T-pose, Y up, X left, facing +Z, every local frame world-aligned (cm)."""
    joints: list[Joint] = []

    def add(name, parent, offset, end=None) -> int:
        joints.append(Joint(name, parent, np.array(offset, float), end and np.array(end, float)))
        return len(joints) - 1

    hips = add("Hips", -1, [0, 95, 0])
    chest = add("Chest", add("Spine", hips, [0, 10, 0]), [0, 12, 0])
    upper = add("UpperChest", chest, [0, 12, 0])
    add("Head", add("Neck", upper, [0, 15, 0]), [0, 8, 2], [0, 15, 0])
    for side, x in (("Left", 1.0), ("Right", -1.0)):
        shoulder = add(side + "Shoulder", upper, [4 * x, 12, 0])
        arm = add(side + "UpperArm", shoulder, [12 * x, 0, 0])
        add(
            side + "Hand",
            add(side + "LowerArm", arm, [28 * x, 0, 0]),
            [25 * x, 0, 0],
            [8 * x, 0, 0],
        )
    for side, x in (("Left", 1.0), ("Right", -1.0)):
        knee = add(side + "LowerLeg", add(side + "UpperLeg", hips, [9 * x, -5, 0]), [0, -42, 0])
        add(side + "Toes", add(side + "Foot", knee, [0, -42, 0]), [0, -7, 14], [0, 0, 5])
    return joints


def humanoid_motion(joints: list[Joint], n: int, rng) -> tuple[np.ndarray, np.ndarray]:
    """Root positions (n, 3) and local rotations (n, J, 3, 3) of a walk-like motion: knees
    and elbows bend about their hinge (plus some wobble), everything else sways."""
    t = np.arange(n) / 30.0
    phase = 2 * np.pi * 1.2 * t
    root = np.stack([2 * np.sin(phase), 95 + np.cos(2 * phase), 120 * t], axis=1)
    wobble = rng.uniform(-8, 8, (len(joints), 3))[None] * np.sin(
        phase[:, None, None] + rng.uniform(0, 6, (len(joints), 3))
    )
    rotvec = np.radians(wobble)
    names = [j.name for j in joints]
    for side, sign in (("Left", 1.0), ("Right", -1.0)):
        swing = np.sin(phase + (0 if sign > 0 else np.pi))
        rotvec[:, names.index(side + "LowerLeg"), 0] += np.radians(35 + 25 * swing)
        rotvec[:, names.index(side + "LowerArm"), 1] -= sign * np.radians(40 + 20 * swing)
    local = Rotation.from_rotvec(rotvec.reshape(-1, 3)).as_matrix().reshape(n, len(joints), 3, 3)
    return root, local


def bvh_text(joints, root, local, frames_q=None, orders=None) -> str:
    """A BVH file of the motion; `frames_q` (J, 3, 3) turns every joint's local frame by a
    constant rotation (offsets and channels re-expressed: the same motion on another rig)."""
    n_joints = len(joints)
    q = np.broadcast_to(np.eye(3), (n_joints, 3, 3)) if frames_q is None else frames_q
    orders = orders or ["ZXY"] * n_joints
    children = {k: [c for c, j in enumerate(joints) if j.parent == k] for k in range(n_joints)}
    lines = ["HIERARCHY"]

    def write(k: int, depth: int) -> None:
        joint, pad = joints[k], "  " * depth
        parent_q = np.eye(3) if joint.parent < 0 else q[joint.parent]
        offset = parent_q.T @ joint.offset
        rotations = " ".join(f"{axis}rotation" for axis in orders[k])
        channels = (
            f"6 Xposition Yposition Zposition {rotations}" if depth == 0 else f"3 {rotations}"
        )
        lines.extend([f"{pad}{'ROOT' if depth == 0 else 'JOINT'} {joint.name}", pad + "{"])
        lines.extend(
            [
                f"{pad}  OFFSET " + " ".join(f"{v:.12g}" for v in offset),
                f"{pad}  CHANNELS {channels}",
            ]
        )
        for child in children[k]:
            write(child, depth + 1)
        if joint.end_site is not None:
            end = " ".join(f"{v:.12g}" for v in q[k].T @ joint.end_site)
            lines.extend([f"{pad}  End Site", pad + "  {", f"{pad}    OFFSET {end}", pad + "  }"])
        lines.append(pad + "}")

    write(0, 0)
    columns = [root]
    for k, joint in enumerate(joints):
        parent_q = np.eye(3) if joint.parent < 0 else q[joint.parent]
        turned = parent_q.T @ local[:, k] @ q[k]
        columns.append(Rotation.from_matrix(turned).as_euler(orders[k], degrees=True))
    values = np.concatenate(columns, axis=1)
    lines += ["MOTION", f"Frames: {len(root)}", "Frame Time: 0.0333333333333"]
    lines += [" ".join(f"{v:.15g}" for v in row) for row in values]
    return "\n".join(lines) + "\n"


def test_arbitrary_rest_axes_read_to_the_same_segments_and_robot_motion(tmp_path, rng):
    from pimann.retarget import retarget_motion

    joints = humanoid()
    root, local = humanoid_motion(joints, 20, rng)
    plain, turned = tmp_path / "plain.bvh", tmp_path / "turned.bvh"
    plain.write_text(bvh_text(joints, root, local))
    frames_q = Rotation.random(len(joints), random_state=7).as_matrix()
    orders = [str(rng.choice(["XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"])) for _ in joints]
    turned.write_text(bvh_text(joints, root, local, frames_q, orders))
    a, b = read_bvh(plain), read_bvh(turned)
    np.testing.assert_allclose(b.orientations, a.orientations, atol=1e-6)
    np.testing.assert_allclose(b.segment_positions, a.segment_positions, atol=1e-6)
    np.testing.assert_allclose(b.foot_points, a.foot_points, atol=1e-6)
    # the axis-aligned rig's T-pose is the XSens T-pose: identity once calibrated
    pelvis = a.segment("Pelvis")
    assert np.degrees(np.arccos(pelvis[:, 2, 2])).max() < 10.0  # upright, swaying
    assert a.pelvis_position[-1, 0] - a.pelvis_position[0, 0] > 0.7  # cm -> m, walks along x
    params = load_params().retarget
    robot_a, robot_b = retarget_motion(a, params), retarget_motion(b, params)
    np.testing.assert_allclose(robot_b.joint_positions, robot_a.joint_positions, atol=1e-6)
    np.testing.assert_allclose(robot_b.base_position, robot_a.base_position, atol=1e-6)


def knee_off_axis(motion, side: str, min_deg: float = 10.0) -> float:
    """Median angle between the knee's rotation axis and the calibrated thigh's y axis."""
    thigh, shank = motion.segment(side + "UpperLeg"), motion.segment(side + "LowerLeg")
    knee = Rotation.from_matrix(np.swapaxes(thigh, 1, 2) @ shank).as_rotvec()
    angle = np.linalg.norm(knee, axis=1)
    flexed = angle > np.radians(min_deg)
    return float(np.median(np.degrees(np.arccos(knee[flexed, 1] / angle[flexed]))))


def ankle_pitch(motion, side: str) -> float:
    """Mean ankle pitch (deg) of the foot relative to the shank."""
    shank, foot = motion.segment(side + "LowerLeg"), motion.segment(side + "Foot")
    return float(
        np.degrees(Rotation.from_matrix(np.swapaxes(shank, 1, 2) @ foot).as_rotvec()[:, 1].mean())
    )


def tilt(motion, segment: str) -> np.ndarray:
    return np.degrees(np.arccos(np.clip(motion.segment(segment)[:, 2, 2], -1, 1)))


def heading_along_velocity(motion) -> float:
    """Median cosine between the pelvis x axis and its horizontal velocity (moving frames)."""
    velocity = np.gradient(motion.pelvis_position, motion.time, axis=0)[:, :2]
    speed = np.linalg.norm(velocity, axis=1)
    forward = motion.segment("Pelvis")[:, :2, 0]
    moving = speed > 0.3
    cos = (forward[moving] * velocity[moving]).sum(1) / speed[moving]
    return float(np.median(cos / np.linalg.norm(forward[moving], axis=1)))


def feet_sit_sensibly(motion) -> None:
    """Left foot at the pelvis's left, toes ahead of the heels, soles flat on median."""
    pelvis = motion.segment("Pelvis")
    heels, toes = motion.foot_points[:, :, 0], motion.foot_points[:, :, 1]
    lateral = np.einsum("tji,tj->ti", pelvis, heels[:, 0] - heels[:, 1])
    assert np.median(lateral[:, 1]) > 0.0  # Bandai's actor walks with the ankles 3 cm apart
    ahead = np.einsum("tji,tsj->tsi", pelvis, toes - heels)
    assert (np.median(ahead[..., 0], axis=0) > 0.05).all()
    for side in ("Left", "Right"):
        pitch = np.degrees(np.arcsin(motion.segment(side + "Foot")[:, 2, 0]))
        assert abs(np.median(pitch)) < 3.0


def test_bandai_namco_reads_and_calibrates():
    motion = read_bvh(mocap_dir() / BANDAI)
    assert motion.n_frames == 195 and motion.rate_hz == pytest.approx(30.0, rel=1e-4)
    for side in ("Left", "Right"):
        assert knee_off_axis(motion, side) < 1.0  # the target: ~0.5 deg
        assert abs(ankle_pitch(motion, side)) < 6.0
    assert tilt(motion, "T8").mean() < 4.0 and tilt(motion, "Pelvis").mean() < 5.0
    assert heading_along_velocity(motion) > 0.95
    assert 0.8 < motion.pelvis_position[:, 2].mean() < 1.0  # cm detected
    feet_sit_sensibly(motion)


def test_reactidle_reads_and_calibrates():
    """Standing idle in metres, Blender names: knees hardly bend, so no knee-axis check."""
    motion = read_bvh(mocap_dir() / "reactidle/000_genuine.bvh")
    assert motion.rate_hz == pytest.approx(24.0, rel=1e-3)
    assert tilt(motion, "T8").mean() < 6.0 and tilt(motion, "Pelvis").mean() < 5.0
    height = motion.pelvis_position[:, 2] - motion.foot_points[..., 0, 2].min(axis=1)
    assert 0.5 < np.median(height) < 0.8  # metres: a 0.62 m leg
    feet_sit_sensibly(motion)


def test_xsens_mvn_reads_and_its_tpose_is_identity():
    """A crouched VR walk (knees ~45 deg, T8 ~30 deg forward all take long), so the trunk
    is checked on the same skeleton's T-pose file with the take's calibration instead."""
    take = mocap_dir() / "avatargovr/locomotion_vr_mid.bvh"
    motion = read_bvh(take)
    for side in ("Left", "Right"):
        assert knee_off_axis(motion, side) < 3.0
    assert heading_along_velocity(motion) > 0.8
    feet_sit_sensibly(motion)
    calibration = calibrate_segments(bvh_landmarks(parse_bvh(take)))
    tpose = bvh_landmarks(parse_bvh(mocap_dir() / "avatargovr/tpose.bvh"))
    segments = (tpose.rotations @ calibration)[0]  # frame 0 is the T-pose
    # head (mean pose over a head-down take) and forearm twist (no landmark) are not checked
    checked = [k for k, s in enumerate(SEGMENTS) if s != "Head" and not s.endswith("ForeArm")]
    yaw = Rotation.from_matrix(segments[0]).as_euler("ZYX")[0]
    upright = Rotation.from_euler("z", -yaw).as_matrix() @ segments[checked]
    angles = np.degrees(np.linalg.norm(Rotation.from_matrix(upright).as_rotvec(), axis=1))
    left_arm_y = segments[SEGMENTS.index("LeftUpperArm"), :, 1]
    assert abs(np.degrees(np.arcsin(left_arm_y[2]))) < 5.0  # arms horizontal
    assert np.median(angles) < 4.0, dict(
        zip(np.array(SEGMENTS)[checked], angles.round(1), strict=True)
    )


def test_unity_humanoid_reads_and_calibrates():
    motion = read_bvh(mocap_dir() / "motionmatching-locomotion/locomotion.bvh")
    assert motion.rate_hz == pytest.approx(60.0, rel=1e-4)
    for side in ("Left", "Right"):
        assert knee_off_axis(motion, side) < 6.0
        assert abs(ankle_pitch(motion, side)) < 15.0  # walking and running
    assert np.median(tilt(motion, "T8")) < 8.0  # leans into the running
    assert heading_along_velocity(motion) > 0.9
    feet_sit_sensibly(motion)


def test_recognises_prefixed_mixamo_and_cmu_names():
    limbs = ["UpLeg", "Leg", "Foot", "ToeBase", "Arm", "ForeArm"]
    mixamo = ["Hips", "Spine", "Spine1", "Spine2", "Neck", "Head"]
    mixamo += [side + limb for side in ("Left", "Right") for limb in limbs]
    skeleton = recognise_skeleton(["mixamorig:" + name for name in mixamo])
    assert skeleton.segments["T8"] == "mixamorig:Spine2"
    assert skeleton.toes == {
        "LeftFoot": "mixamorig:LeftToeBase",
        "RightFoot": "mixamorig:RightToeBase",
    }
    limbs = ["Thigh", "Shin", "Foot", "Shldr", "ForeArm"]
    cmu = ["hip", "abdomen", "chest", "neck", "head"]
    cmu += [side + limb for side in ("l", "r") for limb in limbs]
    skeleton = recognise_skeleton(cmu)
    assert skeleton.segments["LeftUpperArm"] == "lShldr" and skeleton.toes is None


def test_unknown_skeleton_names_unmapped_segments_and_params_key(tmp_path):
    text = (mocap_dir() / BANDAI).read_text().replace("UpperLeg_", "Thigh_")
    path = tmp_path / "renamed.bvh"
    path.write_text(text)
    with pytest.raises(PimannError) as error:
        read_bvh(path)
    message = str(error.value)
    assert "renamed.bvh" in message and len(message.splitlines()) == 1
    assert "LeftUpperLeg, RightUpperLeg" in message and "bandai_namco" in message
    assert "data.skeletons.<name>.segments" in message and "skeleton: <name>" in message
    # the map the message asks for reads it
    segments = recognise_skeleton([j.name for j in parse_bvh(mocap_dir() / BANDAI).joints])
    renamed = {s: j.replace("UpperLeg_", "Thigh_") for s, j in segments.segments.items()}
    motion = read_bvh(path, SkeletonParams(renamed, None, None))
    np.testing.assert_allclose(motion.orientations, read_bvh(mocap_dir() / BANDAI).orientations)


def test_rate_override_changes_the_time_axis(tmp_path, capsys):
    lines = (mocap_dir() / BANDAI).read_text().splitlines()
    start = lines.index("MOTION")
    short = tmp_path / "short.bvh"
    short.write_text(
        "\n".join(lines[: start + 1] + ["Frames: 40"] + lines[start + 2 : start + 43]) + "\n"
    )
    assert np.diff(read_bvh(short, rate_hz=60.0).time) == pytest.approx(1 / 60)
    assert main(["mocap-info", str(short)]) == 0
    assert json.loads(capsys.readouterr().out)["rate_hz"] == pytest.approx(30.0, rel=1e-4)
    durations = []
    for extra in ([], ["--rate", "60"]):
        out = tmp_path / f"out{len(extra)}.h5"
        assert main(["retarget", str(short), "-o", str(out), *extra]) == 0
        trajectory = read_trajectory(out)
        durations.append(trajectory.time[-1] - trajectory.time[0])
    assert durations[1] == pytest.approx(durations[0] / 2, abs=0.03)
    with pytest.raises(PimannError, match="rate must be positive"):
        read_bvh(short, rate_hz=0.0)


def test_cli_unknown_skeleton_is_one_line(capsys):
    assert main(["mocap-info", str(mocap_dir() / BANDAI), "--skeleton", "nope"]) == 2
    err = capsys.readouterr().err.strip()
    assert "unknown skeleton 'nope'" in err and len(err.splitlines()) == 1


def test_hyperextended_standing_knees_keep_the_thighs_facing_forward(tmp_path, rng):
    """A standing rig whose straight knees bend 3 deg backwards (7 of the 10 ReActIdle takes):
    the flexion axis points right, and taken as it is it would turn the thighs half round."""
    joints = humanoid()
    n = 60
    root = np.tile([0.0, 95.0, 0.0], (n, 1))
    rotvec = np.radians(rng.uniform(-1, 1, (n, len(joints), 3)))
    names = [j.name for j in joints]
    for side in ("Left", "Right"):
        rotvec[:, names.index(side + "LowerLeg"), 0] = np.radians(-3.0)
    local = Rotation.from_rotvec(rotvec.reshape(-1, 3)).as_matrix().reshape(n, len(joints), 3, 3)
    path = tmp_path / "standing.bvh"
    path.write_text(bvh_text(joints, root, local))
    motion = read_bvh(path)
    pelvis_forward = motion.segment("Pelvis")[:, :, 0]
    for side in ("Left", "Right"):
        thigh_forward = motion.segment(side + "UpperLeg")[:, :, 0]
        cos = np.einsum("ti,ti->t", thigh_forward, pelvis_forward)
        assert np.degrees(np.arccos(np.clip(cos, -1, 1))).max() < 10.0, side
