"""The one error type users see: it names the file, where in it, and what is wrong."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path


class PimannError(Exception):
    """Bad input. The command line prints `str(error)` as one line and exits non-zero."""

    def __init__(self, path: str | Path | None, problem: str, *, frame: int | None = None):
        self.path = None if path is None else str(path)
        self.problem = " ".join(str(problem).split())  # one line, whatever a library said
        self.frame = frame
        where = self.path or "<input>"
        if frame is not None:
            where += f" (frame {frame})"
        super().__init__(f"{where}: {self.problem}")

    def __reduce__(self):  # keeps the error intact across process pools
        return (_rebuild_error, (self.path, self.problem, self.frame))


def _rebuild_error(path: str | None, problem: str, frame: int | None) -> PimannError:
    return PimannError(path, problem, frame=frame)


def require_finite(path: str | Path, name: str, values, *, frame_axis: int = 0) -> None:
    """Raise naming the first frame of `values` that holds a NaN or an infinity."""
    import numpy as np

    values = np.asarray(values)
    bad = ~np.isfinite(values)
    if bad.any():
        other_axes = tuple(a for a in range(values.ndim) if a != frame_axis)
        frame = int(np.flatnonzero(bad.any(axis=other_axes) if other_axes else bad)[0])
        raise PimannError(path, f"{name} holds NaN or infinite values", frame=frame)


@contextmanager
def about(path: str | Path, what: str | None = None) -> Iterator[None]:
    """Errors raised inside name `path` (and `what`, e.g. a run or a group), whatever they
    named before: a computation deep in a stage knows the problem, its caller knows the file."""
    try:
        yield
    except PimannError as error:
        if error.path == str(path) and what is None:
            raise
        inner = "" if error.path in (None, str(path)) else f" [{error.path}]"
        prefix = f"{what}: " if what else ""
        raise PimannError(path, f"{prefix}{error.problem}{inner}", frame=error.frame) from None
