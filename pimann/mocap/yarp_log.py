"""XSens MVN suit data as logged through YARP (the paper's raw recordings), one frame a line.

No genuine log is available here, so the layout below is a faithful reconstruction from the
format (second token = timestamp; each segment as a `XsensSuit::vLink::<Name>` entry followed
by a parenthesised group with the orientation quaternion w x y z, then the position x y z in
metres) and from how YARP bottles print: lists in parentheses, strings in double quotes,
numbers bare. The writer produces, per frame (one line, wrapped here):

    <counter> <timestamp> XsensSuit::vLink::Pelvis (("Pelvis" <status>) (<qw> <qx> <qy> <qz>)
        (<px> <py> <pz>)) XsensSuit::vLink::T8 (("T8" <status>) (...) (...)) ...

`<status>` is the sensor status integer (written as 1; not interpreted). The reader also takes
the flattened form of a YARP map entry, in which the full name is repeated inside the group:
`("XsensSuit::vLink::Pelvis" ("XsensSuit::vLink::Pelvis" <status> <qw> ... <pz> ...))`; what
follows the position (velocities, other links, `XsensSuit::vSJoint::` entries) is ignored.

Rules: blank lines are skipped; a frame (line) that lacks any of the 13 segments is dropped
(one warning with the count), as the authors did; a segment absent from the whole file, or no
complete frame, is an error. A malformed last line is taken as a log cut off mid-write and
dropped with a warning; a malformed line elsewhere, a NaN, a quaternion whose norm is
off 1 by more than 0.1, or a timestamp that does not increase raises.
`frame` in errors is the 0-based line index in the file.
"""

from __future__ import annotations

import logging
import re
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from pimann.core.atomic import atomic_path
from pimann.core.errors import PimannError
from pimann.core.robot import SEGMENTS
from pimann.mocap.human_motion import HumanMotion

log = logging.getLogger(__name__)

PREFIX = "XsensSuit::vLink::"
_NUM = r"([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?|[-+]?(?i:nan|inf(?:inity)?))"
_SEP = r"[\s()]+"
# key, then a group opening with the same name quoted, then status + quaternion + position
ENTRY = re.compile(
    r"XsensSuit::vLink::(\w+)\"?\s*\(\s*\(?\s*\"(?:XsensSuit::vLink::)?\1\""
    + "".join(_SEP + _NUM for _ in range(8))
)
KEY = re.compile(r"XsensSuit::vLink::(\w+)")
VALUES_PER_SEGMENT = 8  # status, qw qx qy qz, px py pz
NEW_STATUS = 1


class _Scan:
    """What one pass over the log found: complete frames and every link name seen."""

    def __init__(self, path: Path):
        self.path = path
        self.names: dict[str, None] = {}  # ordered set of every vLink name in the file
        self.lines: list[int] = []  # line index of each complete frame
        self.times: list[str] = []
        self.values: list[str] = []  # per frame, 13 x 8 numbers as text
        self.incomplete = 0
        self._read()

    def _read(self) -> None:
        try:
            text = self.path.read_text()
        except FileNotFoundError:
            raise PimannError(self.path, "file not found") from None
        except UnicodeDecodeError:
            raise PimannError(self.path, "not a text file") from None
        lines = text.splitlines()
        last = max((i for i, line in enumerate(lines) if line.strip()), default=-1)
        wanted = set(SEGMENTS)
        for index, line in enumerate(lines):
            if not line.strip():
                continue
            keys = KEY.findall(line)
            self.names.update(dict.fromkeys(keys))
            entries: dict[str, str] = {}
            for name, *numbers in ENTRY.findall(line):
                if name in wanted:
                    entries.setdefault(name, " ".join(numbers))
            problem = self._problem(line, keys, entries)
            if problem is not None:
                if index == last:
                    log.warning(
                        "%s: dropped the last line %d (%s; cut off?)", self.path, index, problem
                    )
                    continue
                raise PimannError(self.path, f"line {index + 1}: {problem}", frame=index)
            if len(entries) < len(SEGMENTS):
                self.incomplete += 1
                continue
            self.lines.append(index)
            self.times.append(line.split(None, 2)[1])
            self.values.append(" ".join([entries[name] for name in SEGMENTS]))

    @staticmethod
    def _problem(line: str, keys: list[str], entries: dict) -> str | None:
        tokens = line.split(None, 2)
        if len(tokens) < 2:
            return "no timestamp (second token)"
        try:
            float(tokens[1])
        except ValueError:
            return f"timestamp {tokens[1]!r} is not a number"
        malformed = sorted({k for k in keys if k in SEGMENTS and k not in entries})
        if malformed:
            return f"malformed entry for segment(s) {malformed}"
        return None


def _to_motion(scan: _Scan) -> HumanMotion:
    path = scan.path
    missing = [s for s in SEGMENTS if s not in scan.names]
    if missing:
        raise PimannError(path, f"segment(s) {missing} never appear ({PREFIX}<Name> entries)")
    if not scan.values:
        raise PimannError(path, f"no frame holds all {len(SEGMENTS)} segments")
    if scan.incomplete:
        log.warning("%s: dropped %d frame(s) missing segments", path, scan.incomplete)
    time = np.array(scan.times, dtype=float)
    # the regex admitted only number tokens, so numpy's C parser reads them all at once
    values = np.fromstring(" ".join(scan.values), sep=" ").reshape(len(time), len(SEGMENTS), -1)
    lines = np.array(scan.lines)
    bad = ~np.isfinite(values[..., 1:]).all(axis=-1)  # (F, 13)
    if bad.any():
        frame, segment = np.argwhere(bad)[0]
        raise PimannError(
            path, f"segment {SEGMENTS[segment]} holds NaN or infinite values", frame=lines[frame]
        )
    if not np.isfinite(time).all():
        raise PimannError(path, "timestamp is not finite", frame=lines[~np.isfinite(time)][0])
    wxyz = values[..., 1:5]
    norm = np.linalg.norm(wxyz, axis=-1)
    if np.any(np.abs(norm - 1.0) > 0.1):
        frame, segment = np.argwhere(np.abs(norm - 1.0) > 0.1)[0]
        raise PimannError(
            path,
            f"segment {SEGMENTS[segment]} quaternion norm {norm[frame, segment]:.3g} is not 1",
            frame=lines[frame],
        )
    xyzw = wxyz[..., [1, 2, 3, 0]].reshape(-1, 4)
    orientations = Rotation.from_quat(xyzw).as_matrix().reshape(len(time), len(SEGMENTS), 3, 3)
    steps = np.diff(time)
    if np.any(steps <= 0):
        frame = lines[int(np.flatnonzero(steps <= 0)[0]) + 1]
        raise PimannError(path, "timestamp does not increase", frame=frame)
    return HumanMotion(
        time=time,
        orientations=orientations,
        segment_positions=values[..., 5:8],
        source=str(path),
    )


def read_yarp_log(path: str | Path) -> HumanMotion:
    """The 13 study segments of every complete frame of an XSens YARP log."""
    return _to_motion(_Scan(Path(path)))


def yarp_log_info(path: str | Path) -> dict:
    """Summary for `pimann mocap-info`: every link name in the file, complete frames, rate."""
    scan = _Scan(Path(path))
    motion = _to_motion(scan)
    return {
        "format": "yarp-log",
        "frames": motion.n_frames,
        "rate_hz": motion.rate_hz,
        "duration_s": motion.duration,
        "segments": list(scan.names),
    }


def _template() -> str:
    entry = '{p}{s} (("{s}" %d) (%r %r %r %r) (%r %r %r))'
    return "%d %r " + " ".join(entry.format(p=PREFIX, s=s) for s in SEGMENTS) + "\n"


def write_yarp_log(path: str | Path, motion: HumanMotion) -> None:
    """Write `motion` in the layout `read_yarp_log` reads (shortest exact float text)."""
    n = motion.n_frames
    xyzw = Rotation.from_matrix(motion.orientations.reshape(-1, 3, 3)).as_quat()
    wxyz = xyzw[:, [3, 0, 1, 2]].reshape(n, len(SEGMENTS), 4)
    status = np.full((n, len(SEGMENTS), 1), NEW_STATUS, dtype=float)
    values = np.concatenate([status, wxyz, motion.segment_positions], axis=-1).reshape(n, -1)
    template = _template()
    rows = values.tolist()
    integer = slice(0, None, VALUES_PER_SEGMENT)
    with atomic_path(path) as tmp, open(tmp, "w") as file:
        for k in range(n):
            row = rows[k]
            row[integer] = [int(v) for v in row[integer]]
            file.write(template % (k, float(motion.time[k]), *row))
