"""pimann's imports go down the pipeline, never up, and never in a circle.

A module imports only its own stage's package or an earlier one in STAGE_ORDER, so editing a
later stage (a claim's wording, the steering law) can never rerun an earlier DVC stage, and a
circle cannot hide behind a function-body import. The graph is read statically (`ast`): every
import statement anywhere in a module, function bodies included.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from pimann.core.paths import PACKAGE_CHECKOUT

PACKAGE = "pimann"
DIAGNOSTICS = "diagnostics"  # beside pimann, above the whole pipeline
# the pipeline's order; `render` (stick-figure drawing) sits above mocap, whose person it
# draws, and below sim, whose videos it draws (the simulation reads only render's robot part)
STAGE_ORDER = (
    "core",
    "mocap",
    "render",
    "retarget",
    "learn",
    "generate",
    "evaluate",
    "sim",
    "report",
    "cli",
)


def module_files(root: Path) -> dict[str, Path]:
    """{dotted module name: file} of every module of the package under `root`."""
    modules = {}
    for path in sorted((root / PACKAGE).rglob("*.py")):
        parts = list(path.relative_to(root).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        modules[".".join(parts)] = path
    return modules


def import_graph(root: Path) -> dict[str, set[str]]:
    """{module: the package's modules it imports}, relative imports resolved."""
    modules = module_files(root)
    graph: dict[str, set[str]] = {}
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        found: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    parent = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join(parent + ([base] if base else []))
                targets = [base] + [f"{base}.{alias.name}" for alias in node.names]
            else:
                continue
            found.update(t for t in targets if t in modules and t != name)
        graph[name] = found
    return graph


def stage_of(module: str) -> str:
    """The pipeline stage of a module: its subpackage, or its own name at the top (cli)."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "core"


def reverse_imports(graph: dict[str, set[str]]) -> list[str]:
    """'a -> b' for each import of a later stage than the importer's own."""
    problems = []
    for module, imported in sorted(graph.items()):
        for target in sorted(imported):
            if target == PACKAGE:
                continue
            if STAGE_ORDER.index(stage_of(target)) > STAGE_ORDER.index(stage_of(module)):
                problems.append(f"{module} -> {target}")
    return problems


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import circle as [a, b, ..., a], or None."""
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    path: list[str] = []

    def visit(module: str) -> list[str] | None:
        state[module] = 1
        path.append(module)
        for target in sorted(graph.get(module, ())):
            if state.get(target) == 1:
                return path[path.index(target) :] + [target]
            if target not in state and (cycle := visit(target)):
                return cycle
        path.pop()
        state[module] = 2
        return None

    for module in sorted(graph):
        if module not in state and (cycle := visit(module)):
            return cycle
    return None


def test_every_module_belongs_to_a_stage():
    stages = {stage_of(module) for module in module_files(PACKAGE_CHECKOUT)}
    assert stages <= set(STAGE_ORDER), f"packages outside STAGE_ORDER: {stages - set(STAGE_ORDER)}"


def test_imports_go_down_the_pipeline():
    problems = reverse_imports(import_graph(PACKAGE_CHECKOUT))
    assert not problems, "imports against the pipeline order:\n" + "\n".join(problems)


def test_no_import_circle():
    cycle = find_cycle(import_graph(PACKAGE_CHECKOUT))
    assert cycle is None, "import circle: " + " -> ".join(cycle)


def imports_of(path: Path, top: str) -> list[str]:
    """The names of `top` or its modules that one file imports, function bodies included."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and not node.level:
            names = [node.module or ""]
        else:
            continue
        found += [name for name in names if name == top or name.startswith(top + ".")]
    return found


def test_the_pipeline_never_imports_the_diagnostics():
    """The diagnostics sit above every stage: a stage importing one would rerun on its edits."""
    files = sorted((PACKAGE_CHECKOUT / PACKAGE).rglob("*.py"))
    files += sorted((PACKAGE_CHECKOUT / "stages").glob("*.py"))
    problems = [
        f"{path.relative_to(PACKAGE_CHECKOUT)} -> {name}"
        for path in files
        for name in imports_of(path, DIAGNOSTICS)
    ]
    assert files and not problems, "the pipeline imports the diagnostics:\n" + "\n".join(problems)


def test_an_import_of_the_diagnostics_is_found(tmp_path: Path):
    module = tmp_path / "m.py"
    module.write_text("import os\n\ndef f():\n    from diagnostics.gait_shape import x\n")
    assert imports_of(module, DIAGNOSTICS) == ["diagnostics.gait_shape"]


@pytest.fixture
def toy_package(tmp_path: Path) -> Path:
    """A package with core, generate and learn stages, learn importing core only."""
    for name, text in {
        "pimann/__init__.py": "",
        "pimann/core/__init__.py": "",
        "pimann/core/a.py": "",
        "pimann/learn/__init__.py": "",
        "pimann/learn/b.py": "from pimann.core import a\n",
        "pimann/generate/__init__.py": "",
        "pimann/generate/c.py": "from pimann.learn.b import thing\n",
    }.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text)
    return tmp_path


def test_a_reverse_import_in_a_function_body_is_found(toy_package: Path):
    assert reverse_imports(import_graph(toy_package)) == []
    (toy_package / "pimann/learn/b.py").write_text(
        "def f():\n    from pimann.generate.c import thing\n"
    )
    assert reverse_imports(import_graph(toy_package)) == ["pimann.learn.b -> pimann.generate.c"]


def test_a_circle_through_relative_imports_is_found(toy_package: Path):
    assert find_cycle(import_graph(toy_package)) is None
    (toy_package / "pimann/core/a.py").write_text("def f():\n    from . import d\n")
    (toy_package / "pimann/core/d.py").write_text("from pimann.core.a import f\n")
    assert find_cycle(import_graph(toy_package)) == [
        "pimann.core.a",
        "pimann.core.d",
        "pimann.core.a",
    ]
