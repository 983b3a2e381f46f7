"""``urdaemon replay FILE.mcap``: drive a cell through a recording's joint motion (``--config``), or
publish the recording again with no robot moving (``--publish``). docs/replay.md.

Exit codes: 0 done; 1 a goal failed or was refused, or the cell to publish is served; 2 bad input
(the file, the arguments, a recording that does not match the cell); 130 Ctrl-C (the goal that ran
canceled first: the robots stop).
"""

from __future__ import annotations

import argparse
import asyncio
import math
import sys
from typing import Any

__all__ = ["add_parsers", "run"]


def _rate(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number, got {text!r}") from None
    if not (math.isfinite(value) and 0.01 <= value <= 100.0):
        raise argparse.ArgumentTypeError(f"must be within 0.01..100 (1: as recorded), got {text}")
    return value


def add_parsers(sub: Any) -> None:
    """The ``replay`` command."""
    from urdaemon.client import DEFAULT_ENDPOINT

    replay = sub.add_parser(
        "replay",
        help="drive a cell through a recording's joint motion, or publish the recording again (--publish)",
        description=(
            "Drive a mock or fake-controller cell through the joint motion a recording holds (--config), "
            "or publish the recorded messages again with no robot moving (--publish). docs/replay.md"
        ),
    )
    replay.add_argument("file", metavar="FILE.mcap", help="a recording (urdaemon record)")
    what = replay.add_mutually_exclusive_group(required=True)
    what.add_argument("--config", metavar="CELL.yaml", help="the cell to drive (its daemon at --connect)")
    what.add_argument("--publish", action="store_true", help="publish the recorded messages on their keys")
    replay.add_argument(
        "--rate", type=_rate, default=1.0, help="speed: 0.5 is half the recorded speed (default 1)"
    )
    replay.add_argument(
        "--path",
        choices=("samples", "moves"),
        default=None,
        help="samples: through every recorded sample; moves: each move re-planned between its rests "
        "(default: samples below rate 1, else moves; docs/replay.md)",
    )
    replay.add_argument(
        "--robot",
        action="append",
        default=None,
        help="replay this robot only (repeatable; default: every one)",
    )
    replay.add_argument(
        "--connect",
        action="append",
        default=None,
        help=f"the daemon serving the cell (default {DEFAULT_ENDPOINT}); with --publish: join this network",
    )
    replay.add_argument("--zenoh-config", metavar="FILE", default=None, help="Zenoh JSON5 config (e.g. TLS)")
    replay.add_argument(
        "--listen",
        action="append",
        default=None,
        help=f"--publish: where viewers connect (default {DEFAULT_ENDPOINT})",
    )
    replay.add_argument(
        "--wait",
        action="store_true",
        help="--publish: start once something subscribes to the recorded joint states",
    )
    replay.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """The command (``args`` from ``add_parsers``)."""
    from urdaemon.errors import ConfigError
    from urdaemon.replay.source import read_cell

    problem = _bad_arguments(args)
    if problem is not None:
        print(f"error: {problem}", file=sys.stderr)
        return 2
    try:
        recorded = read_cell(args.file, samples=not args.publish)
    except ConfigError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    try:
        if args.publish:
            return asyncio.run(_publish(args, recorded))
        return asyncio.run(_drive(args, recorded))
    except KeyboardInterrupt:
        return 130


def _bad_arguments(args: argparse.Namespace) -> str | None:
    from urdaemon.client import DEFAULT_ENDPOINT

    if args.publish and args.path is not None:
        return "--path shapes the goals that drive a cell; --publish drives none"
    if args.publish and args.robot:
        return "--robot picks the robots to drive; --publish publishes the whole recording"
    if not args.publish and args.listen:
        return "--listen is for --publish (driving a cell connects to its daemon: --connect)"
    if not args.publish and args.wait:
        return "--wait is for --publish"
    if not args.publish and args.connect and len(args.connect) > 1:
        return "--connect: one daemon serves the cell"
    if args.publish and args.zenoh_config is not None:
        return "--zenoh-config is for driving a cell's daemon"
    args.connect_to = (args.connect or [DEFAULT_ENDPOINT])[0]
    return None


async def _publish(args: argparse.Namespace, recorded: Any) -> int:
    from urdaemon.client import DEFAULT_ENDPOINT
    from urdaemon.replay.publish import publish_recording

    listen = args.listen or [DEFAULT_ENDPOINT]
    return await publish_recording(recorded, args.rate, listen, args.connect or [], args.wait, sys.stderr)


async def _drive(args: argparse.Namespace, recorded: Any) -> int:
    from urdaemon.cell import load_cell
    from urdaemon.client import Client, default_holder, zenoh_message
    from urdaemon.errors import ConfigError, GoalRejected, UrDaemonError
    from urdaemon.replay.drive import Drive

    try:
        cell = load_cell(args.config)
    except ConfigError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    robots = list(dict.fromkeys(args.robot)) if args.robot else recorded.robots
    try:
        client = await Client.connect(
            args.connect_to, config_file=args.zenoh_config, holder=default_holder("urdaemon replay")
        )
    except UrDaemonError as err:
        print(f"error: {zenoh_message(err)}", file=sys.stderr)
        return 1
    async with client:
        try:
            drive = Drive(client, cell, recorded, robots, args.rate, sys.stderr, sys.stdout, args.path)
            return await drive.run()
        except GoalRejected as err:
            print(f"rejected: {err.reason}", file=sys.stderr)
            return 1
        except (UrDaemonError, ValueError) as err:
            print(f"error: {err}", file=sys.stderr)
            return 1
