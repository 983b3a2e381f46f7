"""``urdaemon foxglove``: serve a running cell live over Foxglove's WebSocket protocol until Ctrl-C
(or SIGTERM); open it in the Foxglove app at ws://HOST:PORT (docs/foxglove.md).

Exit codes: 0 ended by Ctrl-C or SIGTERM; 1 no cell answered, or the server could not start (the port
taken); 2 bad arguments, or foxglove-sdk not installed (the ``foxglove`` extra).
"""

from __future__ import annotations

import argparse
import asyncio
import sys
from typing import Any

from urdaemon import cli_args
from urdaemon.errors import ConfigError, UrDaemonError
from urdaemon.stop_signals import stopped_by_signals

__all__ = ["DEFAULT_PORT", "NEEDS_EXTRA", "add_parsers", "foxglove_main"]

NEEDS_EXTRA = "urdaemon foxglove needs the foxglove extra: pip install 'urdaemon[foxglove]'"
DEFAULT_PORT = 8765
"""Foxglove's usual WebSocket port."""


def add_parsers(sub: Any) -> None:
    """The ``foxglove`` command's parser."""
    from urdaemon.client import DEFAULT_ENDPOINT

    parser = sub.add_parser(
        "foxglove", help="serve a cell live over Foxglove's WebSocket protocol (the foxglove extra)"
    )
    parser.add_argument("--connect", default=None, help=f"daemon endpoint (default {DEFAULT_ENDPOINT})")
    parser.add_argument("--zenoh-config", metavar="FILE", default=None, help="Zenoh JSON5 config (e.g. TLS)")
    parser.add_argument("--cell", default=None, help="cell name (default: the one cell served)")
    parser.add_argument(
        "--host", default="127.0.0.1", help="address the WebSocket server listens on (default 127.0.0.1)"
    )
    parser.add_argument(
        "--port",
        type=cli_args.port(allow_zero=True),
        default=DEFAULT_PORT,
        help=f"port of the WebSocket server (default {DEFAULT_PORT}; 0: any free port)",
    )
    parser.set_defaults(run=foxglove_main)


def foxglove_main(args: argparse.Namespace) -> int:
    """Run ``urdaemon foxglove`` with its parsed arguments; the exit code."""
    try:
        import foxglove  # noqa: F401  (only to say early that the extra is missing)
    except ImportError:
        print(NEEDS_EXTRA, file=sys.stderr)
        return 2
    try:
        return asyncio.run(_serve(args))
    except ConfigError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    except UrDaemonError as err:
        print(f"error: {err}", file=sys.stderr)
        return 1


async def _serve(args: argparse.Namespace) -> int:
    from urdaemon.client import DEFAULT_ENDPOINT
    from urdaemon.foxglove_bridge.bridge import running_bridge

    stop = asyncio.Event()
    with stopped_by_signals(stop):  # SIGINT, SIGTERM
        try:
            bridge_cm = running_bridge(
                args.connect or DEFAULT_ENDPOINT,
                host=args.host,
                port=args.port,
                cell=args.cell,
                zenoh_config=args.zenoh_config,
            )
            async with bridge_cm as bridge:
                print(f"urdaemon foxglove of cell {bridge.cell!r}: {bridge.url}", flush=True)
                await stop.wait()
                print("urdaemon foxglove: stopping", file=sys.stderr)
        except RuntimeError as err:  # foxglove-sdk could not start its server (the port taken, ...)
            print(f"error: the Foxglove server did not start: {err}", file=sys.stderr)
            return 1
    return 0
