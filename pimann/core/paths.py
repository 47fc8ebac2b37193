"""Where the shared, read-only study data lives: one setting, `PIMANN_SHARED`.

The robots, the mocap and the paper are never copied into the repository; they are read in
place from the folder this variable names, `../shared` beside the repository by default.
"""

from __future__ import annotations

import glob
import os
from pathlib import Path

SHARED_ENV = "PIMANN_SHARED"
PACKAGE_CHECKOUT = Path(__file__).resolve().parents[2]


def project_root(start: Path | None = None) -> Path:
    """The pimann project being worked in: the nearest folder at or above `start` (default:
    the current one, where DVC runs every stage) that holds params.yaml and dvc.yaml; else
    the checkout this package was installed from. A second clone thus never writes into the
    first one's outputs."""
    start = (start or Path.cwd()).resolve()
    for folder in (start, *start.parents):
        if (folder / "params.yaml").is_file() and (folder / "dvc.yaml").is_file():
            return folder
    return PACKAGE_CHECKOUT


REPO_ROOT = project_root()


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


def resolve_shared(relative: str | Path, shared: Path | None = None) -> Path:
    """A path from params.yaml: relative ones are taken inside the shared folder (`shared`,
    default `shared_dir()`)."""
    path = Path(relative)
    return path if path.is_absolute() else (shared or shared_dir()) / path


def shared_glob(pattern: str | Path, shared: Path | None = None) -> list[Path]:
    """The files a glob of params.yaml (data.sources paths) matches, sorted."""
    return sorted(
        Path(p) for p in glob.glob(str(resolve_shared(pattern, shared))) if Path(p).is_file()
    )


def bandai_label_files(bvh: Path) -> tuple[Path, Path, Path]:
    """The files `bandai_labels` reads for one BVH: its JSON, the dataset's content and style
    lists (<dataset>/data/<file>.bvh, labels in <dataset>/cfg)."""
    dataset_dir = bvh.parent.parent
    cfg = dataset_dir / "cfg"
    return bvh.with_suffix(".json"), cfg / "content_label.txt", cfg / "style_label.txt"


def repo_relative(path: str | Path) -> str:
    """A path as results record it: relative to the repository when inside it (a run's files
    read the same on every machine, and hash the same in two checkouts), else absolute.

    Inside the repository by its spelling (a linked folder such as data/ stays relative)
    or, failing that, by its resolved location."""
    for candidate in (Path(os.path.abspath(path)), Path(path).resolve()):
        if candidate.is_relative_to(REPO_ROOT):
            return str(candidate.relative_to(REPO_ROOT))
    return str(Path(path).resolve())


def repo_path(recorded: str | Path) -> Path:
    """A path `repo_relative` recorded, as a path to open: a relative one is under REPO_ROOT."""
    recorded = Path(recorded)
    return recorded if recorded.is_absolute() else REPO_ROOT / recorded
