"""A simulated walk on video: the measured states replayed in MuJoCo's offscreen renderer.

Rendering replays the recorded base pose and joints in the visual model (meshes kept), so
it works from a result file as well as from a run. Without a working OpenGL backend (no
EGL, no display) it falls back to pimann.render.trajectory's matplotlib stick figure of the same
trajectory: a stage never fails for want of a GPU context.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from pimann.core.params import SimulateParams
from pimann.core.robot import load_robot
from pimann.core.trajectory import Trajectory
from pimann.render.trajectory import (
    STRIP_FRAMES,
    check_output,
    render_trajectory,
    strip_frame_indices,
    write_pictures,
)

log = logging.getLogger(__name__)
CAMERA = {"distance": 2.6, "azimuth": 150.0, "elevation": -10.0, "height": 0.5}


def _open_renderer(params: SimulateParams, width: int, height: int):
    """(model, renderer) or raise whatever the GL backend raises when it cannot start."""
    import mujoco

    from pimann.sim.model import build_sim_model

    sim = build_sim_model(params, visual=True)
    sim.model.vis.global_.offwidth = max(width, sim.model.vis.global_.offwidth)
    sim.model.vis.global_.offheight = max(height, sim.model.vis.global_.offheight)
    sim.model.vis.headlight.ambient[:] = 0.45
    sim.model.vis.headlight.diffuse[:] = 0.6
    return sim, mujoco.Renderer(sim.model, height, width)


def _mujoco_frames(sim, renderer, trajectory: Trajectory, frames: np.ndarray) -> Iterator:
    """Each picked frame of the trajectory, the camera following the base from the side."""
    import mujoco

    robot = load_robot("simulation")
    data = sim.new_data()
    camera = mujoco.MjvCamera()
    camera.distance, camera.azimuth = CAMERA["distance"], CAMERA["azimuth"]
    camera.elevation = CAMERA["elevation"]
    for k in frames:
        q = robot.configuration(
            trajectory.base_position[k],
            trajectory.base_quaternion_xyzw[k],
            trajectory.joint_positions[k],
        )
        sim.set_configuration(data, robot, q)
        camera.lookat[:] = [*trajectory.base_position[k, :2], CAMERA["height"]]
        renderer.update_scene(data, camera)
        yield renderer.render().copy()


def check_video_path(path: str | Path) -> None:
    """Raise PimannError now for a picture format render_simulation cannot write."""
    check_output(Path(path))


def render_simulation(
    trajectory: Trajectory,
    output_path: str | Path,
    params: SimulateParams,
    *,
    every_n_frames: int = 4,
    width: int = 480,
    height: int = 360,
    strip_frames: int = STRIP_FRAMES,
    use_mujoco: bool = True,
) -> Path:
    """Draw a simulated run (`trajectory`: its measured states) to .mp4, .gif or a .png strip.

    MP4 and GIF play every `every_n_frames`-th sample in real time; PNG puts `strip_frames`
    evenly spaced frames in rows of four. `use_mujoco=False`, or a GL backend that does not
    start, draws pimann.render.trajectory's stick figure instead.
    """
    output_path = Path(output_path)
    suffix = check_output(output_path)
    renderer = None
    if use_mujoco:
        try:
            sim, renderer = _open_renderer(params, width, height)
        except Exception as error:  # noqa: BLE001 -- any GL failure: no EGL, no display, ...
            log.warning("MuJoCo rendering unavailable (%s): stick figure instead", error)
    if renderer is None:
        return render_trajectory(
            trajectory,
            output_path,
            fps=None,
            width=width,
            height=height,
            every_n_frames=every_n_frames,
            strip_frames=strip_frames,
        )
    clock = np.asarray(trajectory.time, dtype=float)
    if suffix == ".png":
        frames = strip_frame_indices(len(clock), strip_frames)
    else:
        frames = np.arange(0, len(clock), every_n_frames)
    span = clock[-1] - clock[0] if len(clock) > 1 else 0.0
    fps = (len(clock) - 1) / span / every_n_frames if span > 0 else 25.0
    log.debug("rendering %d frames of %s to %s", len(frames), trajectory.source, output_path)
    try:
        write_pictures(output_path, _mujoco_frames(sim, renderer, trajectory, frames), fps)
    finally:
        renderer.close()
    return output_path
