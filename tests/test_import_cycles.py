"""No import cycle between urdaemon's modules (issue 31), counting every import: at the top, inside
functions (lazy) and under ``TYPE_CHECKING``, since each is a dependency of one module on another.

There is none: any cycle fails. ``find_cycles`` is also run on a small package written for the test,
where a deliberately bad import must be found.
"""

from __future__ import annotations

from pathlib import Path

from tests.import_graph import find_cycles, module_graph

PACKAGE = Path(__file__).resolve().parents[1] / "urdaemon"


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
