"""The import direction of the design, floor by floor: the core (``satenv``) -> ``satenv.baselines``
-> ``satenv.training`` -> ``satenv.bench`` -> ``satenv.cli`` (the ``satenv`` command), never upward,
and no cycle between modules (imports inside functions included: a lazy import hides a cycle, it does
not remove it)."""

from __future__ import annotations

import ast
import functools
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FLOORS = ("satenv", "satenv.baselines", "satenv.training", "satenv.bench", "satenv.cli")
"""The floors, lowest first; a module belongs to the highest floor its name starts with."""
ENTRY_POINTS = {"satenv.__main__": "satenv.cli"}
"""Modules on a floor their name does not say: ``python -m satenv`` is the ``satenv`` command."""


def floor(module: str) -> int:
    """The floor of a module (an index into :data:`FLOORS`)."""
    module = ENTRY_POINTS.get(module, module)
    return max(i for i, f in enumerate(FLOORS) if module == f or module.startswith(f + "."))


def _module(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(path: Path, module: str) -> set[str]:
    """Every project module ``path`` imports (absolute or relative, at any depth of the file)."""
    out = set()
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*anchor, base] if base else anchor)
            out.add(base)
            out |= {f"{base}.{a.name}" for a in node.names}
    return {m for m in out if m.split(".")[0] == "satenv"}


@functools.cache
def _graph() -> dict[str, set[str]]:
    files = [p for p in (ROOT / "satenv").rglob("*.py") if "policies" not in p.relative_to(ROOT).parts]
    modules = {_module(p): p for p in files}
    graph = {}
    for name, path in modules.items():
        targets = set()
        for imp in _imports(path, name):
            while imp and imp not in modules:     # `from pkg import name`: name may be an attribute
                imp = imp.rpartition(".")[0]
            if imp and imp != name and not name.startswith(imp + "."):   # a package's own parent
                targets.add(imp)
        graph[name] = targets
    return graph


def test_no_upward_import():
    upward = sorted(f"{m} imports {t}" for m, ts in _graph().items() for t in ts if floor(t) > floor(m))
    assert upward == [], "imports go " + " -> ".join(FLOORS) + ", never up:\n" + "\n".join(upward)


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_no_import_cycle():
    graph = {m: {t for t in ts if not m.startswith(t + ".") and t not in FLOORS} for m, ts in _graph().items()}
    cycles = _cycles(graph)
    assert cycles == [], "import cycles (imports inside functions count):\n" + "\n".join(map(" <-> ".join, cycles))


def test_the_check_can_fail(tmp_path):
    """The cycle finder sees a two-module and a three-module cycle."""
    assert _cycles({"a": {"b"}, "b": {"a"}, "c": {"d"}, "d": {"e"}, "e": {"c"}, "f": {"a"}}) == [
        ["a", "b"], ["c", "d", "e"]]


@pytest.mark.parametrize("level", range(len(FLOORS)))
def test_every_floor_is_scanned(level):
    assert any(floor(m) == level for m in _graph())


def test_the_floors_are_told_apart():
    assert [floor(m) for m in ("satenv.tasks", "satenv.baselines.dmpc", "satenv.training", "satenv.bench.perf",
                               "satenv.benchmark", "satenv.cli", "satenv.cliargs", "satenv.__main__")] == [
        0, 1, 2, 3, 0, 4, 0, 4]
