"""Carry the training to a lent GPU machine and its models back, in pieces that fit its limits.

The device machine gets a copy of the working tree (tracked files and untracked, unignored
ones) plus at most 8 ignored paths a call, 64 MiB in all, and has no network, no DVC and no
pinocchio; what a command writes under $OUT comes back, at most 8 files of 16 MiB. So:

    python jobs/gpu_carry.py pack [--wheels DIR]      # here, after `dvc repro -s retarget features`

packs the training stages' inputs (the features files, the robot description from the shared
folder, wheels for what the device lacks) into one gzip'd tar split into pieces that fit a
call beside the working tree, in .carry/in/, and prints each call's `carry` and command. On
the device, call by call while the machine stays warm (ignored paths stay there between
calls), the pieces gather in .carry/in/; the last call runs

    python3 jobs/gpu_carry.py unpack && python3 jobs/gpu_carry.py train \\
        && python3 jobs/gpu_carry.py pack-models --out $OUT --call 0

which checks and extracts the pieces, runs every `train@<w>` stage's and `train_baseline`'s
command of dvc.yaml (the first trains the whole sweep on CUDA), and packs the models, loss
curves and stage-time records into pieces of 16 MiB, 8 files a call (`--call 1`, ... for
the rest, from pieces kept on the device). Back here,

    python jobs/gpu_carry.py unpack-models DIR [DIR ...] [--commit]

checks and extracts the pieces of every call into the checkout, and with --commit records
the stages in dvc.lock (`dvc commit -f`), so `dvc repro` goes on from the trained models.

    python jobs/gpu_carry.py smoke [--features DIR]

dry-runs all of it on this CPU in a temporary folder: a copy of the working tree stands in
for the device, with a tiny profile (`--features`: full.h5 and ground_projected.h5 to use,
default the checkout's, cut to a few hundred samples).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import shutil
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
CARRY = ".carry"  # ignored (.gitignore): what travels only when a call's carry names it
CALL_LIMIT = 64 * 2**20  # the working tree and the carried paths of one call
RETURN_PIECE, RETURN_FILES = 16 * 2**20, 8  # what one call's $OUT brings back
MANIFEST = "manifest.json"
SHARED = f"{CARRY}/shared"  # PIMANN_SHARED on the device: the robot description
WHEELS = f"{CARRY}/wheels"
SITE = "/tmp/pimann-site"  # where the wheels are installed on the device
MARGIN = 2 * 2**20


def _sha256(path: Path) -> str:
    """The file's sha256: each piece and params.yaml are checked on arrival."""
    digest = hashlib.sha256()
    with path.open("rb") as file:
        for block in iter(lambda: file.read(2**20), b""):
            digest.update(block)
    return digest.hexdigest()


def _raw_params(root: Path) -> dict:
    """params.yaml as written: DVC renders its commands from these values, not a profile's."""
    return yaml.safe_load((root / "params.yaml").read_text())


def _tree_files(root: Path) -> list[str]:
    """What every call sends: tracked files and untracked ones git does not ignore."""
    listed = subprocess.run(
        ["git", "ls-files", "-z", "-co", "--exclude-standard"],
        cwd=root,
        capture_output=True,
        check=True,
    ).stdout
    return [n for n in listed.decode().split("\0") if n and (root / n).is_file()]


def _tree_bytes(root: Path) -> int:
    """What every call sends anyway, in bytes (`_tree_files`)."""
    return sum((root / n).stat().st_size for n in _tree_files(root))


def _inputs(
    root: Path, features: Path, shared: Path, wheels: Path | None
) -> list[tuple[Path, str]]:
    """(file here, its path in the device's checkout) of everything the training reads."""
    files = [(features / f"{v}.h5", f"{_features_dir(root)}/{v}.h5") for v in _variants()]
    robots = shared / "robots"
    files += [(p, f"{SHARED}/{p.relative_to(shared)}") for p in sorted(robots.rglob("*"))]
    if wheels is not None:
        kept = [p for p in sorted(wheels.glob("*.whl")) if not p.name.startswith("numpy-")]
        files += [(p, f"{WHEELS}/{p.name}") for p in kept]  # the device's numpy stays
    missing = [str(here) for here, _ in files if not here.exists()]
    if missing:
        raise SystemExit(f"missing: {', '.join(missing)} (dvc repro -s retarget features first)")
    return [(here, there) for here, there in files if here.is_file()]


def _variants() -> tuple[str, ...]:
    """The features files the training stages read."""
    return ("full", "ground_projected")  # train@<w>'s and train_baseline's features


def _features_dir(root: Path) -> str:
    """features.output_dir, relative to the checkout here and there."""
    return str(_raw_params(root)["features"]["output_dir"]).rstrip("/")


def _split(blob: Path, folder: Path, size: int, stem: str) -> list[dict]:
    """blob cut into folder/<stem>.000, .001, ... of `size` bytes; their manifest entries."""
    pieces = []
    with blob.open("rb") as file:
        for k in range(10**3):
            chunk = file.read(size)
            if not chunk:
                break
            path = folder / f"{stem}.{k:03d}"
            path.write_bytes(chunk)
            pieces.append({"name": path.name, "bytes": len(chunk), "sha256": _sha256(path)})
    return pieces


def _tar(files: list[tuple[Path, str]], out: Path) -> None:
    """One gzip'd tar of `files` under their paths in the other checkout."""
    with tarfile.open(out, "w:gz", compresslevel=6) as tar:
        for here, there in files:
            tar.add(here, arcname=there, recursive=False)


def _join(folder: Path, manifest: dict) -> Path:
    """The pieces checked against the manifest and joined; the joined file."""
    joined = folder / manifest["archive"]
    with joined.open("wb") as out:
        for piece in manifest["pieces"]:
            path = folder / piece["name"]
            if not path.is_file():
                raise SystemExit(f"{path}: missing; carry it in a call first")
            if path.stat().st_size != piece["bytes"] or _sha256(path) != piece["sha256"]:
                raise SystemExit(f"{path}: not the piece packed (size or sha256 differ)")
            with path.open("rb") as file:
                shutil.copyfileobj(file, out)
    return joined


def _extract(archive: Path, root: Path) -> list[str]:
    """The archive into the checkout (tarfile's data filter: no path out of it)."""
    with tarfile.open(archive, "r:gz") as tar:
        names = tar.getnames()
        tar.extractall(root, filter="data")
    return names


def pack(
    root: Path,
    features: Path | None = None,
    shared: Path | None = None,
    wheels: Path | None = None,
    piece_bytes: int | None = None,
) -> dict:
    """The training's inputs packed into root/.carry/in/; the manifest (with each call's plan)."""
    if shared is None:
        sys.path.insert(0, str(root))
        from pimann.core.paths import shared_dir

        shared = shared_dir()
    features = root / _features_dir(root) if features is None else features
    folder = root / CARRY / "in"
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir(parents=True)
    files = _inputs(root, features, shared, wheels)
    if piece_bytes is None:
        piece_bytes = CALL_LIMIT - _tree_bytes(root) - MARGIN
        if piece_bytes < 2**20:
            raise SystemExit("the working tree leaves no room for a piece: ignore more of it")
    with tempfile.TemporaryDirectory() as tmp:
        blob = Path(tmp) / "inputs.tar.gz"
        _tar(files, blob)
        pieces = _split(blob, folder, piece_bytes, "inputs.tar.gz")
    manifest = {
        "archive": "inputs.tar.gz",
        "pieces": pieces,
        "params_sha256": _sha256(root / "params.yaml"),
        "files": [there for _, there in files],
        "wheels": wheels is not None,
    }
    (folder / MANIFEST).write_text(json.dumps(manifest, indent=1))
    return manifest


def device_calls(manifest: dict) -> list[dict]:
    """Each device call: the paths it carries and its command (the last one trains)."""
    calls = []
    last = len(manifest["pieces"]) - 1
    for k, piece in enumerate(manifest["pieces"]):
        carry = [f"{CARRY}/in/{MANIFEST}", f"{CARRY}/in/{piece['name']}"]
        command = "ls -l .carry/in"
        if k == last:
            command = (
                "python3 jobs/gpu_carry.py unpack && python3 jobs/gpu_carry.py train"
                " && python3 jobs/gpu_carry.py pack-models --out $OUT --call 0"
            )
        calls.append({"carry": carry, "command": command})
    return calls


def unpack(root: Path) -> list[str]:
    """On the device: the pieces checked, joined and extracted; wheels installed (if any)."""
    folder = root / CARRY / "in"
    manifest = json.loads((folder / MANIFEST).read_text())
    if _sha256(root / "params.yaml") != manifest["params_sha256"]:
        raise SystemExit("params.yaml differs from the one packed with the features")
    joined = _join(folder, manifest)
    names = _extract(joined, root)
    joined.unlink()
    if manifest["wheels"]:
        wheels = sorted(str(p) for p in (root / WHEELS).glob("*.whl"))
        subprocess.run(
            [sys.executable, "-m", "pip", "install", "-q", "--no-index", "--no-deps"]
            + ["--no-compile", "--target", SITE, *wheels],
            check=True,
        )
    return names


def stage_commands(root: Path) -> list[tuple[str, str]]:
    """(stage name, command) of every train@<w> and train_baseline, as DVC renders them."""
    stages = yaml.safe_load((root / "dvc.yaml").read_text())["stages"]
    weights = _raw_params(root)["train"]["pi_weights"]  # DVC's matrix: the file's values
    template = " ".join(stages["train"]["cmd"].split())
    commands = [(f"train@{w}", template.replace("${item.w}", str(w))) for w in weights]
    commands.append(("train_baseline", " ".join(stages["train_baseline"]["cmd"].split())))
    return commands


def _device_env(root: Path) -> dict[str, str]:
    """The stages' environment there: this checkout's pimann, the carried robot and wheels."""
    env = dict(os.environ, PIMANN_SHARED=str(root / SHARED))
    # cmeel's wheels (pinocchio's) put their modules in cmeel.prefix/, which a .pth file
    # names; PYTHONPATH's folders read no .pth file, so that folder is named here
    prefix = sorted(str(p) for p in Path(SITE).glob("cmeel.prefix/lib/python*/site-packages"))
    paths = [str(root)] + ([SITE] if Path(SITE).is_dir() else []) + prefix
    env["PYTHONPATH"] = os.pathsep.join(paths + [env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    return env


def train(root: Path) -> None:
    """On the device: each training stage's command, named as DVC names it (its time record)."""
    env = _device_env(root)
    for stage, command in stage_commands(root):
        if command.startswith("python "):  # the device's torch is python3's
            command = f"{sys.executable} {command.removeprefix('python ')}"
        print(f"{stage}: {command}", flush=True)
        subprocess.run(command, shell=True, cwd=root, env=dict(env, DVC_STAGE=stage), check=True)


def _trained(root: Path) -> list[Path]:
    """The training stages' outputs: models, loss curves, stage-time records."""
    names = []
    for stage, command in stage_commands(root):
        words = command.split()
        names += [words[words.index("--out") + 1], words[words.index("--plots") + 1]]
        names.append(f"results/stage_times/{stage}.json")
    return [root / n for n in names]


def pack_models(root: Path, out: Path, call: int, piece_bytes: int = RETURN_PIECE) -> dict:
    """On the device: the outputs packed once into .carry/out/ pieces of 16 MiB; this call's
    share (the manifest and 7 pieces) copied to `out`."""
    folder = root / CARRY / "out"
    manifest_path = folder / MANIFEST
    if call == 0 or not manifest_path.is_file():
        shutil.rmtree(folder, ignore_errors=True)
        folder.mkdir(parents=True)
        files = []
        for path in _trained(root):
            if not path.exists():
                raise SystemExit(f"{path}: not written; did every training stage run?")
            inside = sorted(path.rglob("*")) if path.is_dir() else [path]
            files += [(p, str(p.relative_to(root))) for p in inside if p.is_file()]
        blob = folder / "models.tar.gz"
        _tar(files, blob)
        pieces = _split(blob, folder, piece_bytes, "models.tar.gz")
        blob.unlink()
        manifest = {"archive": "models.tar.gz", "pieces": pieces, "files": [f for _, f in files]}
        manifest["calls"] = -(-len(pieces) // (RETURN_FILES - 1))
        manifest_path.write_text(json.dumps(manifest, indent=1))
    manifest = json.loads(manifest_path.read_text())
    share = manifest["pieces"][call * (RETURN_FILES - 1) : (call + 1) * (RETURN_FILES - 1)]
    out.mkdir(parents=True, exist_ok=True)
    shutil.copy2(manifest_path, out / MANIFEST)
    for piece in share:
        shutil.copy2(folder / piece["name"], out / piece["name"])
    print(f"call {call + 1} of {manifest['calls']}: {len(share)} piece(s) in {out}")
    return manifest


def unpack_models(root: Path, folders: list[Path], commit: bool = False) -> list[str]:
    """Here: the pieces of every call checked, joined and extracted into the checkout."""
    manifest = json.loads((folders[0] / MANIFEST).read_text())
    with tempfile.TemporaryDirectory() as tmp:
        gathered = Path(tmp)
        for folder in folders:
            for path in folder.glob("models.tar.gz.*"):
                shutil.copy2(path, gathered / path.name)
        names = _extract(_join(gathered, manifest), root)
    if commit:
        stages = [stage for stage, _ in stage_commands(root)]
        subprocess.run(["dvc", "commit", "-f", *stages], cwd=root, check=True)
    return names


def _tiny_features(source: Path, target: Path, rows: int = 400) -> None:
    """Each features file cut to its first `rows` training and test samples (h5py)."""
    import h5py

    target.mkdir(parents=True, exist_ok=True)
    for variant in _variants():
        src_path, dst_path = source / f"{variant}.h5", target / f"{variant}.h5"
        with h5py.File(src_path) as src, h5py.File(dst_path, "w") as dst:
            for key, value in src.attrs.items():
                dst.attrs[key] = value
            for name, item in src.items():
                per_sample = name.lower().split("_")[-1] in ("train", "test")
                per_sample |= name.split("_")[0] in ("train", "test")
                dst.create_dataset(name, data=item[:rows] if per_sample else item[()])


SMOKE_PROFILE = {
    "train.seeds": [0],
    "train.epochs": 1,
    "train.max_train_samples": 256,
    "train.workers": 1,
    "model.prediction_hidden": 32,
    "model.gating_hidden": 8,
}


def _tree_copy(root: Path, target: Path) -> None:
    """The device's copy of what a call sends (`_tree_files`)."""
    for name in _tree_files(root):
        (target / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(root / name, target / name)


def smoke(root: Path, work: Path, features: Path | None = None) -> dict:
    """The whole round trip on this CPU: a copy of the tree as `here` and as the device."""
    here, device, back = work / "here", work / "device", work / "back"
    params = _raw_params(root)
    params["profiles"]["quick"] = SMOKE_PROFILE  # the profile names are fixed: quick's values
    params["profile"] = "quick"
    for folder in (here, device, back):  # the tree travels with every call
        folder.mkdir(parents=True)
        _tree_copy(root, folder)
        (folder / "params.yaml").write_text(yaml.safe_dump(params, sort_keys=False))
    source = root / _features_dir(root) if features is None else features
    _tiny_features(source, here / _features_dir(here))
    manifest = pack(here, piece_bytes=64 * 2**10)  # small pieces: the joining is exercised
    (device / CARRY / "in").mkdir(parents=True)
    for name in [MANIFEST] + [p["name"] for p in manifest["pieces"]]:  # the pieces carried
        shutil.copy2(here / CARRY / "in" / name, device / CARRY / "in" / name)
    script = [sys.executable, "jobs/gpu_carry.py"]
    env = {k: v for k, v in os.environ.items() if k not in ("PIMANN_SHARED", "PYTHONPATH")}
    for args in (["unpack"], ["train"]):
        subprocess.run(script + args, cwd=device, env=env, check=True)
    outs = []
    calls = 1
    k = 0
    while k < calls:
        outs.append(work / f"out{k}")
        command = script + ["pack-models", "--out", str(outs[-1]), "--call", str(k)]
        command += ["--piece-bytes", str(16 * 2**10)]  # small: several calls come back
        subprocess.run(command, cwd=device, env=env, check=True)
        calls = json.loads((outs[-1] / MANIFEST).read_text())["calls"]
        k += 1
    names = unpack_models(back, outs)
    for name in names:
        if (device / name).is_file() and (device / name).read_bytes() != (back / name).read_bytes():
            raise SystemExit(f"{name}: differs after the round trip")
    return {"inputs": manifest, "returned": names, "calls": calls}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    commands = parser.add_subparsers(dest="command", required=True)
    p = commands.add_parser("pack", help="here: the training's inputs into .carry/in/")
    p.add_argument("--wheels", type=Path, help="a folder of wheels the device lacks")
    p.add_argument("--features", type=Path, help="default: features.output_dir")
    commands.add_parser("unpack", help="device: check, join and extract the pieces")
    commands.add_parser("train", help="device: every training stage's command")
    p = commands.add_parser("pack-models", help="device: the outputs into $OUT, 8 files a call")
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--call", type=int, default=0)
    p.add_argument("--piece-bytes", type=int, default=RETURN_PIECE, help=argparse.SUPPRESS)
    p = commands.add_parser("unpack-models", help="here: every call's pieces into the checkout")
    p.add_argument("folders", type=Path, nargs="+")
    p.add_argument("--commit", action="store_true", help="then dvc commit -f the stages")
    p = commands.add_parser("smoke", help="the round trip on this CPU, in a temporary folder")
    p.add_argument("--features", type=Path, help="default: features.output_dir")
    args = parser.parse_args(argv)
    if args.command == "pack":
        manifest = pack(ROOT, args.features, wheels=args.wheels)
        calls = device_calls(manifest)
        print(f"{len(manifest['pieces'])} piece(s) in {CARRY}/in; one device call each:")
        for k, call in enumerate(calls):
            print(f"call {k + 1}: carry {json.dumps(call['carry'])}\n  command: {call['command']}")
    elif args.command == "unpack":
        print(f"{len(unpack(ROOT))} file(s) extracted")
    elif args.command == "train":
        train(ROOT)
    elif args.command == "pack-models":
        pack_models(ROOT, args.out, args.call, min(args.piece_bytes, RETURN_PIECE))
    elif args.command == "unpack-models":
        print(f"{len(unpack_models(ROOT, args.folders, args.commit))} file(s) extracted")
    else:
        with tempfile.TemporaryDirectory() as tmp:
            result = smoke(ROOT, Path(tmp), args.features)
        inputs = result["inputs"]
        print(
            f"smoke: {len(inputs['files'])} input file(s) in {len(inputs['pieces'])} piece(s);"
            f" {len(result['returned'])} trained file(s) back in {result['calls']} call(s)"
        )


if __name__ == "__main__":
    main()
