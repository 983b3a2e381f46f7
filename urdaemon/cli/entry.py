"""The ``urdaemon`` console script: ``client-config`` handed to transport_security.py, the arguments
parsed (parser.py), logging set up, and the command run by its module; bad input found on the way is
exit 2, Ctrl-C exit 0 (exit_codes.py)."""

from __future__ import annotations

import argparse
import asyncio
import sys
from collections.abc import Callable, Coroutine, Sequence
from typing import Any

from urdaemon.cli.calibration_command import calibration
from urdaemon.cli.cell_commands import check, fake_robot, serve, urdf
from urdaemon.cli.client_commands import call_service, cancel, dashboard, echo, lease, stop, teleop
from urdaemon.cli.exit_codes import EXIT_BAD_INPUT, EXIT_OK
from urdaemon.cli.move_command import move
from urdaemon.cli.parser import build_parser
from urdaemon.errors import ConfigError, DescriptionError

__all__ = ["main"]


def _view(args: argparse.Namespace) -> int:
    from urdaemon.view.command import view_main

    return view_main(args)


COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {
    "serve": serve,
    "check": check,
    "urdf": urdf,
    "fake-robot": fake_robot,
    "calibration": calibration,
    "view": _view,
}
"""Each built-in command that runs by itself, and what runs it (``args`` → exit code); the
commands of parser.py's ``TOOL_MODULES`` bring theirs as the parser's ``run``."""
CLIENT_COMMANDS: dict[str, Callable[[argparse.Namespace], Coroutine[Any, Any, int]]] = {
    "echo": echo,
    "move": move,
    "teleop": teleop,
    "cancel": cancel,
    "stop": stop,
    "dashboard": dashboard,
    "service": call_service,
    "lease": lease,
}
"""Each client command, and what runs it on a loop of its own (``args`` → exit code)."""


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the console script."""
    from urdaemon.logs import setup_logging, shutdown_logging

    words = sys.argv[1:] if argv is None else list(argv)
    if words[:1] == ["client-config"]:
        from urdaemon.transport_security import client_config_main

        return client_config_main(words[1:])
    args = build_parser().parse_args(words)  # negative number lists joined there (parser.py)
    args.owns_process = argv is None  # run as the ``urdaemon`` command, not called with arguments
    installed = setup_logging(args.verbose)  # a bounded queue to stderr: never blocks the loop
    try:
        return _dispatch(args)
    finally:
        if installed is not None:
            shutdown_logging()


def _dispatch(args: argparse.Namespace) -> int:
    try:
        run: Callable[[argparse.Namespace], int] | None = getattr(args, "run", None)
        if run is not None:
            return run(args)
        command = COMMANDS.get(args.command)
        if command is not None:
            return command(args)
        client_command = CLIENT_COMMANDS.get(args.command)
        if client_command is not None:
            return asyncio.run(client_command(args))
    except (ConfigError, DescriptionError) as err:
        print(f"error: {err}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        return EXIT_OK
    return EXIT_BAD_INPUT
