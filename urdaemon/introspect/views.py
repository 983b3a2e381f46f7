"""The asyncio shells of ``urdaemon list`` and ``urdaemon info``: ask, measure, print."""

from __future__ import annotations

import argparse
import asyncio
import json

from urdaemon.errors import UrDaemonError
from urdaemon.introspect.connection import EXIT_FAILED, EXIT_OK, connect, error
from urdaemon.introspect.sampling import Collector
from urdaemon.introspect.survey import find_robot, survey
from urdaemon.introspect.tables import MeasuredRate, info_lines, list_lines

__all__ = ["info_command", "list_command", "measure"]


async def list_command(args: argparse.Namespace) -> int:
    """Print every cell reachable, its daemon and its robots."""
    try:
        async with await connect(args) as client:
            found = await survey(client)
    except UrDaemonError as err:
        return error(str(err))
    if args.json:
        print(json.dumps({"daemons": found.daemons, "alive": [list(a) for a in found.alive]}, indent=2))
    else:
        print("\n".join(list_lines(found)))
    return EXIT_OK if found.cells else EXIT_FAILED


async def measure(session: object, key_expr: str, window_s: float) -> dict[str, MeasuredRate]:
    """Each key's rate under ``key_expr`` over ``window_s`` seconds of listening."""
    collector = Collector(session, key_expr)
    try:
        await asyncio.sleep(window_s)
    finally:
        collector.close()
    collector.drain()
    measured: dict[str, MeasuredRate] = {}
    for key, times in collector.keys.items():
        stats = times.times.stats()
        measured[key] = (stats.rate_hz if stats is not None else None, times.count, times.source)
    return measured


async def info_command(args: argparse.Namespace) -> int:
    """Print what the daemon says of one robot, and the rates its keys are measured at."""
    try:
        async with await connect(args) as client:
            found = await survey(client)
            cell, problem = find_robot(found, args.robot, args.cell)
            if problem is not None:
                return error(problem)
            daemon = found.daemons.get(cell)
            robot = found.robot(cell, args.robot)
            if daemon is None or robot is None:
                return error(
                    f"robot {args.robot!r} is alive in cell {cell!r}, but no answer on {cell}/daemon"
                )
            measured = await measure(client.session, f"{cell}/{args.robot}/**", args.window)
    except UrDaemonError as err:
        return error(str(err))
    if args.json:
        rates = {key: {"rate_hz": r, "count": n, "times": s} for key, (r, n, s) in measured.items()}
        print(
            json.dumps({"cell": cell, "robot": robot, "measured": rates, "window_s": args.window}, indent=2)
        )
    else:
        print("\n".join(info_lines(cell, robot, daemon, measured, args.window)))
    return EXIT_OK
