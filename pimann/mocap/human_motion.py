"""The one in-memory type every mocap reader produces."""

from __future__ import annotations

import dataclasses

import numpy as np

from pimann.core.errors import PimannError, require_finite
from pimann.core.robot import SEGMENTS


@dataclasses.dataclass
class HumanMotion:
    """A person's motion in XSens convention: z up, metres, every segment frame x forward,
    y left, z up when the person stands in the T-pose.

    `orientations[t, k]` is the world rotation matrix of segment `SEGMENTS[k]`;
    `segment_positions[t, k]` the world position of its origin (used to detect foot
    contacts; only the Pelvis position drives the retargeting).
    `foot_points[t, side, point]` (optional) holds the world positions of each foot's heel
    (the ankle joint) and toe (the toe joint, or the foot bone's end), left then right: the
    points contact detection watches; without them the foot segment's origin stands in.
    """

    time: np.ndarray  # (T,) s, strictly increasing
    orientations: np.ndarray  # (T, 13, 3, 3)
    segment_positions: np.ndarray  # (T, 13, 3) m
    source: str
    mirrored: bool = False
    foot_points: np.ndarray | None = None  # (T, 2, 2, 3) m: [left, right] x [heel, toe]

    def __post_init__(self) -> None:
        n = len(self.time)
        if self.orientations.shape != (n, len(SEGMENTS), 3, 3):
            raise PimannError(self.source, f"orientations have shape {self.orientations.shape}")
        if self.segment_positions.shape != (n, len(SEGMENTS), 3):
            raise PimannError(self.source, f"positions have shape {self.segment_positions.shape}")
        if self.foot_points is not None:
            if self.foot_points.shape != (n, 2, 2, 3):
                raise PimannError(self.source, f"foot points have shape {self.foot_points.shape}")
            require_finite(self.source, "foot points", self.foot_points)
        require_finite(self.source, "segment orientations", self.orientations)
        require_finite(self.source, "segment positions", self.segment_positions)
        if n > 1 and np.any(np.diff(self.time) <= 0):
            frame = int(np.flatnonzero(np.diff(self.time) <= 0)[0]) + 1
            raise PimannError(self.source, "time is not strictly increasing", frame=frame)

    @property
    def n_frames(self) -> int:
        return len(self.time)

    @property
    def duration(self) -> float:
        return float(self.time[-1] - self.time[0]) if self.n_frames else 0.0

    @property
    def rate_hz(self) -> float:
        return (self.n_frames - 1) / self.duration if self.duration > 0 else 0.0

    @property
    def pelvis_position(self) -> np.ndarray:
        return self.segment_positions[:, SEGMENTS.index("Pelvis")]

    def contact_points(self) -> np.ndarray:
        """(T, 2, P, 3) the points whose height and speed tell foot contact: heel and toe
        when the reader knows them, else the foot segment's origin."""
        if self.foot_points is not None:
            return self.foot_points
        feet = [SEGMENTS.index("LeftFoot"), SEGMENTS.index("RightFoot")]
        return self.segment_positions[:, feet, None, :]

    def segment(self, name: str) -> np.ndarray:
        """(T, 3, 3) world orientation of one segment."""
        return self.orientations[:, SEGMENTS.index(name)]
