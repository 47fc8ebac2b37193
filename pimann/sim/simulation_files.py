"""A simulation run on disk: the simulated robot as a trajectory file plus the controller's traces.

The file follows the trajectory contract (pimann.core.trajectory: `time`, `base_position`,
`base_quaternion_xyzw`, `joint_positions` = the measured joints, `contacts` from the foot
forces, `com_position`), so `read_trajectory`, `pimann metrics` and `pimann render` read it
as they read a rollout. Beside it: the joint traces the joint-tracking figure reads
(`joints_reference`, `joints_measured`, `joints_generated`), the CoM and ZMP plans and
measurements, the per-foot slip, the `fall` flag, and the run's summary as attributes.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import h5py
import numpy as np

from pimann.core.atomic import atomic_path
from pimann.core.errors import PimannError
from pimann.core.params import SimulateParams
from pimann.core.robot import JOINT_NAMES, SOLE_HALF_LENGTH, SOLE_HALF_WIDTH
from pimann.core.trajectory import Trajectory, write_trajectory
from pimann.sim.closed_loop import SimulationResult

CONTACT_FORCE_N = 20.0  # N of normal force for a foot to count as in contact
TRACES = (
    "joints_reference",
    "joints_measured",
    "joints_generated",
    "com_reference",
    "com_measured",
    "zmp_reference",
    "zmp_measured",
    "base_height",
    "ik_error",
    "soles_measured",
    "soles_reference",
    "foot_forces",
    "zmp_outside_support",
)


def _cross(a: np.ndarray, b: np.ndarray):
    """z of the 2-D cross product (positive: b is counter-clockwise of a)."""
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _convex_hull(points: np.ndarray) -> np.ndarray:
    """Counter-clockwise hull vertices of (n, 2) points (monotone chain), no repeated end."""
    pts = np.unique(np.asarray(points, dtype=float), axis=0)  # sorted by x, then y
    if len(pts) < 3:
        return pts

    def half(sequence: np.ndarray) -> list[np.ndarray]:
        chain: list[np.ndarray] = []
        for p in sequence:
            while len(chain) >= 2 and _cross(chain[-1] - chain[-2], p - chain[-2]) <= 0:
                chain.pop()
            chain.append(p)
        return chain

    lower, upper = half(pts), half(pts[::-1])
    return np.array(lower[:-1] + upper[:-1])


def distance_outside_polygon(point: np.ndarray, polygon: np.ndarray) -> float:
    """Distance from a point (2,) to a convex polygon (n, 2) of any vertex order; 0 inside.

    NaN for a NaN point (no contact, no ZMP) or an empty polygon (both feet in the air).
    """
    point = np.asarray(point, dtype=float)
    hull = _convex_hull(polygon) if len(polygon) else np.empty((0, 2))
    if not np.isfinite(point).all() or len(hull) == 0:
        return float("nan")
    if len(hull) == 1:
        return float(np.linalg.norm(point - hull[0]))
    start, end = hull, np.roll(hull, -1, axis=0)
    edge = end - start
    rel = point - start
    if len(hull) >= 3 and np.all(_cross(edge, rel) >= 0.0):
        return 0.0  # left of every counter-clockwise edge
    s = np.clip(np.einsum("ij,ij->i", rel, edge) / np.einsum("ij,ij->i", edge, edge), 0.0, 1.0)
    return float(np.min(np.linalg.norm(rel - s[:, None] * edge, axis=1)))


def foot_rectangle(position: np.ndarray, yaw: float, half_length: float, half_width: float):
    """(4, 2) corners of a flat foot's support rectangle at a sole position (x, y) and yaw."""
    corners = np.array([[sx * half_length, sy * half_width] for sx in (1, -1) for sy in (1, -1)])
    c, s = np.cos(yaw), np.sin(yaw)
    return corners @ np.array([[c, s], [-s, c]]) + np.asarray(position)[:2]


def zmp_outside_support(result: SimulationResult, params: SimulateParams) -> np.ndarray:
    """(K,) m: measured ZMP's distance outside the measured support polygon, 0 inside.

    The polygon is the hull of the sole rectangles (pimann.core.robot's `SOLE_HALF_LENGTH` x
    `_WIDTH`,
    no margin) of the feet the floor pushes on (> CONTACT_FORCE_N), at their simulated
    positions with the plan's yaw; the ZMP is taken back to the simulation's world (the
    trace has the feet's drift removed, com_world - com_measured). The plan's contacts would
    count a foot that is still loaded after its planned lift-off as gone. The measured ZMP is
    low-pass filtered, so a foot counts for three filter time constants after it unloads.
    """
    drift = result.com_world[:, :2] - result.com_measured[:, :2]
    zmp_world = result.zmp_measured + drift
    dt = float(np.median(np.diff(result.time))) if len(result.time) > 1 else params.timestep
    memory = int(np.ceil(3.0 / (2.0 * np.pi * params.zmp_filter_hz) / dt))
    loaded = result.foot_forces > CONTACT_FORCE_N
    recent = loaded.copy()
    for lag in range(1, memory + 1):
        recent[lag:] |= loaded[:-lag]
    out = np.empty(len(result.time))
    for k, t in enumerate(result.time):
        feet = [
            foot_rectangle(
                result.soles_measured[k, side],
                result.footsteps.foot_pose(side, t)[1],
                SOLE_HALF_LENGTH,
                SOLE_HALF_WIDTH,
            )
            for side in (0, 1)
            if recent[k, side]
        ]
        polygon = np.concatenate(feet) if feet else np.empty((0, 2))
        out[k] = distance_outside_polygon(zmp_world[k], polygon)
    return out


def run_summary(
    result: SimulationResult, params: SimulateParams, outside: np.ndarray | None = None
) -> dict[str, Any]:
    """The run's figures, JSON-ready: the controller's summary plus success, distance, ZMP.

    `outside`: `zmp_outside_support(result, params)` if already computed.
    """
    outside = zmp_outside_support(result, params) if outside is None else outside
    # between the feet, not the base: the base still sways over a stance foot at the end
    walked = result.soles_measured[[0, -1], :, :2].mean(axis=1)
    planned = result.soles_reference[[0, -1], :, :2].mean(axis=1)
    summary = dict(result.summary())
    summary.update(
        success=bool(not result.fallen and result.time[-1] >= result.planned_duration - 0.02),
        steps=int(sum(len(foot) - 1 for foot in result.footsteps.feet)),  # 0: it only stood
        distance_walked_m=float(np.linalg.norm(walked[1] - walked[0])),
        distance_planned_m=float(np.linalg.norm(planned[1] - planned[0])),
        zmp_outside_max_m=float(np.nanmax(outside)) if np.isfinite(outside).any() else None,
        zmp_outside_fraction=float(np.mean(outside > 1e-3)),
        foot_slip_left_m=float(result.foot_slip_per_foot[0]),
        foot_slip_right_m=float(result.foot_slip_per_foot[1]),
    )
    return summary


def _decimate(time: np.ndarray, rate_hz: float) -> np.ndarray:
    """Indices of the samples kept for an output rate (every sample if at or below it)."""
    if len(time) < 2:
        return np.arange(len(time))
    step = max(1, int(round(1.0 / (rate_hz * float(np.median(np.diff(time)))))))
    return np.arange(0, len(time), step)


def write_simulation(
    path: str | Path,
    result: SimulationResult,
    params: SimulateParams,
    *,
    source: str = "simulation",
    rate_hz: float = 100.0,
    attrs: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Write a run to HDF5 atomically (traces at most `rate_hz`); returns its summary.

    `attrs` (provenance: model, seed, scenario, ...) go to the file's attributes.
    """
    if len(result.time) == 0:
        raise PimannError(path, "the simulation has no samples to write")
    outside = zmp_outside_support(result, params)
    summary = run_summary(result, params, outside)
    keep = _decimate(result.time, rate_hz)
    dt = float(np.median(np.diff(result.time[keep]))) if len(keep) > 1 else 1.0 / rate_hz
    trajectory = Trajectory(
        time=result.time[keep],
        base_position=result.base_pose[keep, :3],
        base_quaternion_xyzw=result.base_pose[keep, 3:],
        joint_positions=result.joints_measured[keep],
        source=source,
        rate_hz=1.0 / dt,
        contacts=result.foot_forces[keep] > CONTACT_FORCE_N,
        com_position=result.com_world[keep],
        attrs=dict(attrs or {}),
    )
    traces = {name: getattr(result, name) for name in TRACES[:-1] if name != "joints_measured"}
    traces["zmp_outside_support"] = outside
    with atomic_path(path) as tmp:
        write_trajectory(tmp, trajectory)
        with h5py.File(tmp, "a") as file:
            file["joints_measured"] = file["joint_positions"]  # a hard link: stored once
            for name, values in traces.items():  # float32 (1e-7 relative): half the size
                values = np.asarray(values, dtype=np.float32)[keep]
                file.create_dataset(name, data=values, compression="gzip", shuffle=True)
            file.create_dataset("foot_slip", data=np.asarray(result.foot_slip_per_foot, float))
            file.attrs["fall"] = bool(result.fallen)
            for key, value in summary.items():
                file.attrs[key] = np.nan if value is None else value
    return summary


def read_simulation(path: str | Path) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """(datasets, attributes) of a simulation file; the robot part reads with read_trajectory."""
    path = Path(path)
    try:
        file = h5py.File(path, "r")
    except FileNotFoundError:
        raise PimannError(path, "file not found") from None
    except OSError as error:
        raise PimannError(path, f"not a readable HDF5 file ({error})") from None
    with file:
        missing = [n for n in ("time", "joints_reference", "joints_measured") if n not in file]
        if missing:
            raise PimannError(path, f"not a simulation file: lacks dataset {missing[0]!r}")
        names = [str(n) for n in file.attrs.get("joint_names", [])]
        if names != list(JOINT_NAMES):
            raise PimannError(path, "joint_names are not ergoCub's 26 joints in study order")
        data = {name: file[name][()] for name in file if isinstance(file[name], h5py.Dataset)}
        attrs = {k: (v.item() if isinstance(v, np.generic) else v) for k, v in file.attrs.items()}
    return data, attrs
