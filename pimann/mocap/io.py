"""One entry point for every mocap format: pick the reader by extension, else by content.

`.bvh` -> BVH (any skeleton: a built-in convention is recognised when no map is given),
`.mvnx` -> MVNX, anything else that is text holding `XsensSuit::vLink::` -> YARP log.
`mocap_info` backs `pimann mocap-info FILE` (a JSON summary).
"""

from __future__ import annotations

import re
from pathlib import Path

from pimann.core.errors import PimannError
from pimann.core.params import SkeletonParams
from pimann.mocap.human_motion import HumanMotion
from pimann.mocap.mvnx import mvnx_info, read_mvnx
from pimann.mocap.yarp_log import PREFIX, read_yarp_log, yarp_log_info

SNIFF_BYTES = 1 << 16
BVH_JOINT = re.compile(r"^\s*(?:ROOT|JOINT)\s+(\S+)", re.MULTILINE)


def mocap_format(path: str | Path) -> str:
    """`bvh`, `mvnx` or `yarp-log`; PimannError if the file is none of them."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix in (".bvh", ".mvnx"):
        return suffix[1:]
    try:
        with open(path, "rb") as file:
            head = file.read(SNIFF_BYTES).decode("utf-8", errors="replace")
    except FileNotFoundError:
        raise PimannError(path, "file not found") from None
    except IsADirectoryError:
        raise PimannError(path, "is a folder, not a mocap file") from None
    if head.lstrip().startswith("HIERARCHY"):
        return "bvh"
    if "<mvnx" in head:
        return "mvnx"
    if PREFIX in head:
        return "yarp-log"
    raise PimannError(
        path, f"unknown mocap format (expected .bvh, .mvnx, or a YARP log with {PREFIX} entries)"
    )


def read_mocap(
    path: str | Path, skeleton: SkeletonParams | None = None, rate_hz: float | None = None
) -> HumanMotion:
    """The 13 study segments of a mocap file of any supported format. `skeleton` and
    `rate_hz` (replacing the header's frame time) apply to BVH files only."""
    kind = mocap_format(path)
    if kind == "bvh":
        from pimann.mocap.bvh import read_bvh  # the BVH reader loads only when needed

        return read_bvh(path, skeleton, rate_hz)
    if kind == "mvnx":
        return read_mvnx(path)
    return read_yarp_log(path)


def mocap_info(path: str | Path, skeleton: SkeletonParams | None = None) -> dict:
    """format, frames, rate_hz, duration_s and every segment (joint) name the file holds."""
    kind = mocap_format(path)
    if kind == "mvnx":
        return mvnx_info(path)
    if kind == "yarp-log":
        return yarp_log_info(path)
    motion = read_mocap(path, skeleton)
    header = Path(path).read_text(errors="replace").split("MOTION", 1)[0]
    return {
        "format": "bvh",
        "frames": motion.n_frames,
        "rate_hz": motion.rate_hz,
        "duration_s": motion.duration,
        "segments": BVH_JOINT.findall(header),
    }
