"""The ``--connect`` / ``--zenoh-config`` options of the introspection commands and their session."""

from __future__ import annotations

import argparse
import os
import re
import sys

from urdaemon.client import DEFAULT_ENDPOINT, Client, default_holder

__all__ = ["EXIT_BAD_INPUT", "EXIT_FAILED", "EXIT_OK", "add_connection", "bad_connection", "connect", "error"]

EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT = 0, 1, 2


def add_connection(parser: argparse.ArgumentParser) -> None:
    """``--connect`` and ``--zenoh-config``, as every client command has them."""
    parser.add_argument(
        "--connect", default=DEFAULT_ENDPOINT, help=f"daemon or router endpoint (default {DEFAULT_ENDPOINT})"
    )
    parser.add_argument(
        "--zenoh-config", metavar="FILE", default=None, help="Zenoh JSON5 config to start from (e.g. TLS)"
    )


def bad_connection(args: argparse.Namespace) -> str | None:
    """Why ``--connect`` or ``--zenoh-config`` cannot be used (None when fine)."""
    from urdaemon.cell.zenoh_options import ENDPOINT_PATTERN

    if not re.match(ENDPOINT_PATTERN, args.connect):
        return f"--connect {args.connect!r} is not a Zenoh endpoint like tcp/127.0.0.1:7447"
    if args.zenoh_config is not None and not os.path.isfile(args.zenoh_config):
        return f"--zenoh-config {args.zenoh_config!r} is not a file"
    return None


async def connect(args: argparse.Namespace) -> Client:
    """A session at ``--connect``."""
    return await Client.connect(
        args.connect, config_file=args.zenoh_config, holder=default_holder(f"urdaemon {args.command}")
    )


def error(text: str, code: int = EXIT_FAILED) -> int:
    """Say ``error: text`` on stderr; ``code``."""
    print(f"error: {text}", file=sys.stderr)
    return code
