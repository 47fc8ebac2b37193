"""Pictures of a trajectory: the robot as a stick figure, beside the person it was retargeted from.

A person has to be able to see at a glance that the robot walks like the person did, so the
two are drawn side by side at one scale, seen from the same fixed world direction, each
panel following its own subject (the robot covers ~0.63x the human's distance, so one shared
world view would pull them apart). Left limbs are blue and right limbs red in both panels.

Drawing is a hand-made orthographic projection onto plain 2-D matplotlib axes rather than
mplot3d: a stick figure needs no hidden-surface removal beyond drawing far bones first, and
reusing one Agg figure whose artists are only updated keeps a frame at a few milliseconds.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np
import pinocchio as pin
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection, PolyCollection
from matplotlib.colors import to_rgba
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from tqdm import tqdm

from pimann.atomic import atomic_path
from pimann.contacts import detect_contacts, trajectory_configurations
from pimann.errors import PimannError
from pimann.mocap.human_motion import HumanMotion
from pimann.mocap.mirror import mirror_human
from pimann.params import SkeletonParams
from pimann.robot import LEFT_SOLE, RIGHT_SOLE, SEGMENTS, SOLE_CORNERS, Robot, load_robot
from pimann.trajectory import Trajectory, read_trajectory

log = logging.getLogger(__name__)

FORMATS = (".gif", ".mp4", ".png")
LEFT_COLOUR = "#1f5fbf"
RIGHT_COLOUR = "#d62728"
CENTRE_COLOUR = "#3a3a3a"
BACKGROUND = "#ffffff"
GRID_COLOUR = "#b8b8b8"
PATH_COLOUR = "#2ca02c"

# ergoCub's sole (pimann.robot), corners in drawing order around the rectangle
FOOT_CORNERS = SOLE_CORNERS[[0, 1, 3, 2]]
ROBOT_HEAD_TOP = np.array([0.0, 0.0, 0.2])  # head frame (z up) to the top of the head, m

# Human end points in segment frames (XSens T-pose convention: x forward, y left, z up), for
# a person whose thigh + shank measure HUMAN_LEG_LENGTH; scaled to the actual legs.
HUMAN_LEG_LENGTH = 0.88
HUMAN_ENDS = {
    "HeadTop": ("Head", (0.0, 0.0, 0.2)),
    "LeftHand": ("LeftForeArm", (0.0, 0.22, 0.0)),
    "RightHand": ("RightForeArm", (0.0, -0.22, 0.0)),
    "LeftToe": ("LeftFoot", (0.16, 0.0, -0.07)),
    "RightToe": ("RightFoot", (0.16, 0.0, -0.07)),
}
HUMAN_BONES = (
    ("Pelvis", "T8"), ("T8", "Head"), ("Head", "HeadTop"),
    ("Pelvis", "LeftUpperLeg"), ("LeftUpperLeg", "LeftLowerLeg"),
    ("LeftLowerLeg", "LeftFoot"), ("LeftFoot", "LeftToe"),
    ("Pelvis", "RightUpperLeg"), ("RightUpperLeg", "RightLowerLeg"),
    ("RightLowerLeg", "RightFoot"), ("RightFoot", "RightToe"),
    ("T8", "LeftUpperArm"), ("LeftUpperArm", "LeftForeArm"), ("LeftForeArm", "LeftHand"),
    ("T8", "RightUpperArm"), ("RightUpperArm", "RightForeArm"), ("RightForeArm", "RightHand"),
)  # fmt: skip

# Camera: fixed world direction, from the subject's right front, slightly above.
AZIMUTH_DEG = -60.0
ELEVATION_DEG = 15.0
VIEW_BELOW = 0.45  # m of view below the floor point under the subject
VIEW_ABOVE = 1.95  # m of view above it (ergoCub is 1.6 m, the person ~1.8 m)
GRID_STEP = 0.5
GRID_RADIUS = 3.0
GRID_PIECE = 1.0


def _side_colour(name: str) -> str:
    if name.startswith(("l_", "Left")):
        return LEFT_COLOUR
    if name.startswith(("r_", "Right")):
        return RIGHT_COLOUR
    return CENTRE_COLOUR


@dataclasses.dataclass
class Skeleton:
    """One subject's drawing data for the rendered frames (N of them)."""

    title: str
    points: np.ndarray  # (N, P, 3) world positions
    bones: np.ndarray  # (B, 2) indices into points, (parent end, child end)
    bone_colours: list[str]  # (B,)
    path: np.ndarray  # (M, 2) ground path of the base over the whole clip
    path_index: np.ndarray  # (N,) index into path of each rendered frame
    feet: np.ndarray | None = None  # (N, 2, 4, 3) sole rectangles, left then right
    contacts: np.ndarray | None = None  # (N, 2) bool

    @property
    def centre(self) -> np.ndarray:
        """(N, 2) ground point each panel follows."""
        return self.path[self.path_index]


def robot_skeleton(
    trajectory: Trajectory, frames: np.ndarray, robot: Robot | None = None
) -> Skeleton:
    """Joint origins, sole rectangles, hands and head top of the robot at `frames`."""
    robot = robot or load_robot("retarget")
    model = robot.model
    data = model.createData()  # private: the cached Robot's data may be in use elsewhere
    joint_ids = list(range(1, model.njoints))  # the free flyer and the 26 joints
    index = {j: k for k, j in enumerate(joint_ids)}
    bones = [(index[model.parents[j]], index[j]) for j in joint_ids if model.parents[j] > 0]
    colours = [_side_colour(model.names[j]) for j in joint_ids if model.parents[j] > 0]
    leaves = [
        (LEFT_SOLE, None),
        (RIGHT_SOLE, None),
        ("l_hand_palm", None),
        ("r_hand_palm", None),
        ("head", ROBOT_HEAD_TOP),
    ]
    leaf_ids = [robot.frame_id(name) for name, _ in leaves]
    for k, (name, _) in enumerate(leaves):
        bones.append((index[model.frames[leaf_ids[k]].parentJoint], len(joint_ids) + k))
        colours.append(_side_colour(name))
    sole_ids = leaf_ids[:2]

    points = np.empty((len(frames), len(joint_ids) + len(leaves), 3))
    feet = np.empty((len(frames), 2, 4, 3))
    configurations = trajectory_configurations(robot, trajectory)
    for n, t in enumerate(frames):
        q = configurations[t]
        pin.forwardKinematics(model, data, q)
        for k, j in enumerate(joint_ids):
            points[n, k] = data.oMi[j].translation
        for k, ((_, offset), fid) in enumerate(zip(leaves, leaf_ids, strict=True)):
            placement = pin.updateFramePlacement(model, data, fid)
            tip = placement.translation
            if offset is not None:
                tip = tip + placement.rotation @ offset
            points[n, len(joint_ids) + k] = tip
        for side, fid in enumerate(sole_ids):
            placement = data.oMf[fid]
            feet[n, side] = FOOT_CORNERS @ placement.rotation.T + placement.translation
    if trajectory.contacts is not None:
        contacts = np.asarray(trajectory.contacts, dtype=bool)[frames]
    else:  # the evaluation's own detector, so the picture agrees with the metrics
        contacts = detect_contacts(robot, trajectory)[frames]
    return Skeleton(
        title="ergoCub",
        points=points,
        bones=np.array(bones),
        bone_colours=colours,
        path=np.asarray(trajectory.base_position)[:, :2],
        path_index=np.asarray(frames),
        feet=feet,
        contacts=contacts,
    )


def human_skeleton(human: HumanMotion, frames: np.ndarray) -> Skeleton:
    """The person's segment origins plus head top, hands and toes at `frames`."""
    positions = human.segment_positions[frames]
    seg = {name: k for k, name in enumerate(SEGMENTS)}
    first = human.segment_positions[0]
    leg = np.mean(
        [
            np.linalg.norm(first[seg[f"{s}UpperLeg"]] - first[seg[f"{s}LowerLeg"]])
            + np.linalg.norm(first[seg[f"{s}LowerLeg"]] - first[seg[f"{s}Foot"]])
            for s in ("Left", "Right")
        ]
    )
    scale = leg / HUMAN_LEG_LENGTH if leg > 0 else 1.0
    ends = [
        positions[:, seg[parent]]
        + scale * np.einsum("nij,j->ni", human.orientations[frames, seg[parent]], offset)
        for parent, offset in HUMAN_ENDS.values()
    ]
    points = np.concatenate([positions, np.stack(ends, axis=1)], axis=1)
    names = list(SEGMENTS) + list(HUMAN_ENDS)
    bones = np.array([(names.index(a), names.index(b)) for a, b in HUMAN_BONES])
    return Skeleton(
        title="human" + (" (mirrored)" if human.mirrored else ""),
        points=points,
        bones=bones,
        bone_colours=[_side_colour(b) for _, b in HUMAN_BONES],
        path=human.pelvis_position[:, :2],
        path_index=np.asarray(frames),
    )


def match_frames(times: np.ndarray, source_times: np.ndarray) -> np.ndarray:
    """Index of the source frame nearest each time. Clocks that do not overlap (one file
    stamped from 0, the other with the recording's clock) are aligned at their starts."""
    times = np.asarray(times, dtype=float)
    source = np.asarray(source_times, dtype=float)
    if times[0] > source[-1] or times[-1] < source[0]:
        times = times - times[0] + source[0]
    right = np.clip(np.searchsorted(source, times), 1, len(source) - 1)
    left = right - 1
    nearer_left = np.abs(times - source[left]) <= np.abs(source[right] - times)
    return np.where(nearer_left, left, right) if len(source) > 1 else np.zeros_like(right)


class _Camera:
    """Orthographic projection from a fixed world direction: (u right, v up, depth far)."""

    def __init__(self, azimuth_deg: float = AZIMUTH_DEG, elevation_deg: float = ELEVATION_DEG):
        az, el = np.radians(azimuth_deg), np.radians(elevation_deg)
        towards_camera = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
        forward = -towards_camera
        right = np.cross(forward, [0.0, 0.0, 1.0])
        right /= np.linalg.norm(right)
        up = np.cross(right, forward)
        self.matrix = np.stack([right, up, forward])  # rows: u, v, depth

    def project(self, points: np.ndarray) -> np.ndarray:
        return np.asarray(points) @ self.matrix.T


class _Panel:
    """One subject's axes; its artists are created once and only updated per frame."""

    def __init__(self, figure: Figure, rect: Sequence[float], skeleton: Skeleton, span_u: float):
        self.skeleton = skeleton
        self.span_u = span_u
        ax = figure.add_axes(rect)
        ax.set_axis_off()
        ax.set_facecolor(BACKGROUND)
        self.ax = ax
        self.grid = LineCollection([], colors=GRID_COLOUR, linewidths=0.8, zorder=0)
        self.path_all = ax.plot([], [], color=PATH_COLOUR, alpha=0.25, lw=1.5, zorder=1)[0]
        self.path_done = ax.plot([], [], color=PATH_COLOUR, lw=2.0, zorder=1)[0]
        self.feet = PolyCollection([], linewidths=1.5, zorder=2)
        self.bones = LineCollection([], linewidths=3.0, capstyle="round", zorder=3)
        self.joints = ax.plot([], [], "o", color="#222222", ms=2.5, zorder=4)[0]
        ax.add_collection(self.grid)
        ax.add_collection(self.feet)
        ax.add_collection(self.bones)
        # redrawn every frame over a saved background (blitting); the rest is drawn once
        self.dynamic = (
            self.grid,
            self.path_all,
            self.path_done,
            self.feet,
            self.bones,
            self.joints,
        )
        for artist in self.dynamic:
            artist.set_animated(True)
        ax.text(
            0.03,
            0.96,
            skeleton.title,
            transform=ax.transAxes,
            fontsize=12,
            fontweight="bold",
            va="top",
            color=CENTRE_COLOUR,
        )
        self.colours = np.array(skeleton.bone_colours)
        self.grid_lines = self._grid_lines()
        self.grid_rgba = np.tile(to_rgba(GRID_COLOUR), (len(self.grid_lines), 1))

    @staticmethod
    def _grid_lines() -> np.ndarray:
        """(L, 2, 3) floor grid around the origin, in 1 m pieces that fade out one by one."""
        ticks = np.arange(-GRID_RADIUS, GRID_RADIUS + 1e-9, GRID_STEP)
        starts = np.arange(-GRID_RADIUS, GRID_RADIUS - 1e-9, GRID_PIECE)
        a, b = np.meshgrid(ticks, starts, indexing="ij")
        a, b = a.ravel(), b.ravel()
        zero = np.zeros_like(a)
        ends = np.minimum(b + GRID_PIECE, GRID_RADIUS)
        along_y = np.stack([np.stack([a, b, zero], -1), np.stack([a, ends, zero], -1)], 1)
        along_x = along_y[:, :, [1, 0, 2]]
        return np.concatenate([along_y, along_x])

    def update(self, camera: _Camera, n: int) -> None:
        sk = self.skeleton
        centre = sk.centre[n]
        snapped = np.round(centre / GRID_STEP) * GRID_STEP
        grid = self.grid_lines + np.array([snapped[0], snapped[1], 0.0])
        distance = np.linalg.norm(grid[:, :, :2].mean(axis=1) - centre, axis=1)
        self.grid_rgba[:, 3] = np.clip(1.0 - distance / GRID_RADIUS, 0.0, 1.0)  # fade out
        self.grid.set_segments(camera.project(grid)[..., :2])
        self.grid.set_color(self.grid_rgba)

        path = np.column_stack([sk.path, np.zeros(len(sk.path))])
        path_uv = camera.project(path)
        self.path_all.set_data(path_uv[:, 0], path_uv[:, 1])
        done = path_uv[: sk.path_index[n] + 1]
        self.path_done.set_data(done[:, 0], done[:, 1])

        uvd = camera.project(sk.points[n])
        segments = uvd[sk.bones]  # (B, 2, 3)
        order = np.argsort(-segments[:, :, 2].mean(axis=1))  # far bones first
        self.bones.set_segments(segments[order, :, :2])
        self.bones.set_color(self.colours[order])
        self.joints.set_data(uvd[:, 0], uvd[:, 1])

        if sk.feet is not None:
            feet_uv = camera.project(sk.feet[n])[..., :2]
            edge = [LEFT_COLOUR, RIGHT_COLOUR]
            face = [c if on else "none" for c, on in zip(edge, sk.contacts[n], strict=True)]
            self.feet.set_verts(list(feet_uv))
            self.feet.set_edgecolor(edge)
            self.feet.set_facecolor(face)
            self.feet.set_alpha(None)

        ground = camera.project(np.array([centre[0], centre[1], 0.0]))
        self.ax.set_xlim(ground[0] - self.span_u / 2, ground[0] + self.span_u / 2)
        self.ax.set_ylim(ground[1] - VIEW_BELOW, ground[1] + VIEW_ABOVE)


class _Scene:
    """One reused Agg figure holding a panel per subject; `draw(n)` gives an RGB frame."""

    def __init__(self, skeletons: Sequence[Skeleton], times: np.ndarray, width: int, height: int):
        dpi = 100
        self.figure = Figure(figsize=(width / dpi, height / dpi), dpi=dpi, facecolor=BACKGROUND)
        self.canvas = FigureCanvasAgg(self.figure)
        self.camera = _Camera()
        n = len(skeletons)
        metres_per_pixel = (VIEW_BELOW + VIEW_ABOVE) / height
        span_u = (width / n) * metres_per_pixel  # one scale for every panel
        self.panels = [
            _Panel(self.figure, [k / n, 0.0, 1.0 / n, 1.0], sk, span_u)
            for k, sk in enumerate(skeletons)
        ]
        for k in range(1, n):  # a faint divider between the subjects
            self.figure.add_artist(Line2D([k / n] * 2, [0.0, 1.0], color=GRID_COLOUR, lw=1.0))
        self.times = times
        self.clock = self.figure.text(0.99, 0.97, "", ha="right", va="top", fontsize=11)
        self.clock.set_animated(True)
        for y, (label, colour) in enumerate((("left", LEFT_COLOUR), ("right", RIGHT_COLOUR))):
            self.figure.text(0.99, 0.02 + 0.04 * y, label, color=colour, ha="right", fontsize=9)
        self.canvas.draw()  # the static part, once
        self.background = self.canvas.copy_from_bbox(self.figure.bbox)

    def draw(self, n: int) -> np.ndarray:
        self.canvas.restore_region(self.background)
        for panel in self.panels:
            panel.update(self.camera, n)
            for artist in panel.dynamic:
                panel.ax.draw_artist(artist)
        self.clock.set_text(f"t = {self.times[n]:.2f} s")
        self.figure.draw_artist(self.clock)
        rgba = np.asarray(self.canvas.buffer_rgba())
        return rgba[..., :3].copy()

    def frames(self, count: int, description: str) -> Iterator[np.ndarray]:
        for n in tqdm(range(count), desc=description, unit="frame", leave=False):
            yield self.draw(n)


def check_output(path: Path) -> str:
    """The picture format of `path` (.gif, .mp4, .png), or a PimannError naming the file."""
    suffix = path.suffix.lower()
    if suffix not in FORMATS:
        raise PimannError(
            path, f"unknown picture format {path.suffix or '(none)'!r}; use one of {FORMATS}"
        )
    if suffix == ".mp4":
        try:
            import imageio_ffmpeg  # noqa: F401
        except ImportError:
            raise PimannError(
                path, "writing .mp4 needs the imageio-ffmpeg package; use .gif or .png"
            ) from None
    return suffix


def _write_gif(path: Path, frames: Iterator[np.ndarray], fps: float) -> None:
    """Pillow GIF with each frame quantised as it comes (1 byte a pixel held, not 3)."""
    from PIL import Image

    images = [
        Image.fromarray(f).quantize(
            colors=64, method=Image.Quantize.FASTOCTREE, dither=Image.Dither.NONE
        )
        for f in frames
    ]
    images[0].save(path, save_all=True, append_images=images[1:], duration=1000.0 / fps, loop=0)


def _write_mp4(path: Path, frames: Iterator[np.ndarray], fps: float) -> None:
    """Frames streamed to ffmpeg (H.264), never all held in memory."""
    import imageio.v2 as imageio

    with imageio.get_writer(
        path, format="FFMPEG", fps=fps, codec="libx264", quality=7, macro_block_size=2
    ) as writer:
        for frame in frames:
            writer.append_data(frame)


def write_pictures(output_path: Path, pictures: Iterator[np.ndarray], fps: float) -> None:
    """Pictures to a .png strip, a .gif or an .mp4 (by the suffix), written atomically."""
    suffix = check_output(output_path)
    with atomic_path(output_path) as tmp:
        if suffix == ".png":
            _write_strip(tmp, list(pictures))
        elif suffix == ".gif":
            _write_gif(tmp, pictures, fps)
        else:
            _write_mp4(tmp, pictures, fps)


def render_trajectory(
    trajectory: Trajectory | None,
    output_path: str | Path,
    human: HumanMotion | None = None,
    *,
    fps: float | None = None,
    width: int = 960,
    height: int = 480,
    every_n_frames: int = 2,
    strip_frames: int = 6,
    robot: Robot | None = None,
) -> Path:
    """Draw the robot (and the person beside it) to a .gif, .mp4 or .png strip.

    GIF and MP4 show every `every_n_frames`-th frame at `fps` (default: real time); a PNG
    is `strip_frames` evenly spaced frames side by side, each `width` x `height` pixels.
    `human` may be at another rate: frames are matched by time. Either subject may be None.
    """
    output_path = Path(output_path)
    suffix = check_output(output_path)
    if trajectory is None and human is None:
        raise PimannError(output_path, "nothing to render: no trajectory and no human motion")
    if width < 64 or height < 64 or every_n_frames < 1 or strip_frames < 1:
        raise PimannError(output_path, "width/height must be >= 64, frame counts >= 1")
    clock = np.asarray(trajectory.time if trajectory is not None else human.time, dtype=float)
    source = trajectory.source if trajectory is not None else human.source
    if len(clock) == 0:
        raise PimannError(source, "no frames to render")

    if suffix == ".png":
        frames = np.unique(np.linspace(0, len(clock) - 1, strip_frames).round().astype(int))
    else:
        frames = np.arange(0, len(clock), every_n_frames)
    times = clock[frames]
    skeletons = []
    if trajectory is not None:
        skeletons.append(robot_skeleton(trajectory, frames, robot))
    if human is not None:
        skeletons.append(human_skeleton(human, match_frames(times, human.time)))
    scene = _Scene(skeletons, times - clock[0], width, height)

    if fps is None:
        duration = clock[-1] - clock[0]
        rate = (len(clock) - 1) / duration if duration > 0 else 25.0
        fps = rate / every_n_frames
    log.info("rendering %d frames of %s to %s", len(frames), source, output_path)
    write_pictures(output_path, scene.frames(len(frames), output_path.name), fps)
    return output_path


def _write_strip(path: Path, pictures: list[np.ndarray]) -> None:
    import imageio.v3 as iio

    separator = np.full((pictures[0].shape[0], 3, 3), 120, dtype=np.uint8)
    row = [pictures[0]]
    for picture in pictures[1:]:
        row += [separator, picture]
    iio.imwrite(path, np.concatenate(row, axis=1), extension=".png")


def render_file(
    trajectory_path: str | Path,
    output_path: str | Path,
    group: str | None = None,
    mocap_path: str | Path | None = None,
    skeleton: SkeletonParams | None = None,
    **options,
) -> Path:
    """`pimann render`: a trajectory file (one group of a collection), optionally beside the
    mocap clip it came from (read with `skeleton`, default: recognised from its joints), to a
    picture. A mirrored trajectory gets the mirrored person. `options` go to
    `render_trajectory`."""
    trajectory = read_trajectory(trajectory_path, group)
    human = None
    if mocap_path is not None:
        from pimann.mocap.io import read_mocap

        human = read_mocap(mocap_path, skeleton)
        if bool(trajectory.attrs.get("mirrored", False)) != human.mirrored:
            human = mirror_human(human)
    return render_trajectory(trajectory, output_path, human, **options)
