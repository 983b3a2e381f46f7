"""CONTRIBUTING.md's commit scopes cover the code (issue 31): one scope vocabulary, every top-level
module and package of urdaemon/ named in exactly one scope's row, and no scope named twice."""

from __future__ import annotations

import re
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "urdaemon"


def scope_rows() -> list[tuple[str, str]]:
    """(scope, what it covers) for each row of the table under '## Commits'."""
    text = (ROOT / "CONTRIBUTING.md").read_text()
    section = text.split("## Commits", 1)[1].split("\n## ", 1)[0]
    rows = []
    for line in section.splitlines():
        match = re.match(r"\| `([a-z]+)` \| (.+) \|$", line)
        if match:
            rows.append((match[1], match[2]))
    return rows


def top_level_units() -> set[str]:
    units = {p.name for p in PACKAGE.iterdir() if p.suffix == ".py"}
    units |= {f"{p.name}/" for p in PACKAGE.iterdir() if p.is_dir() and any(p.glob("*.py"))}
    return units


def test_scopes_are_named_once() -> None:
    counts = Counter(scope for scope, _ in scope_rows())
    assert len(counts) >= 10, "the scope table under '## Commits' is missing"
    assert [s for s, n in counts.items() if n > 1] == []


def test_every_module_and_package_has_one_scope() -> None:
    """A module is named as itself; a package as itself or by the parts it splits into across scopes
    (backends/: `backends/base.py` for the shared part, `backends/ur/` for ur, …)."""
    exact: Counter[str] = Counter()
    touched: set[str] = set()
    for _, covers in scope_rows():
        for name in set(re.findall(r"`([a-z_./]+)`", covers)):
            exact[name] += 1
            touched |= {u for u in top_level_units() if name == u or (u.endswith("/") and name.startswith(u))}
    missing = sorted(top_level_units() - touched)
    twice = sorted(u for u in top_level_units() if exact[u] > 1)
    assert not missing, f"CONTRIBUTING.md names no commit scope for {missing}"
    assert not twice, f"CONTRIBUTING.md names more than one scope for {twice}"
