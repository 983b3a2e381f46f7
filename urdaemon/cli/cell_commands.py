"""``serve``, ``check``, ``urdf`` and ``fake-robot``: a cell file run, checked or described, and the
fake controllers that stand for its robots. ``serve`` and ``fake-robot`` run until a stop signal
(stop_signals.py)."""

from __future__ import annotations

import argparse
import asyncio
import sys
from collections.abc import Coroutine
from pathlib import Path
from typing import TYPE_CHECKING, Any

from urdaemon.cli.connect import fail
from urdaemon.cli.exit_codes import EXIT_BAD_INPUT, EXIT_FAILED, EXIT_OK
from urdaemon.errors import ConfigError, DescriptionError, UrDaemonError
from urdaemon.stop_signals import end_stop_signals, stop_on_signals, stop_signal_handlers

if TYPE_CHECKING:
    from urdaemon.cell.config import Cell

__all__ = ["check", "fake_robot", "serve", "urdf"]


def serve(args: argparse.Namespace) -> int:
    """``urdaemon serve``: the daemon of ``--config`` until a stop signal; the exit code."""
    from urdaemon.cell import load_cell
    from urdaemon.daemon import Daemon

    cell = load_cell(args.config)
    try:  # the start poses are checked against the arms' limits here, before Zenoh or a port opens
        daemon = Daemon(cell, listen=tuple(args.listen) if args.listen else None)
    except ConfigError as err:
        raise _in_file(err, args.config) from err
    previous = None if args.owns_process else stop_signal_handlers()

    async def run() -> None:
        stop = asyncio.Event()
        stop_on_signals(stop, f"cell {cell.cell!r}")
        await daemon.run(stop)

    try:
        _run_loop(run())
    except ConfigError as err:  # bad input found as the robots start (a servo arm's missing device)
        raise _in_file(err, args.config) from err  # exit 2, as check does
    except DescriptionError:
        raise
    except UrDaemonError as err:
        return fail(err)
    except OSError as err:  # e.g. a port in use: say which, no traceback
        print(f"error: {err.strerror or err}", file=sys.stderr)
        return EXIT_FAILED
    except Exception as err:
        import zenoh

        if isinstance(err, zenoh.ZError):  # e.g. the listen endpoint is taken
            return fail(err, "Zenoh: ")
        raise
    finally:
        end_stop_signals(previous)
        daemon.release()  # the loop has ended: no ruckig object outlives serving (nanobind's leak report)
    return EXIT_OK


def _run_loop(main: Coroutine[Any, Any, None]) -> None:
    """Run ``main`` on asyncio, or on uvloop when ``URDAEMON_LOOP=uvloop`` and uvloop is installed.

    Opt-in: measured on the 2-core VM it made no clear difference (docs/performance.md). uvloop's
    ``loop.time()`` has 1 ms resolution; nothing in urdaemon measures with it.
    """
    import os

    if os.environ.get("URDAEMON_LOOP", "").lower() == "uvloop":
        try:
            import uvloop
        except ImportError:
            print("warning: URDAEMON_LOOP=uvloop but uvloop is not installed; using asyncio", file=sys.stderr)
        else:
            uvloop.run(main)
            return
    asyncio.run(main)


def fake_robot(args: argparse.Namespace) -> int:
    """``urdaemon fake-robot``: serve the fakes until a stop signal (fakeur/command.py); the exit code."""
    from urdaemon.fakeur.command import run_fakes

    return run_fakes(args)


def check(args: argparse.Namespace) -> int:
    """``urdaemon check``: what ``serve`` would refuse of ``--config``, or its summary."""
    from urdaemon.cell import load_cell, summarize
    from urdaemon.daemon import describe_cell, make_backend

    path, check_devices = args.config, not args.skip_devices
    try:
        cell = load_cell(path)
        try:  # what `serve` would refuse, `check` refuses too
            description = describe_cell(cell)
            for robot in cell.robots:
                make_backend(
                    robot, description.limits[robot.name], None, cell.cell, check_devices=check_devices
                )
        except ConfigError as err:
            raise _in_file(err, path) from err
        busy = _busy_ports(cell, path)  # serve would retry these forever
        if busy:
            raise ConfigError("\n".join(busy), errors=busy)
    except ConfigError as err:
        print(f"{len(err.errors)} error(s):", file=sys.stderr)
        for line in err.errors:
            print(f"  {line}", file=sys.stderr)
        return EXIT_BAD_INPUT
    print(summarize(cell))
    for name, limits in description.limits.items():
        print(f"  {name}: {limits.dof} joints: {', '.join(limits.names)}")
    print("ok")
    return EXIT_OK


def _in_file(err: ConfigError, path: str) -> ConfigError:
    """``err`` with each line naming the cell file ``path`` first, as the file's own errors do."""
    source = str(Path(path))
    lines = [line if line.startswith(f"{source}: ") else f"{source}: {line}" for line in err.errors]
    return ConfigError("\n".join(lines), errors=lines)


def _busy_ports(cell: Cell, source: str) -> list[str]:
    """Callback ports ``serve`` would listen on (robots that command) that something else holds now
    (each bound and released at once). ``serve`` fails at once when its Zenoh port is taken, but
    would retry a taken callback port forever."""
    import socket

    from urdaemon.backends.ur.route import listen_plan
    from urdaemon.cell.robot_options import UrOptions
    from urdaemon.errors import BackendError

    wanted: list[tuple[str, str, int]] = []
    problems = []
    for i, robot in enumerate(cell.robots):
        if not robot.listens or robot.address is None:
            continue
        try:  # where serve's servers would listen: the interface that reaches the robot, by default
            host = listen_plan(robot.address, robot.ur or UrOptions()).address
        except BackendError as err:  # serve would retry this until the network lets it through
            problems.append(f"{source}: robots[{i}] ({robot.name}): {err}")
            continue
        for role, port in robot.ports.as_dict().items():
            wanted.append((f"robots[{i}] ({robot.name}).ports.{role}", host, port))
    for where, host, port in wanted:
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        try:
            with socket.socket(family, socket.SOCK_STREAM) as sock:
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as the servers do
                sock.bind((host, port))
        except OSError as err:
            problems.append(f"{source}: {where}: cannot listen on {host}:{port}: {err.strerror or err}")
    return problems


def urdf(args: argparse.Namespace) -> int:
    """``urdaemon urdf``: the cell URDF of ``--config`` on stdout."""
    from urdaemon.cell import load_cell
    from urdaemon.description import build_cell_urdf

    sys.stdout.write(build_cell_urdf(load_cell(args.config)))
    return EXIT_OK
