"""What is reachable through a session: every cell's daemon (its ``<cell>/daemon`` answer) and every
robot's liveliness token, over any number of cells (a wildcard query, never one assumed cell)."""

from __future__ import annotations

import asyncio
import json
from dataclasses import dataclass, field
from typing import Any

from urdaemon.client import Client
from urdaemon.publish.keys import CellKeys

__all__ = ["ROUND_PAUSE_S", "SURVEY_TIMEOUT_S", "Survey", "find_robot", "survey"]

SURVEY_TIMEOUT_S = 5.0
"""How long the daemons are given to answer (each answers from memory, at once: the time is spent
only on a daemon that does not answer), and how long the survey waits at most for a token that a
daemon's answer names but the session has not heard of yet."""
ROUND_PAUSE_S = 0.1
"""The pause between two rounds of questions (see ``survey``)."""


@dataclass
class Survey:
    """The daemons that answered, by cell, and the robots whose liveliness tokens are present."""

    daemons: dict[str, dict[str, Any]] = field(default_factory=dict)
    alive: list[tuple[str, str]] = field(default_factory=list)

    @property
    def cells(self) -> list[str]:
        """Every cell seen: by its daemon or its robots' tokens."""
        return sorted(set(self.daemons) | {cell for cell, _ in self.alive})

    def robots_of(self, cell: str) -> list[str]:
        """The robots of ``cell``: the daemon's list, else the liveliness tokens'."""
        daemon = self.daemons.get(cell)
        if daemon is not None:
            return [str(robot.get("name")) for robot in daemon.get("robots", [])]
        return sorted(robot for c, robot in self.alive if c == cell)

    def untokened(self) -> set[tuple[str, str]]:
        """(cell, robot) of every robot a daemon's answer names whose liveliness token is not seen."""
        named = {(cell, robot) for cell in self.daemons for robot in self.robots_of(cell)}
        return named - set(self.alive)

    def robot(self, cell: str, name: str) -> dict[str, Any] | None:
        """What the daemon of ``cell`` says of robot ``name`` (None: no daemon answer names it)."""
        for robot in (self.daemons.get(cell) or {}).get("robots", []):
            if robot.get("name") == name:
                return dict(robot)
        return None

    def published(self) -> list[str]:
        """Every key (expression) a daemon that answered publishes on."""
        keys: list[str] = []
        for daemon in self.daemons.values():
            for robot in daemon.get("robots", []):
                keys += robot.get("keys", {}).get("published", [])
            keys += daemon.get("keys", {}).get("published", [])
        return keys


async def survey(client: Client, *, timeout: float = SURVEY_TIMEOUT_S) -> Survey:
    """Ask every daemon reachable to describe itself, and list the robots' liveliness tokens.

    A session that just connected hears of some tokens and queryables late (a router passes them on,
    and on a busy machine a daemon behind it may answer before its tokens got through): the question
    is asked again until a round adds nothing and every robot a daemon names has its token, for
    ``timeout`` s at most (a token still missing then: the listing marks that robot)."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout
    found = Survey()
    for round_ in range(2 + int(timeout / ROUND_PAUSE_S)):
        seen = (set(found.daemons), set(found.alive))
        await _ask(client, found, timeout)
        settled = (set(found.daemons), set(found.alive)) == seen and not found.untokened()
        if round_ and (settled or loop.time() >= deadline):
            break
        await asyncio.sleep(ROUND_PAUSE_S)
    return found


async def _ask(client: Client, found: Survey, timeout: float) -> None:
    """One round: the tokens and the daemons' answers, added to ``found``."""
    found.alive = sorted(set(found.alive) | set(await client.robots(timeout=timeout)))
    replies = await client.query_replies(CellKeys("*").daemon, timeout=timeout, every_queryable=True)
    for reply in replies:
        try:
            data = json.loads(reply.payload)
        except ValueError:
            continue
        if not isinstance(data, dict) or not isinstance(data.get("robots"), list):
            continue
        if isinstance(data.get("cell"), str):
            found.daemons[data["cell"]] = data


def find_robot(found: Survey, name: str, cell: str | None) -> tuple[str, str | None]:
    """The cell of robot ``name`` (``cell`` if given): ``(cell, None)``, or ``("", why not)``."""
    cells = [c for c in found.cells if name in found.robots_of(c) and cell in (None, c)]
    if len(cells) == 1:
        return cells[0], None
    if len(cells) > 1:
        return "", f"robot {name!r} is served in several cells ({', '.join(cells)}); name one with --cell"
    served = [f"{c}/{r}" for c in found.cells for r in found.robots_of(c)]
    where = f" in cell {cell!r}" if cell is not None else ""
    return "", f"no robot {name!r}{where}; robots: {', '.join(served) or 'none reachable'}"
