"""``urdaemon doctor [ROBOT]``: ask every robot (or one) for the ``doctor`` service's checks and print
them as a table, one line per check: verdict, name, what was measured, what to do.

Without ROBOT every robot of every cell served (their liveliness tokens, ``*/*/alive``; ``--cell``
keeps one cell). The host's checks are printed once per cell (every robot of a cell runs in one
daemon, on one host). Exit 0 when no check failed, 1 when one did or a robot did not answer, 2 for
bad arguments.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import re
import sys
from typing import Any

__all__ = ["add_parsers", "format_table", "run"]

EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT = 0, 1, 2
HOST_CHECKS = ("kernel", "realtime_priority")
"""The checks of the daemon's host (doctor/checks.py ``host_checks``), the same for every robot of a cell."""


def add_parsers(sub: Any) -> None:
    """Add ``doctor`` to the ``urdaemon`` command."""
    from urdaemon.client import DEFAULT_ENDPOINT

    doctor = sub.add_parser(
        "doctor",
        help="check what decides whether the cell runs well: each check's verdict and what to do",
        description=(
            "Check the daemon's host (kernel, real-time priority) and each robot (links, round trip, "
            "controller version, remote control, callback ports, RTDE jitter, clock offset, missed and "
            "late cycles, turnaround). Changes nothing on the robots. Exit 1 if any check fails."
        ),
    )
    doctor.add_argument("robot", nargs="?", default=None, help="one robot (default: every robot served)")
    doctor.add_argument("--cell", default=None, help="cell name (default: every cell served)")
    doctor.add_argument("--json", action="store_true", help="print the replies as JSON")
    doctor.add_argument(
        "--connect", default=DEFAULT_ENDPOINT, help=f"daemon endpoint (default {DEFAULT_ENDPOINT})"
    )
    doctor.add_argument("--zenoh-config", metavar="FILE", default=None, help="Zenoh JSON5 config (e.g. TLS)")
    doctor.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """The command: 0 no check failed, 1 one did (or a robot did not answer), 2 bad arguments."""
    problem = _bad_arguments(args)
    if problem is not None:
        print(f"error: {problem}", file=sys.stderr)
        return EXIT_BAD_INPUT
    return asyncio.run(_doctor(args))


def _bad_arguments(args: argparse.Namespace) -> str | None:
    import os

    from urdaemon.cell.config import CELL_NAME_PATTERN
    from urdaemon.cell.robot_options import NAME_PATTERN
    from urdaemon.cell.zenoh_options import ENDPOINT_PATTERN

    if not re.match(ENDPOINT_PATTERN, args.connect):
        return f"--connect {args.connect!r} is not a Zenoh endpoint like tcp/127.0.0.1:7447"
    if args.zenoh_config is not None and not os.path.isfile(args.zenoh_config):
        return f"--zenoh-config {args.zenoh_config!r} is not a file"
    if args.robot is not None and not re.match(NAME_PATTERN, args.robot):
        return f"{args.robot!r} is not a robot name (lower-case letters, digits, '_')"
    if args.cell is not None and not re.match(CELL_NAME_PATTERN, args.cell):
        return f"--cell {args.cell!r} is not a cell name"
    return None


async def _doctor(args: argparse.Namespace) -> int:
    from urdaemon.client import Client, default_holder
    from urdaemon.errors import UrDaemonError

    try:
        async with await Client.connect(
            args.connect, config_file=args.zenoh_config, holder=default_holder("urdaemon doctor")
        ) as client:
            targets = await _targets(client, args)
            if not targets:
                where = f" in cell {args.cell!r}" if args.cell is not None else ""
                print(f"error: no robot is served at {args.connect}{where}", file=sys.stderr)
                return EXIT_FAILED
            replies = await asyncio.gather(*(_ask(client, cell, robot) for cell, robot in targets))
    except UrDaemonError as err:
        print(f"error: {err}", file=sys.stderr)
        return EXIT_FAILED
    if args.json:
        print(json.dumps({"robots": replies}, indent=1))
    else:
        print(format_table(replies))
    failed = any(not r.get("ok") or r.get("verdict") == "fail" for r in replies)
    return EXIT_FAILED if failed else EXIT_OK


async def _targets(client: Any, args: argparse.Namespace) -> list[tuple[str, str]]:
    """(cell, robot) to ask: the one named (its cell found from its token), or every robot served."""
    if args.robot is not None:
        handle = await client.robot(args.robot, cell=args.cell)
        return [(handle.keys.cell, args.robot)]
    return [(cell, robot) for cell, robot in await client.robots() if args.cell in (None, cell)]


async def _ask(client: Any, cell: str, robot: str) -> dict[str, Any]:
    """The robot's doctor reply, with its cell and name; a failed ask as a reply that says why."""
    from urdaemon.errors import UrDaemonError

    try:
        handle = await client.robot(robot, cell=cell)
        reply = dict(await handle.doctor())
    except UrDaemonError as err:
        reply = {"ok": False, "reason": str(err)}
    reply["cell"], reply["robot"] = cell, robot
    return reply


def format_table(replies: list[dict[str, Any]]) -> str:
    """The replies as the table: per cell the host's checks once, then each robot's."""
    lines: list[str] = []
    hosts_shown: set[str] = set()
    for reply in replies:
        cell, robot = reply.get("cell", "?"), reply.get("robot", "?")
        if not reply.get("ok"):
            lines += [f"{cell}/{robot}", _row("fail", "doctor", f"no answer: {reply.get('reason', '?')}", "")]
            continue
        checks = reply.get("checks") or []
        if cell not in hosts_shown:
            hosts_shown.add(cell)
            lines.append(f"{cell}: the daemon's host")
            lines += [_row(**c) for c in checks if c.get("name") in HOST_CHECKS]
        backend = (reply.get("facts") or {}).get("backend", "?")
        lines.append(f"{cell}/{robot} ({backend})")
        lines += [_row(**c) for c in checks if c.get("name") not in HOST_CHECKS]
    return "\n".join(lines)


def _row(verdict: str, name: str, measured: str, action: str) -> str:
    return f"  {verdict:<7} {name:<18} {measured}" + (f"  -> {action}" if action else "")
