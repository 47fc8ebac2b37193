"""dvc.yaml's deps are the code and shared files each stage reads: no more, no fewer.

A stage reruns when a dep changes, so a module missing from its deps lets a code change pass
unseen (stale outputs), and a module listed that the stage never imports reruns it for
nothing (a rollout or MuJoCo run redone after a reworded claim). The import closure of each
stage script over the pimann package is read statically (`ast`, every import in the module,
function bodies included) and compared with the stage's deps; the shared files read through
pimann.core.robot's MODEL_FILES / MESH_DIRS / load_robot and pimann.core.paths.resolve_shared
(params.yaml data.sources) must be listed as `../shared/...` paths.
"""

from __future__ import annotations

import ast
import glob
import inspect
import re
from pathlib import Path, PurePosixPath

import pytest
import yaml

from pimann.core.paths import PACKAGE_CHECKOUT, shared_dir
from pimann.core.robot import MESH_DIRS, MODEL_FILES, load_robot

ROOT = PACKAGE_CHECKOUT
PACKAGE = "pimann"
SHARED_DEP = "../shared"  # the default shared folder beside the checkout, as dvc.yaml names it
CODE_PREFIXES = (f"{PACKAGE}/", "stages/")
# Reading a rollout must not rerun when the claims or their evaluation are reworded.
DATA_CHECK = f"{PACKAGE}/core/data_check.py"
PATHS = f"{PACKAGE}/core/paths.py"
EVALUATION_MODULES = (
    "pimann/evaluate/evaluation.py",
    "pimann/evaluate/claims.py",
)
GENERATION_STAGES = ("rollout", "rollout_baseline", "simulate")


def _dvc_stages() -> dict[str, dict]:
    return yaml.safe_load((ROOT / "dvc.yaml").read_text())["stages"]


def _params() -> dict:
    return yaml.safe_load((ROOT / "params.yaml").read_text())


def _interpolate(text: str, params: dict) -> str:
    """`${a.b}` from params.yaml, as dvc does; `${item.*}` (matrix) and unknowns stay."""

    def value(match: re.Match) -> str:
        node = params
        for key in match.group(1).split("."):
            if not isinstance(node, dict) or key not in node:
                return match.group(0)
            node = node[key]
        return str(node)

    return re.sub(r"\$\{([^}]+)\}", value, text)


def _dep_path(dep: str | dict) -> str:
    return next(iter(dep)) if isinstance(dep, dict) else dep


# --- the import closure ---------------------------------------------------------------------


def _module_file(root: Path, name: str) -> Path | None:
    base = root.joinpath(*name.split("."))
    for candidate in (base / "__init__.py", base.with_suffix(".py")):
        if candidate.is_file():
            return candidate
    return None


def _module_name(root: Path, path: Path) -> list[str]:
    parts = list(path.relative_to(root).with_suffix("").parts)
    return parts[:-1] if parts[-1] == "__init__" else parts


def _imported_names(root: Path, path: Path) -> set[str]:
    """Every dotted name an import statement of the module may load, anywhere in it."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative: from the module's own package
                package = _module_name(root, path)
                if path.name != "__init__.py":
                    package = package[:-1]
                package = package[: len(package) - node.level + 1]
                base = ".".join(package + ([node.module] if node.module else []))
            else:
                base = node.module or ""
            names.add(base)
            # `from pimann.x import y` loads pimann.x.y when y is a submodule
            names.update(f"{base}.{alias.name}" for alias in node.names if alias.name != "*")
    return names


def _imported_files(root: Path, path: Path, package: str) -> set[Path]:
    """The package's files one module's imports run: each named module and the __init__.py
    of every package above it."""
    files = set()
    for name in _imported_names(root, path):
        if name != package and not name.startswith(package + "."):
            continue
        parts = name.split(".")
        for depth in range(1, len(parts) + 1):
            found = _module_file(root, ".".join(parts[:depth]))
            if found is not None:
                files.add(found)
    return files


def import_closure(script: Path, root: Path = ROOT, package: str = PACKAGE) -> set[Path]:
    """The script and every file of `package` it imports, directly or through others."""
    seen: set[Path] = set()
    todo = [script]
    while todo:
        path = todo.pop()
        if path not in seen:
            seen.add(path)
            todo.extend(_imported_files(root, path, package) - seen)
    return seen


def _relative(paths: set[Path]) -> set[str]:
    return {path.relative_to(ROOT).as_posix() for path in paths}


# --- the shared files a closure reads -------------------------------------------------------


def _constant(node: ast.expr | None) -> str | None:
    return node.value if isinstance(node, ast.Constant) and isinstance(node.value, str) else None


def _called_name(node: ast.Call) -> str | None:
    func = node.func
    return func.id if isinstance(func, ast.Name) else getattr(func, "attr", None)


def _subscripted_name(node: ast.Subscript) -> str | None:
    value = node.value
    return value.id if isinstance(value, ast.Name) else getattr(value, "attr", None)


def _glob_root(pattern: str) -> str:
    """The folder a glob reads under: its parts up to the first with a wildcard."""
    parts = PurePosixPath(pattern).parts
    first_wildcard = next((i for i, part in enumerate(parts) if glob.has_magic(part)), None)
    return PurePosixPath(*parts[:first_wildcard]).as_posix()


def _source_paths(params: dict) -> set[str]:
    """data.sources' paths of params.yaml and of every profile's overrides."""
    paths = {source["path"] for source in params["data"]["sources"].values()}
    for overrides in params.get("profiles", {}).values():
        paths.update(
            value
            for key, value in (overrides or {}).items()
            if re.fullmatch(r"data\.sources\.[^.]+\.path", key)
        )
    return {_glob_root(path) for path in paths if not PurePosixPath(path).is_absolute()}


def shared_reads(files: set[Path], params: dict) -> dict[str, str]:
    """Shared files (relative to the shared folder) the modules read -> the module that reads.

    `load_robot(variant)` and `MODEL_FILES[variant]` read that variant's URDF (load_robot's
    default without an argument, every variant with a computed one), `MESH_DIRS[variant]` its
    mesh folder, and `resolve_shared` the mocap sources of params.yaml data.sources.
    """
    default = inspect.signature(load_robot).parameters["variant"].default
    robots = PurePosixPath("robots")
    reads: dict[str, str] = {}
    for path in sorted(files):
        module = path.relative_to(ROOT).as_posix()
        if module in (DATA_CHECK, PATHS):  # the check reads what stage_entry(reads=...)
            continue  # names; paths.py defines resolve_shared, its callers read
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            found: list[str] = []
            if isinstance(node, ast.Call) and _called_name(node) == "load_robot":
                argument = node.args[0] if node.args else None
                for keyword in node.keywords:
                    argument = keyword.value if keyword.arg == "variant" else argument
                variant = _constant(argument) if argument is not None else default
                variants = [variant] if variant is not None else list(MODEL_FILES)
                found = [(robots / MODEL_FILES[v]).as_posix() for v in variants]
            elif isinstance(node, ast.Subscript) and _constant(node.slice) is not None:
                # robot.py's own MODEL_FILES[variant] looks up its caller's variant: no constant
                table = {"MODEL_FILES": MODEL_FILES, "MESH_DIRS": MESH_DIRS}.get(
                    _subscripted_name(node) or ""
                )
                if table is not None:
                    found = [(robots / table[_constant(node.slice)]).as_posix()]
            elif isinstance(node, ast.Call) and _called_name(node) in (
                "resolve_shared",
                "shared_glob",
            ):
                found = sorted(_source_paths(params))
            for shared in found:
                reads.setdefault(shared, module)
    return reads


def checked_reads(script: Path, params: dict) -> dict[str, str]:
    """Shared files the data check of `stage_entry(reads=groups)` hashes before the stage
    runs -> the script: `robot` the retargeting URDF, `simulation` the MuJoCo model's URDF
    and meshes, `mocap` the data.sources."""
    robots = PurePosixPath("robots")
    by_group = {
        "robot": [(robots / MODEL_FILES["retarget"]).as_posix()],
        "simulation": [
            (robots / MODEL_FILES["simulation"]).as_posix(),
            (robots / MESH_DIRS["simulation"]).as_posix(),
        ],
        "mocap": sorted(_source_paths(params)),
    }
    reads: dict[str, str] = {}
    for node in ast.walk(ast.parse(script.read_text(), filename=str(script))):
        if isinstance(node, ast.Call) and _called_name(node) == "stage_entry":
            for keyword in node.keywords:
                if keyword.arg == "reads":
                    for group in ast.literal_eval(keyword.value):
                        for shared in by_group[group]:
                            reads.setdefault(shared, script.relative_to(ROOT).as_posix())
    return reads


# --- the stages -----------------------------------------------------------------------------


def _stage_script(name: str, stage: dict) -> Path:
    match = re.search(r"\bpython\s+(stages/\S+\.py)\b", stage["cmd"])
    assert match, f"stage {name}: its cmd names no stages/<x>.py script: {stage['cmd']!r}"
    return ROOT / match.group(1)


def _covers(dep: str, path: str) -> bool:
    return path == dep or path.startswith(dep.rstrip("/") + "/")


def _check_stage(name: str, stage: dict, params: dict) -> list[str]:
    """What is wrong with one stage's deps, one line each (none: right)."""
    deps = {_interpolate(_dep_path(dep), params) for dep in stage.get("deps", [])}
    closure = import_closure(_stage_script(name, stage))
    modules = _relative(closure)
    code_deps = {dep for dep in deps if dep.startswith(CODE_PREFIXES)}
    shared_deps = {dep for dep in deps if dep.startswith(SHARED_DEP + "/")}
    script = _stage_script(name, stage)
    read = {**checked_reads(script, params), **shared_reads(closure, params)}
    reads = {f"{SHARED_DEP}/{path}": module for path, module in read.items()}
    problems = []
    for module in sorted(modules):
        if not any(_covers(dep, module) for dep in code_deps):
            problems.append(f"missing dep {module} (imported)")
    for dep in sorted(code_deps):
        if not any(_covers(dep, module) for module in modules):
            problems.append(f"extra dep {dep} (not imported)")
    for shared, module in sorted(reads.items()):
        if not any(_covers(dep, shared) for dep in shared_deps):
            problems.append(f"missing dep {shared} (read by {module})")
    for dep in sorted(shared_deps):
        if not any(_covers(dep, shared) for shared in reads):
            problems.append(f"extra dep {dep} (nothing imported reads it)")
    return problems


def test_every_stage_lists_what_it_imports_and_reads():
    params = _params()
    problems = {
        name: found
        for name, stage in _dvc_stages().items()
        if (found := _check_stage(name, stage, params))
    }
    report = "\n".join(
        f"{name}:\n" + "\n".join(f"  - {line}" for line in lines)
        for name, lines in problems.items()
    )
    assert not problems, f"dvc.yaml deps differ from what the stages import and read:\n{report}"


@pytest.mark.parametrize("name", GENERATION_STAGES)
def test_generation_stages_do_not_import_the_evaluation(name):
    stage = _dvc_stages()[name]
    modules = _relative(import_closure(_stage_script(name, stage)))
    assert not modules & set(EVALUATION_MODULES), (
        f"stage {name} imports {sorted(modules & set(EVALUATION_MODULES))}: a reworded claim "
        "would rerun it"
    )


def test_listed_shared_files_exist():
    """Every `../shared/...` dep names a file or folder of the shared folder (typos)."""
    if not shared_dir().is_dir():
        pytest.skip(f"no shared folder at {shared_dir()}")
    listed = {
        _dep_path(dep)
        for stage in _dvc_stages().values()
        for dep in stage.get("deps", [])
        if _dep_path(dep).startswith(SHARED_DEP + "/")
    }
    assert listed, "no stage lists a shared file"
    missing = sorted(d for d in listed if not (shared_dir() / d[len(SHARED_DEP) + 1 :]).exists())
    assert not missing, f"dvc.yaml deps not in {shared_dir()}: {missing}"


def test_closure_follows_every_kind_of_import(tmp_path):
    """Imports inside functions, submodules named by `from`, relative imports and package
    __init__ files are all followed; modules never imported are not."""
    package = tmp_path / "pkg"
    (package / "sub").mkdir(parents=True)
    files = {
        "pkg/__init__.py": "",
        "pkg/a.py": "def f():\n    import pkg.b\n",
        "pkg/b.py": "from pkg.sub import c\n",
        "pkg/sub/__init__.py": "",
        "pkg/sub/c.py": "from . import d\nfrom .e import thing\n",
        "pkg/sub/d.py": "",
        "pkg/sub/e.py": "thing = 1\n",
        "pkg/unused.py": "",
    }
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    script = tmp_path / "script.py"
    script.write_text("import os\n\ndef main():\n    from pkg import a\n")
    closure = {p.relative_to(tmp_path).as_posix() for p in import_closure(script, tmp_path, "pkg")}
    assert closure == {"script.py"} | (set(files) - {"pkg/unused.py"})


def test_shared_reads_follow_the_robot_variants():
    """The simulation model reads its URDF and meshes; generation the default (retarget) URDF;
    the mocap clips the data.sources folders."""
    params = _params()
    sim_reads = shared_reads({ROOT / "pimann/sim/model.py"}, params)
    assert set(sim_reads) == {
        f"robots/{MODEL_FILES['simulation']}",
        f"robots/{MESH_DIRS['simulation']}",
    }
    assert set(shared_reads({ROOT / "pimann/generate/rollout_batch.py"}, params)) == {
        f"robots/{MODEL_FILES['retarget']}"
    }
    clips = set(shared_reads({ROOT / "pimann/mocap/clips.py"}, params))
    assert "data/mocap/bandai-namco/dataset" in clips
    assert not any(glob.has_magic(path) for path in clips)


# train.* settings that do not change a trained model: the matrix itself, and where or in what
# slices it runs (tests/test_train.py shows members train alike in any group and batch)
# settings that change how fast, not what, a training learns (threads: rounding only)
TRAIN_NOT_RESULT = {"pi_weights", "eval_batch_size", "device", "workers", "threads", "adherent"}


@pytest.mark.parametrize("name", ["train", "train_baseline"])
def test_trainings_list_every_train_setting_that_changes_a_model(name):
    """A train.* key the training reads but DVC does not track would let an edit of it pass
    unseen (the models of the other value kept): each one is a param of both trainings."""
    import dataclasses

    from pimann.core.params import TrainParams

    listed = set(_dvc_stages()[name]["params"])
    wanted = {f"train.{f.name}" for f in dataclasses.fields(TrainParams)}
    wanted -= {f"train.{key}" for key in TRAIN_NOT_RESULT}
    assert not wanted - listed, f"{name}: params not listed in dvc.yaml: {sorted(wanted - listed)}"


def _stages_listing(module: str) -> set[str]:
    """The stages a code edit of `module` reruns directly (its deps cover the file)."""
    params = _params()
    return {
        name
        for name, stage in _dvc_stages().items()
        if any(_covers(_interpolate(_dep_path(dep), params), module) for dep in stage["deps"])
    }


def test_editing_the_steering_law_reruns_the_rollouts_and_no_training():
    """The steering law acts at generation (paper Sec. IV): its rollouts rerun, and what reads
    them after, but never the features or a training, which lie upstream."""
    reruns = _stages_listing("pimann/generate/steering.py")
    assert {"rollout", "rollout_baseline"} <= reruns
    assert not reruns & {"retarget", "data_report", "features", "train", "train_baseline"}


def test_rewording_a_claim_reruns_the_evaluation_onward_only():
    """The claims are judged by the evaluate stage; the data report, generation and the
    trainings never import them."""
    module = "pimann/evaluate/claims.py"
    reruns = _stages_listing(module)
    assert "evaluate" in reruns, module
    assert reruns <= {"evaluate", "figures", "report"}, f"{module} reruns {sorted(reruns)}"
