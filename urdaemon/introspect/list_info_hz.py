"""``urdaemon list``, ``urdaemon info ROBOT`` and ``urdaemon hz KEY`` (docs/introspection.md).

Registered through cli/parser.py's ``TOOL_MODULES``; nothing heavy is imported until a command runs.
"""

from __future__ import annotations

import argparse
import asyncio
from typing import Any

from urdaemon import cli_args
from urdaemon.introspect.connection import EXIT_BAD_INPUT, EXIT_OK, add_connection

__all__ = ["INFO_WINDOW_S", "add_parsers"]

INFO_WINDOW_S = 1.0
"""How long ``info`` listens to measure each key's rate (s)."""


def add_parsers(sub: Any) -> None:
    """``list``, ``info`` and ``hz``."""
    listing = sub.add_parser("list", help="every cell, robot and daemon reachable, with their state")
    listing.add_argument("--json", action="store_true", help="print what the daemons answered as JSON")
    add_connection(listing)
    listing.set_defaults(run=_run_list)

    info = sub.add_parser("info", help="one robot: model, backend, controller, ports, limits, lease, keys")
    info.add_argument("robot")
    info.add_argument("--cell", default=None, help="the robot's cell (needed when several have it)")
    info.add_argument(
        "--window",
        type=cli_args.seconds(allow_zero=False),
        default=INFO_WINDOW_S,
        help=f"seconds to measure rates (default {INFO_WINDOW_S:g})",
    )
    info.add_argument("--json", action="store_true", help="print the facts and measured rates as JSON")
    add_connection(info)
    info.set_defaults(run=_run_info)

    hz = sub.add_parser("hz", help="the rate of a key: average, min/max/std of the period, gaps")
    hz.add_argument("key", help="key expression, e.g. demo_cell/alice/joint_states")
    hz.add_argument(
        "--window", type=cli_args.whole_number(1), default=None, help="periods kept (default 10000)"
    )
    until = hz.add_mutually_exclusive_group()
    until.add_argument("--count", type=cli_args.whole_number(1), default=None, help="stop after N messages")
    until.add_argument(
        "--duration", type=cli_args.seconds(allow_zero=False), default=None, help="stop after S seconds"
    )
    hz.add_argument(
        "--timeout",
        type=cli_args.seconds(allow_zero=False),
        default=None,
        help="give up after S seconds without a message (default: never)",
    )
    add_connection(hz)
    hz.set_defaults(run=_run_hz)


def _run_list(args: argparse.Namespace) -> int:
    from urdaemon.introspect.views import list_command

    return _checked(args) or asyncio.run(list_command(args))


def _run_info(args: argparse.Namespace) -> int:
    from urdaemon.introspect.views import info_command

    return _checked(args) or asyncio.run(info_command(args))


def _run_hz(args: argparse.Namespace) -> int:
    from urdaemon.introspect.hz import hz_command

    return _checked(args) or asyncio.run(hz_command(args))


def _checked(args: argparse.Namespace) -> int:
    """EXIT_BAD_INPUT (said why) when the arguments cannot be used, else 0."""
    import re

    from urdaemon.cell.config import CELL_NAME_PATTERN
    from urdaemon.cell.robot_options import NAME_PATTERN
    from urdaemon.introspect.connection import bad_connection, error

    problem = bad_connection(args)
    robot, cell = getattr(args, "robot", None), getattr(args, "cell", None)
    if problem is None and robot is not None and not re.match(NAME_PATTERN, robot):
        problem = f"{robot!r} is not a robot name (lower-case letters, digits, '_')"
    if problem is None and cell is not None and not re.match(CELL_NAME_PATTERN, cell):
        problem = f"--cell {cell!r} is not a cell name"
    return EXIT_OK if problem is None else error(problem, EXIT_BAD_INPUT)
