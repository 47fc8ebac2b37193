"""The `pimann` command line: mocap, retargeting, rendering, generation, MuJoCo, metrics, and
the check of the shared data.

Every subcommand exits 0 on success; on bad input it prints one line naming the file and the
problem on stderr (no traceback) and exits 2, leaving no partial output (writers are atomic);
`check-data` prints such a line for every file that is missing or differs.
Heavy libraries are imported inside the subcommands so `pimann --help` stays instant.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from collections.abc import Callable
from pathlib import Path

from pimann.core.data_check import MANIFEST
from pimann.core.errors import PimannError, about
from pimann.core.logs import quiet_third_party

EXIT_BAD_INPUT = 2
SKELETON_HELP = "BVH skeleton: a key of params data.skeletons (default: auto, recognised)"


def _params(args: argparse.Namespace):
    from pimann.core.params import load_params

    return load_params(args.params)


def _skeleton(args: argparse.Namespace):
    """The BVH name map `--skeleton` picks from params data.skeletons; None: recognise."""
    if args.skeleton in (None, "auto"):
        return None
    skeletons = _params(args).data.skeletons
    if args.skeleton not in skeletons:
        known = ", ".join(["auto", *sorted(skeletons)])
        raise PimannError(args.params, f"unknown skeleton {args.skeleton!r}; known: {known}")
    return skeletons[args.skeleton]


def cmd_mocap_info(args: argparse.Namespace) -> None:
    from pimann.mocap.io import mocap_info

    print(json.dumps(mocap_info(args.file, _skeleton(args)), indent=2))


def cmd_retarget(args: argparse.Namespace) -> None:
    from pimann.core.trajectory import write_trajectory
    from pimann.mocap.io import read_mocap
    from pimann.mocap.mirror import mirror_trajectory
    from pimann.retarget import retarget_motion

    params = _params(args)
    motion = read_mocap(args.file, _skeleton(args), args.rate)
    trajectory = retarget_motion(motion, params.retarget)
    if args.mirror:
        trajectory = mirror_trajectory(trajectory)
    write_trajectory(args.output, trajectory)


def _read_trajectory(args: argparse.Namespace):
    """The input trajectory; its errors name the file (a reader may name the clip's source)."""
    from pimann.core.trajectory import read_trajectory

    with about(args.file):
        return read_trajectory(args.file, args.group)


def cmd_render(args: argparse.Namespace) -> None:
    from pimann.render.beside_mocap import render_file

    _read_trajectory(args)  # bad input named by its file before any drawing
    skeleton = _skeleton(args) if args.mocap else None
    options = {
        "strip_frames": args.frames,
        "strip_columns": args.columns,
        "frame_rate": args.fps,
        "width": args.width,
        "height": args.height,
    }
    render_file(
        args.file,
        args.output,
        group=args.group,
        mocap_path=args.mocap,
        skeleton=skeleton,
        contacts=_params(args).contacts,
        **{k: v for k, v in options.items() if v is not None},
    )


def cmd_generate(args: argparse.Namespace) -> None:
    from pimann.generate.rollout_batch import generate_file

    params = _params(args)
    generate_file(
        args.model_dir, args.scenario, args.output, not args.no_steering, params, args.params
    )


def cmd_params(args: argparse.Namespace) -> None:
    """The effective params of the profile (default: params.yaml's `profile`), as YAML: the
    base values with the profile's overrides applied, every value checked."""
    import yaml

    from pimann.core.params import as_dict, load_params

    effective = as_dict(load_params(args.params, args.profile))
    effective.pop("profiles")  # applied: what the stages read is below
    print(yaml.safe_dump(effective, sort_keys=False, default_flow_style=False), end="")


def cmd_metrics(args: argparse.Namespace) -> None:
    from pimann.core.robot import load_robot
    from pimann.evaluate.metrics import trajectory_metrics

    trajectory = _read_trajectory(args)
    with about(args.file):
        params = _params(args)
        metrics = trajectory_metrics(
            trajectory, load_robot(), params.evaluate, params.contacts, not args.rule_contacts
        )
    print(json.dumps(metrics, indent=2))


def cmd_simulate(args: argparse.Namespace) -> None:
    from pimann.core.trajectory import read_trajectory
    from pimann.sim.closed_loop import simulate_trajectory
    from pimann.sim.simulation_files import write_simulation
    from pimann.sim.video import check_video_path, render_simulation

    params = _params(args).simulate
    if args.video:
        check_video_path(args.video)  # before minutes of simulation, not after
    trajectory = _read_trajectory(args)
    with about(args.file):  # name the file, not the trajectory's `source`
        result = simulate_trajectory(trajectory, params, args.duration, args.controller)
    summary = write_simulation(
        args.output, result, params, source=str(args.file), rate_hz=params.output_rate_hz
    )
    if args.video:
        render_simulation(
            read_trajectory(args.output),
            args.video,
            params,
            every_n_frames=params.video_every_n,
            width=params.video_width,
            height=params.video_height,
        )
    print(json.dumps(summary, indent=2))


def cmd_check_data(args: argparse.Namespace) -> int:
    """The shared folder against the data manifest: a line per problem on stderr, exit 2."""
    from pimann.core.atomic import write_text_atomic
    from pimann.core.data_check import build_manifest, check_groups, format_manifest, read_manifest

    shared = args.shared.resolve() if args.shared else None
    if args.write_manifest:
        groups = build_manifest(_params(args), shared)
        write_text_atomic(args.manifest, format_manifest(groups))
        count = sum(len(g.files) for g in groups)
        print(f"{args.manifest}: {count} files in {len(groups)} groups")
        return 0
    groups = read_manifest(args.manifest)
    problems = check_groups(groups.values(), shared)
    for problem in problems:
        print(f"pimann check-data: {problem}", file=sys.stderr)
    if problems:
        return EXIT_BAD_INPUT
    count = sum(len(g.files) for g in groups.values())
    print(f"{count} files in {len(groups)} groups match {args.manifest}")
    return 0


def _global_options(parser: argparse.ArgumentParser, default: object) -> None:
    """--params and -v, accepted before and after the subcommand."""
    parser.add_argument(
        "--params", type=Path, default=default, help="params.yaml (default: the repository's)"
    )
    parser.add_argument(
        "-v", "--verbose", action="store_true", default=default, help="log progress"
    )


def _scenario_names() -> str:
    """The scenarios of the repository's params.yaml, for the help text."""
    try:
        from pimann.core.params import load_params

        return ", ".join(load_params().rollout.scenarios)
    except PimannError:
        return "see rollout.scenarios in params.yaml"


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="pimann", description=__doc__.splitlines()[0])
    _global_options(parser, None)
    parser.set_defaults(verbose=False)
    after = argparse.ArgumentParser(add_help=False)
    _global_options(after, argparse.SUPPRESS)  # after the subcommand: override only if given
    sub = parser.add_subparsers(dest="command", required=True)

    def add(name: str, handler: Callable, help_text: str) -> argparse.ArgumentParser:
        command = sub.add_parser(name, help=help_text, description=help_text, parents=[after])
        command.set_defaults(handler=handler)
        return command

    mocap = "a mocap file: XSens .mvnx, XSens YARP log (folder or data.log), or .bvh"
    trajectory = "a trajectory .h5 (one clip, or a collection with --group)"

    info = add("mocap-info", cmd_mocap_info, "format, frames, rate, duration, segments as JSON")
    info.add_argument("file", type=Path, help=mocap)
    info.add_argument("--skeleton", help=SKELETON_HELP)

    retarget = add("retarget", cmd_retarget, "retarget one mocap file to a trajectory file")
    retarget.add_argument("file", type=Path, help=mocap)
    retarget.add_argument("-o", "--output", type=Path, required=True, help="trajectory .h5")
    retarget.add_argument("--mirror", action="store_true", help="mirror across the sagittal plane")
    retarget.add_argument("--skeleton", help=SKELETON_HELP)
    retarget.add_argument(
        "--rate", type=float, metavar="HZ", help="BVH frame rate, overriding the header's"
    )

    render = add("render", cmd_render, "draw a trajectory to .gif, .mp4 or a .png strip")
    render.add_argument("file", type=Path, help=trajectory)
    render.add_argument("-o", "--output", type=Path, required=True, help=".png strip, .gif or .mp4")
    render.add_argument("--group", help="clip group inside a collection file")
    render.add_argument("--mocap", type=Path, help="the human motion to draw beside the robot")
    render.add_argument("--skeleton", help=SKELETON_HELP)
    render.add_argument(
        "--frames",
        type=int,
        metavar="N",
        help="frames of a .png strip, evenly over the clip (default 12)",
    )
    render.add_argument(
        "--columns", type=int, metavar="N", help="frames per row of a .png strip (default 4)"
    )
    render.add_argument(
        "--fps",
        type=float,
        metavar="F",
        help="frames per second of the clip in a .gif or "
        ".mp4, played in real time (default: every second sample)",
    )
    render.add_argument(
        "--width", type=int, metavar="PX", help="of each frame (strip 480, animation 960)"
    )
    render.add_argument(
        "--height", type=int, metavar="PX", help="of each frame (strip 320, animation 480)"
    )

    generate = add("generate", cmd_generate, "roll a trained model out on one scenario")
    generate.add_argument(
        "model_dir",
        type=Path,
        help="a trained model's folder (model.pt, meta.json), e.g. models/w10/0",
    )
    generate.add_argument(
        "--scenario", required=True, help=f"one of rollout.scenarios: {_scenario_names()}"
    )
    generate.add_argument("-o", "--output", type=Path, required=True, help="trajectory .h5")
    generate.add_argument("--no-steering", action="store_true", help="no control-informed steering")

    simulate = add("simulate", cmd_simulate, "walk a trajectory in MuJoCo (either controller)")
    simulate.add_argument("file", type=Path, help=trajectory)
    simulate.add_argument("-o", "--output", type=Path, required=True, help="result .h5")
    simulate.add_argument("--group", help="clip group inside a collection file")
    simulate.add_argument("--video", type=Path, help=".mp4, .gif or .png strip of the walk")
    simulate.add_argument("--duration", type=float, help="simulate at most this many seconds")
    simulate.add_argument(
        "--controller",
        choices=("offline", "online"),
        default="offline",
        help="offline DCM plan (default) or the online centroidal MPC",
    )

    check = add("check-data", cmd_check_data, "the shared data against the data manifest")
    check.add_argument(
        "--shared",
        type=Path,
        metavar="DIR",
        help="data folder (default: $PIMANN_SHARED, else ../shared)",
    )
    check.add_argument(
        "--manifest", type=Path, default=MANIFEST, help="default: the package's data_manifest.txt"
    )
    check.add_argument(
        "--write-manifest",
        action="store_true",
        help="record the folder as it is now (the "
        "robot models and every file of data.sources) instead of checking it",
    )

    metrics = add("metrics", cmd_metrics, "the paper's sliding metrics and drift as JSON")
    metrics.add_argument("file", type=Path, help=trajectory + " (a collection: every clip)")
    metrics.add_argument("--group", help="clip group inside a collection file")
    metrics.add_argument(
        "--rule-contacts",
        action="store_true",
        help="contacts by the contact rule even where the file has flags (data as rollouts)",
    )

    params = add("params", cmd_params, "the effective params of a profile as YAML")
    params.add_argument(
        "--profile", help="a profile of params.yaml's profiles (default: its `profile`)"
    )
    return parser


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    if args.params is None:
        from pimann.core.params import DEFAULT_PARAMS

        args.params = DEFAULT_PARAMS
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING,
        format="%(levelname)s %(name)s: %(message)s",
    )
    quiet_third_party()
    try:
        status = args.handler(args)
    except PimannError as error:
        print(f"pimann {args.command}: {error}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except OSError as error:  # unreadable or unwritable path: still one line, no traceback
        print(f"pimann {args.command}: {error.filename}: {error.strerror}", file=sys.stderr)
        return EXIT_BAD_INPUT
    return status or 0


if __name__ == "__main__":
    sys.exit(main())
