"""The client commands that ask a serving daemon and print what it says: ``echo``, ``service``,
``dashboard``, ``cancel``, ``stop``, ``lease``; and ``teleop``, keys to twists until a quit key.
Those that command a robot take its lease first (client.py) and give it back as they exit."""

from __future__ import annotations

import argparse
import json
import math
import sys
from typing import TYPE_CHECKING, Any

from urdaemon.cli.connect import ask_robot, bad_cell, bad_connection, bad_target, connect, fail
from urdaemon.cli.exit_codes import EXIT_BAD_INPUT, EXIT_FAILED, EXIT_OK
from urdaemon.errors import GoalRejected, UrDaemonError

if TYPE_CHECKING:
    from urdaemon.client import RobotClient
    from urdaemon.teleop_keys import TeleopKeys

__all__ = ["call_service", "cancel", "dashboard", "echo", "lease", "stop", "teleop"]


async def echo(args: argparse.Namespace) -> int:
    """``urdaemon echo KEY``: its samples as JSON lines (introspect/echo.py), its arguments checked first."""
    import zenoh

    from urdaemon.client import zenoh_message
    from urdaemon.introspect.echo import echo_command

    problem = bad_connection(args)
    try:
        zenoh.KeyExpr(args.key)
    except zenoh.ZError as err:
        problem = f"{args.key!r} is not a valid key expression: {zenoh_message(err)}"
    if problem is None and args.field is not None and not all(args.field.split(".")):
        problem = f"--field {args.field!r} is not a field path like position or tcp.pose.0"
    if problem is not None:
        print(f"error: {problem}", file=sys.stderr)
        return EXIT_BAD_INPUT
    return await echo_command(args)


SERVICE_NAME = r"^[a-z_]{1,40}$"


async def call_service(args: argparse.Namespace) -> int:
    """``urdaemon service ROBOT NAME [BODY]``: the service's reply as JSON."""
    import re

    problem = bad_target(args)
    if problem is None and not re.match(SERVICE_NAME, args.name):
        problem = f"{args.name!r} is not a service name"
    body: object = None
    if problem is None:
        try:
            body = json.loads(args.body)
        except json.JSONDecodeError as err:
            problem = f"the request is not JSON: {err}"
    if problem is None and not isinstance(body, dict):
        problem = "the request must be a JSON object"
    if problem is not None or not isinstance(body, dict):
        print(f"error: {problem}", file=sys.stderr)
        return EXIT_BAD_INPUT
    request = body
    reply = await ask_robot(args, lambda robot: robot.call(args.name, request, timeout=args.timeout))
    if isinstance(reply, int):
        return reply
    print(json.dumps(reply))
    return EXIT_OK if reply.get("ok") else EXIT_FAILED


async def dashboard(args: argparse.Namespace) -> int:
    """``urdaemon dashboard ROBOT COMMAND…``: the controller's reply line, or why it was refused."""
    problem = bad_target(args)
    if problem is not None:
        print(f"error: {problem}", file=sys.stderr)
        return EXIT_BAD_INPUT
    reply = await ask_robot(args, lambda robot: robot.dashboard(" ".join(args.words)))
    if isinstance(reply, int):
        return reply
    if "reply" in reply:
        print(reply["reply"])
    else:
        print(f"error: {reply.get('reason', 'refused')}", file=sys.stderr)
    return EXIT_OK if reply.get("ok") else EXIT_FAILED


async def stop(args: argparse.Namespace) -> int:
    """``urdaemon stop [ROBOT]``: the robot's stop, or the cell's (every robot) without one."""
    problem = bad_target(args) if args.robot is not None else bad_cell(args)
    if problem is not None:
        print(f"error: {problem}", file=sys.stderr)
        return EXIT_BAD_INPUT
    if args.robot is not None:
        reply = await ask_robot(args, lambda robot: robot.stop())
    else:
        try:
            async with await connect(args) as client:
                reply = await client.stop_cell(args.cell)
        except UrDaemonError as err:
            return fail(err)
    if isinstance(reply, int):
        return reply
    print(json.dumps(reply))
    return EXIT_OK if reply.get("ok") else EXIT_FAILED


async def cancel(args: argparse.Namespace) -> int:
    """``urdaemon cancel ROBOT [--goal ID]``: the reply as JSON; exit 1 when nothing was canceled."""
    problem = bad_target(args)
    if problem is not None:
        print(f"error: {problem}", file=sys.stderr)
        return EXIT_BAD_INPUT
    reply = await ask_robot(args, lambda robot: robot.cancel(args.goal))
    if isinstance(reply, int):
        return reply
    print(json.dumps(reply))
    return EXIT_OK if reply.get("canceled") else EXIT_FAILED


async def teleop(args: argparse.Namespace) -> int:
    """``urdaemon teleop ROBOT``: keys to twists in a raw terminal until a quit key (teleop.py)."""
    from urdaemon import teleop_keys

    problem = bad_target(args)
    if problem is None and not (
        math.isfinite(args.speed) and teleop_keys.MIN_SPEED <= args.speed <= teleop_keys.MAX_SPEED
    ):
        problem = f"--speed must be within {teleop_keys.MIN_SPEED:g}..{teleop_keys.MAX_SPEED:g} m/s"
    if problem is None and not sys.stdin.isatty():
        problem = "teleop reads keys from a terminal, and stdin is not one"
    if problem is not None:
        print(f"error: {problem}", file=sys.stderr)
        return EXIT_BAD_INPUT
    try:
        async with await connect(args) as client:
            robot = await client.robot(args.robot, cell=args.cell)
            await robot.ensure_lease()  # twists are streams: they need the lease held first
            return await _teleop_in_terminal(robot, teleop_keys.TeleopKeys(args.speed, args.frame))
    except GoalRejected as err:
        print(f"rejected: {err.reason}", file=sys.stderr)
        return EXIT_FAILED
    except UrDaemonError as err:
        return fail(err)


async def _teleop_in_terminal(robot: RobotClient, keys: TeleopKeys) -> int:
    """The keys' help, then teleop with the terminal raw (put back however it ends)."""
    from urdaemon.teleop import TeleopShell, raw_terminal
    from urdaemon.teleop_keys import HELP

    print(f"teleop {robot.name}: {HELP}", file=sys.stderr)
    fd = sys.stdin.fileno()
    with raw_terminal(fd):
        return await TeleopShell(robot, keys, fd, sys.stdout).run()


async def lease(args: argparse.Namespace) -> int:
    """``urdaemon lease ROBOT``: who holds its lease; with ``--take-over REASON`` take it (the robot
    stops), say from whom, and release it on exit."""
    problem = bad_target(args)
    if problem is None and args.take_over is not None and not args.take_over.strip():
        problem = "--take-over needs a reason (it is logged and published)"
    if problem is not None:
        print(f"error: {problem}", file=sys.stderr)
        return EXIT_BAD_INPUT
    try:
        async with await connect(args) as client:
            robot = await client.robot(args.robot, cell=args.cell)
            if args.take_over is None:
                print(_lease_text(robot.name, await robot.lease_info()))
                return EXIT_OK
            before = await robot.lease_info()
            reply = await robot.take_over(args.take_over)
            previous = reply.get("previous", before)
            print(f"took over {robot.name}'s lease {_taken_from(previous)}")
            await robot.release()
            print(f"released {robot.name}'s lease")
            return EXIT_OK
    except UrDaemonError as err:
        return fail(err)


def _lease_text(robot: str, lease: dict[str, Any] | None) -> str:
    """One line about a lease: its holder, since when and its fingerprint (what the daemon shows of
    the holder's secret session id), or that it is free."""
    if lease is None:
        return f"{robot}: free"
    shown = f"{lease.get('holder')} since {_since(lease)} (fingerprint {lease.get('fingerprint')})"
    return f"{robot}: held by {shown}"


def _taken_from(lease: object) -> str:
    """Whom a take-over took the lease from (the lease it replaced, None when it was free)."""
    if not isinstance(lease, dict):
        return "(it was free)"
    return f"from {lease.get('holder')} (held since {_since(lease)}, fingerprint {lease.get('fingerprint')})"


def _since(lease: dict[str, Any]) -> str:
    import datetime

    since = lease.get("since")
    if not isinstance(since, int | float) or not math.isfinite(since):
        return "an unknown time"
    return datetime.datetime.fromtimestamp(since, datetime.UTC).isoformat(timespec="seconds")
