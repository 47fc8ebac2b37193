"""Checked data: the shared files the pipeline reads against a committed manifest.

A result reproduces only on the data it came from, and the shared folder is read in place
(`PIMANN_SHARED`), not versioned with the code. `pimann/core/data_manifest.txt` records the sha256
and size of every file the pipeline reads from it, grouped by what reads them:

- `robot`: the retargeting URDF, which `pimann.core.robot.load_robot("retarget")` builds with
  pinocchio (no geometry, so no meshes): every stage that measures or generates motion;
- `simulation`: the MuJoCo model's URDF and the meshes it names (`pimann.sim.model`);
- `mocap:<key>`: every file the glob of `data.sources.<key>` matches (the retarget stage lists
  and labels them all, whatever `max_takes` keeps), with Bandai Namco's labels beside.

A stage checks the groups it reads before any work (`pimann.core.stage.stage_entry(reads=...)`),
`pimann check-data` checks every group, `pimann check-data --write-manifest` rewrites the
manifest. The manifest is a text file, one line per file (`<sha256> <size> <path>`), so that
a data change is a one-line diff naming the file; 2,000 files of JSON would be noise. It lives
in the package beside this module, which reads it.
"""

from __future__ import annotations

import dataclasses
import hashlib
import re
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from pimann.core.errors import PimannError
from pimann.core.paths import bandai_label_files, shared_dir, shared_glob

MANIFEST = Path(__file__).with_name("data_manifest.txt")
CHUNK = 1 << 20  # bytes read at a time while hashing
ROBOT, SIMULATION, MOCAP = "robot", "simulation", "mocap"
MOCAP_PREFIX = f"{MOCAP}:"
WRITE_HINT = "pimann check-data --write-manifest records it"
HEADER = """\
# pimann data manifest: every file the pipeline reads from the shared folder ($PIMANN_SHARED,
# default ../shared), with its sha256 and size, grouped by what reads it (pimann.core.data_check).
# The stages check the groups they read before any work; `pimann check-data` checks them all;
# `pimann check-data --write-manifest` rewrites this file from the folder and params.yaml.
# [group] what reads it / glob <data.sources path> / <sha256> <size in bytes> <path>
"""


@dataclasses.dataclass(frozen=True)
class Entry:
    """One file: its path inside the shared folder (absolute when outside it), sha256, size."""

    path: str
    sha256: str
    size: int


@dataclasses.dataclass(frozen=True)
class Group:
    """Files read together by one reader; `glob`: the data.sources path that lists them."""

    name: str
    about: str
    files: tuple[Entry, ...]
    glob: str | None = None


def file_sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as stream:
        while chunk := stream.read(CHUNK):
            digest.update(chunk)
    return digest.hexdigest()


def _relative(path: Path, shared: Path) -> str:
    return path.relative_to(shared).as_posix() if path.is_relative_to(shared) else str(path)


def _entry(path: Path, shared: Path) -> Entry:
    return Entry(_relative(path, shared), file_sha256(path), path.stat().st_size)


# ----------------------------------------------------------------------------- the manifest


def read_manifest(path: Path = MANIFEST) -> dict[str, Group]:
    """The manifest's groups by name."""
    if not path.is_file():
        raise PimannError(path, f"data manifest not found ({WRITE_HINT})")
    groups: dict[str, dict[str, Any]] = {}
    current: dict[str, Any] | None = None
    for number, line in enumerate(path.read_text().splitlines(), start=1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        if header := re.fullmatch(r"\[([^\]]+)\]\s*(.*)", line):
            current = {"name": header.group(1), "about": header.group(2), "files": []}
            groups[current["name"]] = current
            continue
        fields = line.split(maxsplit=2) if current is not None else []
        if len(fields) == 2 and fields[0] == "glob":
            current["glob"] = fields[1]
        elif len(fields) == 3 and re.fullmatch(r"[0-9a-f]{64}", fields[0]) and fields[1].isdigit():
            current["files"].append(Entry(fields[2], fields[0], int(fields[1])))
        else:
            raise PimannError(path, f"line {number}: not `[group]`, `glob P` or `sha256 size path`")
    return {name: Group(**{**g, "files": tuple(g["files"])}) for name, g in groups.items()}


def format_manifest(groups: Iterable[Group]) -> str:
    parts = [HEADER]
    for group in groups:
        parts.append(f"\n[{group.name}] {group.about}\n")
        if group.glob is not None:
            parts.append(f"glob {group.glob}\n")
        parts += [f"{e.sha256} {e.size} {e.path}\n" for e in group.files]
    return "".join(parts)


def build_manifest(params: Any, shared: Path | None = None) -> list[Group]:
    """The groups as the folder holds them now: the robot models, and every source of
    `params.data.sources` (its glob's files, Bandai Namco's labels beside)."""
    from pimann.core.robot import MESH_DIRS, MODEL_FILES

    shared = (shared or shared_dir()).resolve()
    if not shared.is_dir():
        raise PimannError(shared, "shared data folder not found (set PIMANN_SHARED or --shared)")
    robots = shared / "robots"

    def files(paths: Iterable[Path]) -> tuple[Entry, ...]:
        unique = dict.fromkeys(paths)  # in order, once each
        for path in unique:
            if not path.is_file():
                raise PimannError(path, "missing: the pipeline reads it")
        return tuple(_entry(path, shared) for path in unique)

    simulation_urdf = robots / MODEL_FILES["simulation"]
    mesh_dir = robots / MESH_DIRS["simulation"]
    meshes = sorted({mesh_dir / Path(name).name for name in _mesh_names(simulation_urdf)})
    groups = [
        Group(
            ROBOT,
            "pimann.core.robot.load_robot('retarget'): pinocchio reads the URDF alone",
            files([robots / MODEL_FILES["retarget"]]),
        ),
        Group(
            SIMULATION,
            "pimann.sim.model (MuJoCo) and load_robot('simulation'): the URDF "
            "and the meshes it names",
            files([simulation_urdf, *meshes]),
        ),
    ]
    for key, source in params.data.sources.items():
        takes = shared_glob(source.path, shared)
        if not takes:
            raise PimannError(source.path, f"data.sources.{key}: the glob matches no file")
        labelled = source.labels == "bandai_namco"
        read = [
            p
            for take in takes
            for p in ((take, *bandai_label_files(take)) if labelled else (take,))
        ]
        about = f"the retarget stage: data.sources.{key}" + (" and its labels" if labelled else "")
        groups.append(Group(f"{MOCAP_PREFIX}{key}", about, files(read), source.path))
    return groups


def _mesh_names(urdf: Path) -> list[str]:
    if not urdf.is_file():
        raise PimannError(urdf, "missing: the pipeline reads it")
    return re.findall(r"<mesh\b[^>]*\bfilename=\"([^\"]+)\"", urdf.read_text())


# ----------------------------------------------------------------------------- checking


def check_groups(groups: Iterable[Group], shared: Path | None = None) -> list[str]:
    """One line per problem, naming the file: missing, differing from the manifest, or
    matched by a group's glob but not listed (the source would read a file of nobody's study)."""
    shared = (shared or shared_dir()).resolve()
    if not shared.is_dir():
        return [f"{shared}: shared data folder not found (set PIMANN_SHARED or --shared)"]
    problems: list[str] = []
    checked: set[str] = set()
    for group in groups:
        for entry in group.files:
            if entry.path not in checked:
                checked.add(entry.path)
                problems += _check_entry(entry, shared)
        if group.glob is not None:
            listed = {entry.path for entry in group.files}
            problems += [
                f"{path}: not in the manifest, matched by {group.glob} ({WRITE_HINT})"
                for path in shared_glob(group.glob, shared)
                if _relative(path, shared) not in listed
            ]
    return problems


def _check_entry(entry: Entry, shared: Path) -> list[str]:
    path = shared / entry.path
    if not path.is_file():
        return [f"{path}: missing"]
    digest = file_sha256(path)
    if digest == entry.sha256:
        return []
    return [
        f"{path}: differs from the manifest (sha256 {digest[:12]}, manifest {entry.sha256[:12]};"
        f" {path.stat().st_size} bytes, manifest {entry.size})"
    ]


def stage_problems(
    reads: Iterable[str],
    params: Any,
    shared: Path | None = None,
    manifest: Path = MANIFEST,
) -> list[str]:
    """What is wrong with the files a stage reads: `reads` names manifest groups, `mocap`
    standing for the group of every source of params.data.sources (read only then), which
    must be in the manifest with the same glob."""
    groups = read_manifest(manifest)
    wanted: list[Group] = []
    problems: list[str] = []
    for name in reads:
        if name == MOCAP:
            for key, source in params.data.sources.items():
                group = groups.get(f"{MOCAP_PREFIX}{key}")
                if group is None or group.glob != source.path:
                    problems.append(
                        f"{manifest}: data.sources.{key} ({source.path}) is not in the manifest "
                        f"({WRITE_HINT})"
                    )
                else:
                    wanted.append(group)
        elif name in groups:
            wanted.append(groups[name])
        else:
            raise PimannError(manifest, f"no group [{name}] (known: {', '.join(groups)})")
    return problems + check_groups(wanted, shared)
