"""docs/architecture.md's package table stays true to the code: every package and top-level module of
urdaemon/ has a row (named in its first column), and every name there exists."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "urdaemon"
DOC = ROOT / "docs" / "architecture.md"
NOT_IN_THE_TABLE = {"__init__.py", "__main__.py"}


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
