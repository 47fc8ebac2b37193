"""The drawing of pimann.render.trajectory: one reused Agg figure, a panel per subject, a fixed
camera.

Split from pimann.render.trajectory (which turns trajectories and mocap into `Skeleton`s and writes
the files): orthographic projection onto plain 2-D axes, artists created once and only updated per
frame over a saved background (blitting), a few milliseconds a frame.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator, Sequence

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection, PolyCollection
from matplotlib.colors import to_rgba
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from pimann.core.progress import track

LEFT_COLOUR = "#1f5fbf"
RIGHT_COLOUR = "#d62728"
CENTRE_COLOUR = "#3a3a3a"
BACKGROUND = "#ffffff"
GRID_COLOUR = "#b8b8b8"
PATH_COLOUR = "#2ca02c"

# Camera: fixed world direction, from the subject's right front, slightly above.
AZIMUTH_DEG = -60.0
ELEVATION_DEG = 15.0
VIEW_BELOW = 0.45  # m of view below the floor point under the subject
VIEW_ABOVE = 1.95  # m of view above it (ergoCub is 1.6 m, the person ~1.8 m)
GRID_STEP = 0.5
GRID_RADIUS = 3.0
GRID_PIECE = 1.0


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


class Scene:
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
            y_px = 6 + 14 * y  # in pixels: a fraction of the height overlapped in small frames
            self.figure.text(0.99, y_px / height, label, color=colour, ha="right", fontsize=9)
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
        for n in track(range(count), description, "frames"):
            yield self.draw(n)
