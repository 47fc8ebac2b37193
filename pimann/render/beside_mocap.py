"""`pimann render`'s file reading: a trajectory file drawn beside the mocap clip it came from.

Apart from pimann.render.trajectory because it reads the mocap (pimann.mocap.io), which the
simulation's videos must not import.
"""

from __future__ import annotations

from pathlib import Path

from pimann.core.params import SkeletonParams
from pimann.core.trajectory import read_trajectory
from pimann.mocap.mirror import mirror_human
from pimann.render.trajectory import render_trajectory


def render_file(
    trajectory_path: str | Path,
    output_path: str | Path,
    group: str | None = None,
    mocap_path: str | Path | None = None,
    skeleton: SkeletonParams | None = None,
    **options,
) -> Path:
    """`pimann render`: a trajectory file (one group of a collection), optionally beside the
    mocap clip it came from (read with `skeleton`, default: recognised from its joints), to a
    picture. A mirrored trajectory gets the mirrored person. `options` go to
    `render_trajectory`."""
    trajectory = read_trajectory(trajectory_path, group)
    human = None
    if mocap_path is not None:
        from pimann.mocap.io import read_mocap

        human = read_mocap(mocap_path, skeleton)
        if bool(trajectory.attrs.get("mirrored", False)) != human.mirrored:
            human = mirror_human(human)
    return render_trajectory(trajectory, output_path, human, **options)
