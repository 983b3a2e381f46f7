"""What a client command connects to: its ``--connect``, ``--zenoh-config``, robot and cell checked,
the client made (its leases naming the command), and a failure said the one way every client
command says it."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Awaitable, Callable
from typing import TYPE_CHECKING, Any

from urdaemon.cli.exit_codes import EXIT_FAILED
from urdaemon.errors import UrDaemonError

if TYPE_CHECKING:
    from urdaemon.client import Client, RobotClient

__all__ = ["ask_robot", "bad_cell", "bad_connection", "bad_target", "connect", "fail"]


def _bad_endpoint(endpoint: str) -> str | None:
    """Why ``endpoint`` is not a Zenoh endpoint (None when it looks like one)."""
    import re

    from urdaemon.cell.zenoh_options import ENDPOINT_PATTERN

    if not re.match(ENDPOINT_PATTERN, endpoint):
        return f"--connect {endpoint!r} is not a Zenoh endpoint like tcp/127.0.0.1:7447"
    return None


def bad_connection(args: argparse.Namespace) -> str | None:
    """Why ``--connect`` or ``--zenoh-config`` cannot be used (None when fine)."""
    import os

    problem = None if args.connect is None else _bad_endpoint(args.connect)
    if problem is None and args.zenoh_config is not None and not os.path.isfile(args.zenoh_config):
        problem = f"--zenoh-config {args.zenoh_config!r} is not a file"
    return problem


async def connect(args: argparse.Namespace) -> Client:
    """A client of ``--connect``, or, left at its default, of the endpoint ``--zenoh-config`` names
    (``Client.connect``), whose leases name this command."""
    from urdaemon.client import Client, default_holder

    return await Client.connect(
        args.connect, config_file=args.zenoh_config, holder=default_holder(f"urdaemon {args.command}")
    )


def bad_target(args: argparse.Namespace) -> str | None:
    """Why the endpoint, robot or cell name of a client command cannot be used (None when fine)."""
    import re

    from urdaemon.cell.robot_options import NAME_PATTERN

    problem = bad_connection(args)
    if problem is None and not re.match(NAME_PATTERN, args.robot):
        problem = f"{args.robot!r} is not a robot name (lower-case letters, digits, '_')"
    return problem or _bad_cell_name(args.cell)


def bad_cell(args: argparse.Namespace) -> str | None:
    """Why the endpoint or cell name of a cell-wide command cannot be used (None when fine)."""
    return bad_connection(args) or _bad_cell_name(args.cell)


def _bad_cell_name(cell: str | None) -> str | None:
    """Why ``--cell`` cannot be used (None when fine, or not given)."""
    import re

    from urdaemon.cell.config import CELL_NAME_PATTERN

    if cell is not None and not re.match(CELL_NAME_PATTERN, cell):
        return f"--cell {cell!r} is not a cell name"
    return None


def fail(err: BaseException, prefix: str = "") -> int:
    """Say what failed (a Zenoh error in its own words) after ``prefix``; the exit code 1."""
    from urdaemon.client import zenoh_message

    print(f"error: {prefix}{zenoh_message(err)}", file=sys.stderr)
    return EXIT_FAILED


async def ask_robot(
    args: argparse.Namespace, ask: Callable[[RobotClient], Awaitable[dict[str, Any]]]
) -> dict[str, Any] | int:
    """Connect to ``--connect``, find ``args.robot`` and return ``ask(robot)``'s reply, or the exit
    code after saying what failed (the endpoint, or the robots there)."""
    try:
        async with await connect(args) as client:
            robot = await client.robot(args.robot, cell=args.cell)
            return await ask(robot)
    except UrDaemonError as err:
        return fail(err)
