"""docs/architecture.md's package table stays true to the code: every package and top-level module of
urdaemon/ has a row (named in its first column), and every name there exists; and it stays short:
no cell of any of its tables over ``MAX_CELL`` characters (issue 31: a newcomer reads it in ten
minutes). Its "may use" column is checked against the imports by tests/test_package_direction.py."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "urdaemon"
DOC = ROOT / "docs" / "architecture.md"
NOT_IN_THE_TABLE = {"__init__.py", "__main__.py"}
MAX_CELL = 400
"""The most characters a table cell may hold."""


def _named() -> set[str]:
    """The names in the first column of the table's rows (`name.py`, `package/`)."""
    names: set[str] = set()
    for line in DOC.read_text().splitlines():
        if not line.startswith("| `"):
            continue
        first = line.split("|")[1]
        names.update(re.findall(r"`([^`]+)`", first))
    return names


def _in_code() -> set[str]:
    found = set()
    for path in PACKAGE.iterdir():
        if path.name in NOT_IN_THE_TABLE or path.name.startswith(("_", ".")):
            continue
        if path.is_dir() and (path / "__init__.py").exists():
            found.add(f"{path.name}/")
        elif path.suffix == ".py":
            found.add(path.name)
    return found


def test_every_package_and_module_has_a_row() -> None:
    missing = sorted(_in_code() - _named())
    assert not missing, f"docs/architecture.md's package table has no row for: {missing}"


def test_every_row_names_code_that_exists() -> None:
    gone = sorted(name for name in _named() if not (PACKAGE / name.rstrip("/")).exists())
    assert not gone, f"docs/architecture.md's package table names what is not in urdaemon/: {gone}"


def long_cells(text: str) -> list[str]:
    """``line N, column C: L characters`` for every table cell of ``text`` over ``MAX_CELL``."""
    found = []
    for number, line in enumerate(text.splitlines(), start=1):
        if line.startswith("|"):
            for column, cell in enumerate(line.strip().strip("|").split("|"), start=1):
                if len(cell.strip()) > MAX_CELL:
                    found.append(f"line {number}, column {column}: {len(cell.strip())} characters")
    return found


def test_no_cell_is_longer_than_the_limit() -> None:
    long = long_cells(DOC.read_text(encoding="utf-8"))
    assert not long, (
        f"docs/architecture.md's cells over {MAX_CELL} characters (say less; link a page): {long}"
    )


def test_a_long_cell_is_found() -> None:
    assert long_cells(f"| `a.py` | {'x' * MAX_CELL} | stdlib |") == []
    assert long_cells(f"| `a.py` | {'x' * (MAX_CELL + 1)} | stdlib |") == [
        f"line 1, column 2: {MAX_CELL + 1} characters"
    ]
