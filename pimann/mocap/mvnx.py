"""XSens MVNX (the XML export of MVN Analyze): segment orientations and positions per frame.

Only `type="normal"` frames are motion; the special frames an export starts with
(`identity`, `tpose`, `tpose-isb`, `npose`) are calibration poses and are skipped.
Time comes from the frame `index` and the subject's `frameRate`: the `time` attribute is
whole milliseconds (0, 4, 8, 12 at 240 Hz), which would read as 250 Hz. Without a
`frameRate` the `time` attribute is used. The file is streamed (`iterparse`), since full
exports run to hundreds of megabytes.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from pimann.core.errors import PimannError
from pimann.core.robot import SEGMENTS
from pimann.mocap.human_motion import HumanMotion


def _local(tag: str) -> str:
    """Tag without its `{namespace}`: v3 and v4 files use different namespaces (or none)."""
    return tag.rsplit("}", 1)[-1]


class _Scan:
    """One streaming pass: header facts and, if asked, each normal frame's arrays."""

    def __init__(self, path: Path, keep_data: bool):
        self.path = path
        self.version: str | None = None
        self.rate_hz: float | None = None
        self.labels: list[str] = []
        self.indices: list[int] = []
        self.times_ms: list[float] = []
        self.orientations: list[np.ndarray] = []
        self.positions: list[np.ndarray] = []
        self.special: list[str] = []
        self._read(keep_data)

    def _read(self, keep_data: bool) -> None:
        stack: list[str] = []
        try:
            for event, element in ET.iterparse(self.path, events=("start", "end")):
                tag = _local(element.tag)
                if event == "start":
                    stack.append(tag)
                    if tag == "mvnx":
                        self.version = element.get("version")
                    elif tag == "subject" and element.get("frameRate"):
                        self.rate_hz = float(element.get("frameRate"))
                    continue
                stack.pop()
                if tag == "segment" and stack and stack[-1] == "segments":
                    self.labels.append(element.get("label", ""))
                    element.clear()
                elif tag == "frame":
                    self._frame(element, keep_data)
                    element.clear()
        except FileNotFoundError:
            raise PimannError(self.path, "file not found") from None
        except ET.ParseError as error:
            raise PimannError(self.path, f"not valid XML ({error})") from None
        if self.version is None:
            raise PimannError(self.path, "not an MVNX file (no <mvnx> root)")

    def _frame(self, element: ET.Element, keep_data: bool) -> None:
        kind = element.get("type", "normal")
        if kind != "normal":
            self.special.append(kind)
            return
        frame = len(self.indices)
        try:
            self.indices.append(int(element.get("index")))
            self.times_ms.append(float(element.get("time")))
        except (TypeError, ValueError):
            raise PimannError(
                self.path, "normal frame lacks a numeric index or time", frame=frame
            ) from None
        if not keep_data:
            return
        arrays = {}
        for child in element:
            name = _local(child.tag)
            if name in ("orientation", "position"):
                try:
                    arrays[name] = np.array((child.text or "").split(), dtype=float)
                except ValueError:
                    raise PimannError(self.path, f"{name} holds non-numbers", frame=frame) from None
        n = len(self.labels)
        for name, width in (("orientation", 4), ("position", 3)):
            values = arrays.get(name)
            if values is None:
                raise PimannError(self.path, f"frame lacks <{name}>", frame=frame)
            if values.size != width * n:
                raise PimannError(
                    self.path,
                    f"<{name}> holds {values.size} numbers, expected {width} x {n} segments",
                    frame=frame,
                )
        self.orientations.append(arrays["orientation"].reshape(n, 4))
        self.positions.append(arrays["position"].reshape(n, 3))

    def time(self) -> np.ndarray:
        """Seconds, from index / frameRate (exact) or else the millisecond `time` attribute."""
        if self.rate_hz:
            return np.array(self.indices, dtype=float) / self.rate_hz
        return np.array(self.times_ms) / 1000.0


def read_mvnx(path: str | Path) -> HumanMotion:
    """The 13 study segments of every normal frame of an MVNX file."""
    path = Path(path)
    scan = _Scan(path, keep_data=True)
    missing = [s for s in SEGMENTS if s not in scan.labels]
    if missing:
        raise PimannError(path, f"segment(s) {missing} not in the file's <segments>")
    if not scan.indices:
        raise PimannError(path, "holds no normal (motion) frames")
    columns = [scan.labels.index(s) for s in SEGMENTS]
    wxyz = np.stack(scan.orientations)[:, columns]  # (T, 13, 4)
    positions = np.stack(scan.positions)[:, columns]
    bad = ~(np.isfinite(wxyz).all(axis=(1, 2)) & np.isfinite(positions).all(axis=(1, 2)))
    if bad.any():
        raise PimannError(path, "NaN or infinite segment values", frame=int(np.argmax(bad)))
    norm = np.linalg.norm(wxyz, axis=-1)
    if np.any(np.abs(norm - 1.0) > 0.1):
        frame = int(np.argmax(np.any(np.abs(norm - 1.0) > 0.1, axis=1)))
        raise PimannError(path, "segment quaternion norm is not 1", frame=frame)
    orientations = Rotation.from_quat(wxyz[..., [1, 2, 3, 0]].reshape(-1, 4)).as_matrix()
    return HumanMotion(
        time=scan.time(),
        orientations=orientations.reshape(len(wxyz), len(SEGMENTS), 3, 3),
        segment_positions=positions,
        source=str(path),
    )


def mvnx_info(path: str | Path) -> dict:
    """Summary for `pimann mocap-info`, without reading the frame arrays."""
    scan = _Scan(Path(path), keep_data=False)
    time = scan.time()
    frames = len(time)
    duration = float(time[-1] - time[0]) if frames else 0.0
    rate = scan.rate_hz or ((frames - 1) / duration if duration > 0 else 0.0)
    return {
        "format": "mvnx",
        "frames": frames,
        "rate_hz": rate,
        "duration_s": duration,
        "segments": scan.labels,
    }
