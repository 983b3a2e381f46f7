"""Shape rules, checked on the source: no module over 600 lines (issue 31), no class over 400, no
function over 60 (issue 15).

The places still over a limit are listed below with their size today; the list only shrinks: a new
place over a limit fails, and so does a listed one that grew. When one is split, take it off the list
(the test says so when a listed place has come under its limit).
"""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "urdaemon"
MAX_CLASS_LINES = 400
MAX_FUNCTION_LINES = 60
MAX_MODULE_LINES = 600

MODULES_STILL_OVER: dict[str, int] = {}
"""``urdaemon/…`` module → its length in lines today, for each module still over 600 (issue 31 cuts them
by job); the list only shrinks, as ``STILL_OVER`` below."""

STILL_OVER: dict[str, int] = {}
"""``path:qualified.name`` → its length in lines today, for each place still over its limit."""


def _sizes() -> dict[str, tuple[int, int]]:
    """``path:qualified.name`` → (length in lines, its limit) for every class and function."""
    found: dict[str, tuple[int, int]] = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE.parent).as_posix()

        def visit(node: ast.AST, prefix: str, rel: str = rel) -> None:
            for child in ast.iter_child_nodes(node):
                if isinstance(child, ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
                    name = f"{prefix}{child.name}"
                    assert child.end_lineno is not None
                    length = child.end_lineno - child.lineno + 1
                    limit = MAX_CLASS_LINES if isinstance(child, ast.ClassDef) else MAX_FUNCTION_LINES
                    found[f"{rel}:{name}"] = (length, limit)
                    visit(child, f"{name}.")

        visit(ast.parse(path.read_text(), filename=str(path)), "")
    return found


def test_no_class_or_function_grows_over_its_limit() -> None:
    over = {place: length for place, (length, limit) in _sizes().items() if length > limit}
    new = {place: length for place, length in over.items() if place not in STILL_OVER}
    assert not new, f"over the limit (classes {MAX_CLASS_LINES}, functions {MAX_FUNCTION_LINES} lines): {new}"
    grown = {
        place: (STILL_OVER[place], length)
        for place, length in over.items()
        if length > STILL_OVER.get(place, 0)
    }
    assert not grown, f"grew since the list was made (was, now): {grown}"


def test_the_list_names_only_places_still_over() -> None:
    sizes = _sizes()
    done = [place for place in STILL_OVER if place not in sizes or sizes[place][0] <= sizes[place][1]]
    assert not done, f"under the limit now (or gone): take them off STILL_OVER: {done}"


def _module_sizes() -> dict[str, int]:
    return {
        path.relative_to(PACKAGE.parent).as_posix(): len(path.read_text().splitlines())
        for path in sorted(PACKAGE.rglob("*.py"))
    }


def test_no_module_grows_over_its_limit() -> None:
    over = {path: lines for path, lines in _module_sizes().items() if lines > MAX_MODULE_LINES}
    new = {path: lines for path, lines in over.items() if path not in MODULES_STILL_OVER}
    assert not new, f"modules over {MAX_MODULE_LINES} lines (cut them by job): {new}"
    grown = {
        path: (MODULES_STILL_OVER[path], lines)
        for path, lines in over.items()
        if lines > MODULES_STILL_OVER.get(path, 0)
    }
    assert not grown, f"grew since the list was made (was, now): {grown}"


def test_the_module_list_names_only_modules_still_over() -> None:
    sizes = _module_sizes()
    done = [path for path in MODULES_STILL_OVER if sizes.get(path, 0) <= MAX_MODULE_LINES]
    assert not done, (
        f"at most {MAX_MODULE_LINES} lines now (or gone): take them off MODULES_STILL_OVER: {done}"
    )
