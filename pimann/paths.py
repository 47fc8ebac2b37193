"""Where the shared, read-only study data lives: one setting, `PIMANN_SHARED`.

The robots, the mocap and the paper are never copied into the repository; they are read in
place from the folder this variable names, `../shared` beside the repository by default.
"""

from __future__ import annotations

import os
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]
SHARED_ENV = "PIMANN_SHARED"


def shared_dir() -> Path:
    """The shared data folder (`$PIMANN_SHARED`, else `<repo>/../shared`)."""
    configured = os.environ.get(SHARED_ENV)
    return (
        Path(configured).expanduser().resolve()
        if configured
        else (REPO_ROOT.parent / "shared").resolve()
    )


def robots_dir() -> Path:
    return shared_dir() / "robots"


def mocap_dir() -> Path:
    return shared_dir() / "data" / "mocap"


def resolve_shared(relative: str | Path) -> Path:
    """A path from params.yaml: relative ones are taken inside the shared folder."""
    path = Path(relative)
    return path if path.is_absolute() else shared_dir() / path
