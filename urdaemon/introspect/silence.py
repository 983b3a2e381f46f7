"""Why nothing arrives on a key: a typo'd robot or key, a cell nobody serves, or a key that is
published only when something happens. Pure: the key and what the daemons answered in, the verdict out.
"""

from __future__ import annotations

from dataclasses import dataclass

from urdaemon.introspect.survey import Survey
from urdaemon.model import CELL_LEVEL_KEYS

__all__ = ["SILENCE_S", "Silence", "explain"]

SILENCE_S = 3.0
"""How long ``echo`` and ``hz`` wait for a first message before they look into why none came."""
SHOWN = 8
"""Names listed at most in a verdict."""


@dataclass(frozen=True, slots=True)
class Silence:
    """The verdict on a key nothing arrived on."""

    published: bool
    """A daemon that answered publishes on a key matching it (or none answered to tell): waiting may help."""
    text: str


def _names(names: list[str]) -> str:
    shown = ", ".join(names[:SHOWN])
    return (shown + f", … ({len(names)} in all)" if len(names) > SHOWN else shown) or "none"


def _matching(key: str, published: list[str]) -> list[str]:
    import zenoh

    asked = zenoh.KeyExpr(key)
    return [p for p in published if asked.intersects(zenoh.KeyExpr(p))]


def explain(key: str, found: Survey, waited_s: float) -> Silence:
    """Why nothing arrived on ``key`` within ``waited_s`` seconds, from what the daemons answered."""
    matches = _matching(key, found.published())
    quiet = f"nothing on {key} within {waited_s:g} s"
    if matches:
        return Silence(True, f"{quiet}; still waiting: it is published as {_names(matches)}")
    chunks = key.split("/")
    cell, robot = chunks[0], chunks[1] if len(chunks) > 1 else ""
    if "*" in cell:
        return Silence(False, f"{quiet}: no daemon reachable publishes on it; cells: {_names(found.cells)}")
    if cell not in found.cells:
        return Silence(False, f"{quiet}: no cell {cell!r} is reachable; cells: {_names(found.cells)}")
    robots = found.robots_of(cell)
    if cell not in found.daemons:
        why = f"no answer on {cell}/daemon to tell whether anything publishes on it; robots: {_names(robots)}"
        return Silence(True, f"{quiet}; still waiting ({why})")
    if robot and "*" not in robot and robot not in CELL_LEVEL_KEYS and robot not in robots:
        return Silence(False, f"{quiet}: no robot {robot!r} in cell {cell}; robots: {_names(robots)}")
    if robot in robots:
        entry = found.robot(cell, robot) or {}
        keys = [str(k).split("/", 2)[2] for k in entry.get("keys", {}).get("published", [])]
        return Silence(False, f"{quiet}: robot {robot!r} publishes no such key; its keys: {_names(keys)}")
    cell_keys = [k for k in found.published() if k.startswith(f"{cell}/")]
    return Silence(False, f"{quiet}: nothing in cell {cell} publishes on it; e.g. {_names(cell_keys)}")
