"""Every module the code, docs and params cite, dotted (`pimann.learn.train.pick_precision`,
`diagnostics.gait_shape`) or as a path (`pimann/learn/gait_phase.py`), still names a module or
an attribute of one: a move or a rename that leaves a docstring pointing nowhere fails here."""

from __future__ import annotations

import importlib
import re

from pimann.core.paths import PACKAGE_CHECKOUT

ROOT = PACKAGE_CHECKOUT
PATH = re.compile(r"\b((?:pimann|diagnostics|benchmarks|stages|tests)/[\w/]+\.py)\b")
DOTTED = re.compile(r"\b((?:pimann|diagnostics|benchmarks)(?:\.[A-Za-z_][A-Za-z0-9_]*)+)")
CITING = ("pimann/**/*.py", "stages/*.py", "diagnostics/*.py", "benchmarks/*.py", "docs/*.md")
CITING_FILES = ("README.md", "params.yaml", "dvc.yaml")


def resolves(name: str) -> bool:
    """Whether the longest importable prefix of `name` has the rest as attributes."""
    parts = name.split(".")
    for end in range(len(parts), 0, -1):
        try:
            target = importlib.import_module(".".join(parts[:end]))
        except ImportError:
            continue
        for attribute in parts[end:]:
            if not hasattr(target, attribute):
                return False
            target = getattr(target, attribute)
        return True
    return False


def unresolved(text: str) -> list[str]:
    names = {m.group(1) for m in DOTTED.finditer(text)}
    stale = {n for n in names if not n.endswith(".py") and not resolves(n)}
    return sorted(stale | {p for p in PATH.findall(text) if not (ROOT / p).is_file()})


def test_the_check_sees_a_module_that_is_gone():
    text = "built by pimann.learn.rollout_states, read by pimann.learn.train.pick_precision"
    assert unresolved(text) == ["pimann.learn.rollout_states"]
    assert unresolved("pimann.core.robot.NO_SUCH_NAME") == ["pimann.core.robot.NO_SUCH_NAME"]
    assert unresolved("see pimann/generate/generator.py") == ["pimann/generate/generator.py"]
    assert unresolved("see pimann/generate/rollout_batch.py") == []


def test_every_cited_module_exists():
    files = [p for pattern in CITING for p in ROOT.glob(pattern)]
    files += [ROOT / name for name in CITING_FILES]
    stale = {
        str(path.relative_to(ROOT)): names
        for path in files
        if (names := unresolved(path.read_text()))
    }
    assert stale == {}
