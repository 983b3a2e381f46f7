"""``urdaemon view``: serve the live view of a running cell (``--connect``), or of a mock copy of a
cell file (``--config``: every robot on the mock backend, in a child process), until Ctrl-C.

Exit codes: 0 ended by Ctrl-C (or SIGTERM); 1 no cell answered, or the mock cell did not start;
2 bad arguments, a bad cell file, or viser not installed (the ``view`` extra).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import sys

from urdaemon.errors import ConfigError, UrDaemonError
from urdaemon.stop_signals import stopped_by_signals

__all__ = ["NEEDS_EXTRA", "view_main"]

NEEDS_EXTRA = "urdaemon view needs the view extra: pip install 'urdaemon[view]'"


def view_main(args: argparse.Namespace) -> int:
    """Run ``urdaemon view`` with its parsed arguments; the exit code."""
    try:
        import viser  # noqa: F401  (only to say early that the extra is missing)
    except ImportError:
        print(NEEDS_EXTRA, file=sys.stderr)
        return 2
    if args.config is not None and args.connect is not None:
        print(
            "error: --config starts a mock cell to view; --connect views a running one: not both",
            file=sys.stderr,
        )
        return 2
    try:
        return asyncio.run(_view(args))
    except ConfigError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    except UrDaemonError as err:
        print(f"error: {err}", file=sys.stderr)
        return 1


async def _view(args: argparse.Namespace) -> int:
    from urdaemon.client import DEFAULT_ENDPOINT
    from urdaemon.view.app import running_view
    from urdaemon.view.mockcell import mock_cell

    stop = asyncio.Event()
    with stopped_by_signals(stop):  # SIGINT, SIGTERM
        async with contextlib.AsyncExitStack() as stack:
            endpoint = args.connect or DEFAULT_ENDPOINT
            if args.config is not None:
                print(
                    f"urdaemon view: starting {args.config} with every robot on the mock backend "
                    "(it never drives real robots)",
                    file=sys.stderr,
                )
                endpoint = await stack.enter_async_context(mock_cell(args.config))
            view = await stack.enter_async_context(
                running_view(
                    endpoint, host=args.host, port=args.port, cell=args.cell, zenoh_config=args.zenoh_config
                )
            )
            print(f"urdaemon view of cell {view.cell!r}: {view.url}", flush=True)
            await stop.wait()
            print("urdaemon view: stopping", file=sys.stderr)
    return 0
