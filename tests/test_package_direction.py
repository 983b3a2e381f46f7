"""Imports go only where docs/architecture.md's package table allows (issue 31).

The table's last column, "may use", is read from the document itself: a row names its package or
top-level module in backticks in the first column (`control/`, `robot.py`) and what it may import in
backticks in the last (words and anything in parentheses are comments). The line that starts with
``BASE_LINE`` names what every package may use besides. Every import in urdaemon/ counts, at the
top, inside functions (lazy) and under ``TYPE_CHECKING`` (tests/import_graph.py reads them).

Checked: every import between two packages is allowed by the importer's row; every use a row allows
is one the code makes (so the table stays true, not only permissive); the table is a layering (no
package may use, through any chain of rows, itself). The imports that still break it are listed in
``STILL_CROSSING``; the list only shrinks. ``direction_violations`` is also run on a small package
written for the test, where a deliberately bad import must be found.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from pathlib import Path

from tests.import_graph import find_cycles, module_graph

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "urdaemon"
DOC = ROOT / "docs" / "architecture.md"
HEADER = "| package | job | may use |"
BASE_LINE = "Every package may also use"

STILL_CROSSING: dict[tuple[str, str], str] = {}
"""(importing module, imported module) → why it is still allowed: imports that break the table today.
Take an entry off when its import is gone (the test says so); never add one."""


def unit_of(module: str, root: Path = PACKAGE) -> str:
    """The table's name for the package or top-level module a module belongs to: ``urdaemon.control.
    move`` → ``control/``, ``urdaemon.robot`` → ``robot.py``, the package root → ``__init__.py``."""
    parts = module.split(".")[1:]
    if not parts:
        return "__init__.py"
    return f"{parts[0]}/" if (root / parts[0]).is_dir() else f"{parts[0]}.py"


def _names(cell: str) -> set[str]:
    """The backticked names of a cell, outside parentheses (a parenthesis is a comment)."""
    depth, kept = 0, []
    for char in cell:
        depth += char == "("
        if depth == 0:
            kept.append(char)
        depth -= char == ")" and depth > 0
    return set(re.findall(r"`([^`]+)`", "".join(kept)))


def may_use_table(text: str) -> tuple[dict[str, set[str]], set[str]]:
    """(package → what it may use, what every package may use) as the document states them."""
    lines = text.splitlines()
    start = lines.index(HEADER)
    table: dict[str, set[str]] = {}
    for line in lines[start + 2 :]:
        if not line.startswith("|"):
            break
        cells = line.strip().strip("|").split("|")
        for name in re.findall(r"`([^`]+)`", cells[0]):
            table[name] = _names(cells[-1])
    base = next(_names(line) for line in lines if line.startswith(BASE_LINE))
    return table, base


def allowed(table: Mapping[str, set[str]], base: set[str]) -> dict[str, set[str]]:
    """What each package may import: its row, and the base for every package outside the base."""
    return {unit: uses | (set() if unit in base else base) for unit, uses in table.items()}


def direction_violations(
    graph: Mapping[str, set[str]], may_use: Mapping[str, set[str]], root: Path
) -> dict[tuple[str, str], str]:
    """Every import between two packages that the importer's row does not allow, with why."""
    found: dict[tuple[str, str], str] = {}
    for module, targets in graph.items():
        mine = unit_of(module, root)
        for target in targets:
            theirs = unit_of(target, root)
            if theirs != mine and theirs not in may_use.get(mine, set()):
                found[(module, target)] = f"{mine} may not use {theirs}"
    return found


def unused_uses(
    graph: Mapping[str, set[str]], table: Mapping[str, set[str]], root: Path
) -> list[tuple[str, str]]:
    """(package, what its row allows) for every allowed use no module of the package makes."""
    made = {(unit_of(m, root), unit_of(t, root)) for m, targets in graph.items() for t in targets}
    return sorted((unit, use) for unit, uses in table.items() for use in uses if (unit, use) not in made)


def _read() -> tuple[dict[str, set[str]], set[str], dict[str, set[str]]]:
    table, base = may_use_table(DOC.read_text(encoding="utf-8"))
    return table, base, module_graph(PACKAGE)


def test_the_table_names_every_package_once_and_only_what_exists() -> None:
    table, base, graph = _read()
    units = {unit_of(module) for module in graph}
    assert units - table.keys() == set(), (
        f"packages with no row in {DOC.name}: {sorted(units - table.keys())}"
    )
    named = set(table) | base | {use for uses in table.values() for use in uses}
    assert named <= units, f"{DOC.name} names what is not in urdaemon/: {sorted(named - units)}"


def test_every_import_goes_where_the_table_allows() -> None:
    table, base, graph = _read()
    found = direction_violations(graph, allowed(table, base), PACKAGE)
    new = {f"{m} → {t}": why for (m, t), why in found.items() if (m, t) not in STILL_CROSSING}
    assert not new, f"imports the 'may use' column of {DOC.name} does not allow: {new}"


def test_the_list_names_only_imports_still_crossing() -> None:
    table, base, graph = _read()
    found = direction_violations(graph, allowed(table, base), PACKAGE)
    gone = sorted(f"{m} → {t}" for m, t in STILL_CROSSING if (m, t) not in found)
    assert not gone, f"allowed now or gone: take them off STILL_CROSSING: {gone}"


def test_every_use_the_table_allows_is_one_the_code_makes() -> None:
    table, _, graph = _read()
    unused = unused_uses(graph, table, PACKAGE)
    assert not unused, f"{DOC.name} allows uses no module makes (take them off the row): {unused}"


def test_the_table_is_a_layering() -> None:
    table, base, _ = _read()
    cycles = find_cycles(allowed(table, base))
    assert not cycles, f"{DOC.name}'s 'may use' column goes round: {[sorted(c) for c in cycles]}"


_DOC = f"""{HEADER}
| --- | --- | --- |
| `__init__.py` | the root | `errors.py` |
| `errors.py` | the errors | stdlib |
| `low/` | the bottom | nothing (not even `high.py`) |
| `high.py` | the top | `low/` |

{BASE_LINE}: `errors.py`, `__init__.py`.
"""


def test_a_bad_import_is_found(tmp_path: Path) -> None:
    """A package of two layers; a lazy import from the bottom up to the top breaks the table."""
    package = tmp_path / "pkg"
    (package / "low").mkdir(parents=True)
    (package / "__init__.py").write_text("")
    (package / "errors.py").write_text("")
    (package / "low" / "__init__.py").write_text("from pkg import errors\n")
    (package / "low" / "leaf.py").write_text("X = 1\n")
    (package / "high.py").write_text("from .low import leaf\n")
    table, base = may_use_table(_DOC)
    assert table == {"__init__.py": {"errors.py"}, "errors.py": set(), "low/": set(), "high.py": {"low/"}}
    assert base == {"errors.py", "__init__.py"}
    may_use = allowed(table, base)
    assert direction_violations(module_graph(package), may_use, package) == {}
    (package / "low" / "leaf.py").write_text("def f():\n    from pkg.high import g\n")  # the bad import
    assert direction_violations(module_graph(package), may_use, package) == {
        ("pkg.low.leaf", "pkg.high"): "low/ may not use high.py"
    }
    assert find_cycles(allowed({**table, "low/": {"high.py"}}, base)) == [frozenset({"low/", "high.py"})]
