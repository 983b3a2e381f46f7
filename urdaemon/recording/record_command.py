"""``urdaemon record``: what a cell publishes, into an MCAP file (docs/recording.md).

    urdaemon record [--cell C] [--robot R ...] [--key PATTERN ...] [-o FILE.mcap] [--duration S]
    urdaemon record --ros2 -o NAME             # a rosbag2 bag: NAME/NAME_0.mcap and NAME/metadata.yaml
    urdaemon record --recover BROKEN.mcap -o FIXED.mcap

A Zenoh client like ``urdaemon echo`` (``--connect``, ``--zenoh-config``): its subscriptions copy each
sample into a bounded inbox (subscription.py), one thread converts and writes them (write_loop.py);
samples the inbox had no room for are counted and reported at the end.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import Any

from urdaemon import cli_args
from urdaemon.recording.output import EXIT_BAD_INPUT, EXIT_FAILED, EXIT_OK, cannot_write, error, open_output

__all__ = ["add_parsers", "run"]


def add_parsers(sub: Any) -> None:
    """``record``."""
    from urdaemon.cell.zenoh_options import DEFAULT_ENDPOINT

    p = sub.add_parser("record", help="record what a cell publishes into an MCAP file (or a rosbag2 bag)")
    p.add_argument("--cell", default=None, help="cell name (default: the one cell served)")
    p.add_argument("--robot", action="append", default=[], help="record only this robot (repeatable)")
    p.add_argument(
        "--key",
        action="append",
        default=[],
        metavar="PATTERN",
        help="record only this key expression under the cell (alice/joint_states, */status; repeatable)",
    )
    p.add_argument(
        "-o", "--output", default=None, help="the file (default <cell>_<time>.mcap); with --ros2 the bag"
    )
    p.add_argument(
        "--duration",
        type=cli_args.seconds(allow_zero=False),
        default=None,
        help="stop after S seconds (default: Ctrl-C)",
    )
    p.add_argument(
        "--ros2",
        action="store_true",
        help="write a rosbag2 bag (NAME/NAME_0.mcap + metadata.yaml) of the ROS 2 channels only",
    )
    p.add_argument("--recover", metavar="BROKEN", default=None, help="recover a file cut short into -o")
    p.add_argument(
        "--flight",
        action="store_true",
        help="ask the daemon's flight recorder (cell file 'record') to write its last seconds now",
    )
    p.add_argument(
        "--connect", default=DEFAULT_ENDPOINT, help=f"daemon endpoint (default {DEFAULT_ENDPOINT})"
    )
    p.add_argument("--zenoh-config", metavar="FILE", default=None, help="Zenoh JSON5 config (e.g. TLS)")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Record (or recover) as ``args`` say; the exit code."""
    if args.recover is not None:
        return _recover(args.recover, args.output)
    import asyncio

    from urdaemon.recording.record_session import ask_flight_record, record

    problem = _bad_args(args)
    if problem is not None:
        return error(problem, EXIT_BAD_INPUT)
    if args.flight:
        return asyncio.run(ask_flight_record(args))
    output = None
    if args.output is not None:
        try:
            output = open_output(Path(args.output), args.ros2)
        except OSError as err:
            return error(cannot_write(args.output, err), EXIT_BAD_INPUT)
    try:
        return asyncio.run(record(args, output))
    except KeyboardInterrupt:
        return EXIT_OK


def _bad_args(args: argparse.Namespace) -> str | None:
    import re

    from urdaemon.cell.config import CELL_NAME_PATTERN
    from urdaemon.cell.robot_options import NAME_PATTERN
    from urdaemon.cell.zenoh_options import ENDPOINT_PATTERN

    if not re.match(ENDPOINT_PATTERN, args.connect):
        return f"--connect {args.connect!r} is not a Zenoh endpoint like tcp/127.0.0.1:7447"
    if args.zenoh_config is not None and not os.path.isfile(args.zenoh_config):
        return f"--zenoh-config {args.zenoh_config!r} is not a file"
    if args.cell is not None and not re.match(CELL_NAME_PATTERN, args.cell):
        return f"--cell {args.cell!r} is not a cell name"
    for robot in args.robot:
        if not re.match(NAME_PATTERN, robot):
            return f"--robot {robot!r} is not a robot name (lower-case letters, digits, '_')"
    return None


def _recover(broken: str, output: str | None) -> int:
    from urdaemon.recording.recover import recover

    if output is None:
        return error("--recover needs -o FIXED.mcap, the complete file to write", EXIT_BAD_INPUT)
    if Path(output).resolve() == Path(broken).resolve():
        return error("-o must name another file than the one recovered", EXIT_BAD_INPUT)
    try:
        source = open(broken, "rb")  # noqa: SIM115 (closed below, with the output)
    except OSError as err:
        return error(f"cannot read {broken}: {err.strerror or err}", EXIT_BAD_INPUT)
    with source:
        try:
            target = open(output, "wb")  # noqa: SIM115
        except OSError as err:
            return error(cannot_write(output, err), EXIT_BAD_INPUT)
        with target:
            kept = recover(source, target)
    if kept.complete:
        print(f"{broken} was complete: copied {kept.messages} messages to {output}")
        return EXIT_OK
    print(
        f"recovered {kept.messages} messages, {kept.attachments} attachment(s) and {kept.metadata} "
        f"metadata record(s) of {broken} into {output}; reading stopped: {kept.stopped}"
    )
    return EXIT_OK if kept.messages or kept.attachments else EXIT_FAILED
