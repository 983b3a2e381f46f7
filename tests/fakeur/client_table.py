"""The table of what independent clients can call on the fake, read from docs/fake-robot.md.

The section ``## What independent clients can call`` holds one ``### <client>`` heading per client
interface and under it a table whose rows are ``| `call` | outcome | what happens |``. The outcome is
one word, so flipping a row when the fake is fixed is a one-word edit:

- ``works``: the call does what the client documents, checked against the fake;
- ``refused``: the fake refuses it on purpose (not simulated: the third column says why);
- ``fails``: the call should work and does not; the third column says what happens (a gap to fix);
- ``client``: the call fails on the fake as it fails on a controller, through the client's own doing
  (the third column gives the evidence); the fake does not imitate the client's mistake away.
"""

from __future__ import annotations

import re
from pathlib import Path

__all__ = ["OUTCOMES", "SECTION", "read_table"]

DOC = Path(__file__).resolve().parents[2] / "docs" / "fake-robot.md"
SECTION = "## What independent clients can call"
OUTCOMES = ("works", "refused", "fails", "client")

_ROW = re.compile(r"^\|\s*`([A-Za-z_][A-Za-z0-9_]*)`\s*\|\s*([a-z]+)\s*\|(.*)\|\s*$")


def read_table(client: str, doc: Path = DOC) -> dict[str, str]:
    """``{call: outcome}`` of the table under ``### client`` in the section; ValueError on a
    malformed row, an unknown outcome, a call listed twice, or a missing section or heading."""
    lines = doc.read_text(encoding="utf-8").splitlines()
    try:
        start = lines.index(SECTION)
    except ValueError:
        raise ValueError(f"{doc} has no section {SECTION!r}") from None
    rows: dict[str, str] | None = None
    for line in lines[start + 1 :]:
        if line.startswith("## "):
            break
        if line.startswith("### "):
            if rows is not None:
                break
            if line[4:].strip() == client:
                rows = {}
            continue
        if rows is None or not line.startswith("| `"):
            continue
        match = _ROW.match(line)
        if match is None:
            raise ValueError(f"malformed row under {client!r}: {line}")
        call, outcome = match.group(1), match.group(2)
        if outcome not in OUTCOMES:
            raise ValueError(f"{call}: outcome {outcome!r} is none of {OUTCOMES}")
        if call in rows:
            raise ValueError(f"{call} is listed twice under {client!r}")
        rows[call] = outcome
    if not rows:
        raise ValueError(f"no table under '### {client}' in {SECTION!r} of {doc}")
    return rows
