"""``calibration``: a controller's kinematics calibration read over its primary interface into a
calibration file (calibration_tool.py)."""

from __future__ import annotations

import argparse
import asyncio
import sys

from urdaemon.cli.exit_codes import EXIT_BAD_INPUT, EXIT_FAILED, EXIT_OK
from urdaemon.errors import UrDaemonError

__all__ = ["calibration"]


def calibration(args: argparse.Namespace) -> int:
    """``urdaemon calibration``: read ``--address``'s calibration into ``--output``; the exit code."""
    from pathlib import Path

    from urdaemon.calibration_tool import DEFAULT_PORT, DEFAULT_TIMEOUT_S, calibration_yaml, read_calibration

    # the defaults are the calibration tool's (imported here, not when the parser is built: the
    # primary codec behind them costs every other command its import time)
    port = DEFAULT_PORT if args.port is None else args.port
    timeout = DEFAULT_TIMEOUT_S if args.timeout is None else args.timeout
    output = Path(args.output)
    if not output.parent.is_dir():
        print(
            f"error: --output {args.output}: directory {str(output.parent)!r} does not exist", file=sys.stderr
        )
        return EXIT_BAD_INPUT
    if output.is_dir():
        print(f"error: --output {args.output} is a directory", file=sys.stderr)
        return EXIT_BAD_INPUT
    try:
        reading = asyncio.run(read_calibration(args.address, port, timeout))
    except UrDaemonError as err:
        print(f"error: {err}", file=sys.stderr)
        return EXIT_FAILED
    try:
        output.write_text(calibration_yaml(reading, f"{args.address}:{port}"), encoding="utf-8")
    except OSError as err:
        print(f"error: cannot write {args.output}: {err.strerror or err}", file=sys.stderr)
        return EXIT_FAILED
    print(f"wrote {args.output} (hash {reading.kinematics.kinematics_hash()})", file=sys.stderr)
    return EXIT_OK
