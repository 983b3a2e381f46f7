"""No import cycle between urdaemon's modules (issue 31), counting every import: at the top, inside
functions (lazy) and under ``TYPE_CHECKING``, since each is a dependency of one module on another.

There is none: any cycle fails. ``find_cycles`` is also run on a small package written for the test,
where a deliberately bad import must be found.
"""

from __future__ import annotations

import ast
from collections.abc import Iterable, Mapping
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "urdaemon"


def module_graph(root: Path) -> dict[str, set[str]]:
    """Module → the modules of the same package it imports (anywhere in its text). ``import a.b.c``
    and ``from a.b import c`` name ``a.b.c`` when that is a module, else ``a.b``."""
    top = root.name
    modules: dict[str, Path] = {}
    for path in sorted(root.rglob("*.py")):
        parts = list(path.relative_to(root.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        modules[".".join(parts)] = path
    graph: dict[str, set[str]] = {}
    for name, path in modules.items():
        is_package = path.name == "__init__.py"
        targets: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            if isinstance(node, ast.Import):
                targets.update(alias.name for alias in node.names)
            elif isinstance(node, ast.ImportFrom):
                base = _absolute(name, is_package, node.module, node.level)
                if base is None:
                    continue
                targets.add(base)
                targets.update(f"{base}.{alias.name}" for alias in node.names)
        edges = set()
        for target in targets:
            if not target.startswith(top):
                continue
            while target and target not in modules:
                target = target.rpartition(".")[0]
            if target and target != name:
                edges.add(target)
        graph[name] = edges
    return graph


def _absolute(module: str, is_package: bool, name: str | None, level: int) -> str | None:
    if level == 0:
        return name
    parts = module.split(".")
    if not is_package:
        parts.pop()
    parts = parts[: len(parts) - (level - 1)]
    return ".".join([*parts, name] if name else parts) or None


def find_cycles(graph: Mapping[str, Iterable[str]]) -> list[frozenset[str]]:
    """The strongly connected groups of more than one module (Tarjan's algorithm, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    groups: list[frozenset[str]] = []
    counter = 0
    for start in graph:
        if start in index:
            continue
        work = [(start, iter(graph.get(start, ())))]
        index[start] = low[start] = counter
        counter += 1
        stack.append(start)
        on_stack.add(start)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(graph.get(child, ()))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                parent = work[-1][0]
                low[parent] = min(low[parent], low[node])
            if low[node] == index[node]:
                group = set()
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    group.add(member)
                    if member == node:
                        break
                if len(group) > 1:
                    groups.append(frozenset(group))
    return groups


def test_no_import_cycle() -> None:
    cycles = find_cycles(module_graph(PACKAGE))
    assert not cycles, f"import cycles (lazy and TYPE_CHECKING imports count): {[sorted(c) for c in cycles]}"


def test_a_bad_import_is_found(tmp_path: Path) -> None:
    """A package whose modules form a chain; one lazy import back up the chain makes a cycle."""
    package = tmp_path / "pkg"
    (package / "sub").mkdir(parents=True)
    (package / "__init__.py").write_text("")
    (package / "sub" / "__init__.py").write_text("from pkg.sub import low\n")
    (package / "sub" / "low.py").write_text("X = 1\n")
    (package / "high.py").write_text("from .sub import low\n")
    assert find_cycles(module_graph(package)) == []
    (package / "sub" / "low.py").write_text("def f():\n    from ..high import g\n")  # the bad import
    # low → high → the sub package (``from .sub import …`` runs its __init__) → low
    assert find_cycles(module_graph(package)) == [frozenset({"pkg.high", "pkg.sub", "pkg.sub.low"})]
