"""``urdaemon hz KEY``: how often messages arrive on a key, printed every second as ``ros2 topic hz``
prints it, and once more at the end (docs/introspection.md). The statistics are ``rates.py``'s."""

from __future__ import annotations

import argparse
import asyncio
import sys
import time

from urdaemon.errors import UrDaemonError
from urdaemon.introspect.connection import EXIT_BAD_INPUT, EXIT_FAILED, EXIT_OK, connect, error
from urdaemon.introspect.rates import DEFAULT_WINDOW, format_stats
from urdaemon.introspect.sampling import Collector
from urdaemon.introspect.silence import SILENCE_S, explain
from urdaemon.introspect.survey import survey

__all__ = ["POLL_S", "hz_command", "report"]

POLL_S = 0.02
"""How often the loop files what came (s): ``--count`` stops within this of its last message."""
REPORT_S = 1.0
"""How often the statistics are printed (s)."""


def report(collector: Collector) -> str:
    """The statistics of every key heard so far (each under its key when there are several)."""
    keys = sorted(collector.keys)
    blocks = []
    for key in keys:
        times = collector.keys[key]
        text = format_stats(times.times.stats(), source=times.source)
        blocks.append(text if len(keys) == 1 else f"{key}:\n{text}")
    if collector.dropped:
        blocks.append(f"({collector.dropped} message(s) dropped: this process fell behind)")
    return "\n".join(blocks)


async def hz_command(args: argparse.Namespace) -> int:
    """Measure until ``--count`` messages or ``--duration`` seconds (or Ctrl-C); exit 1 when none
    came (``--timeout``, or nothing publishes on the key)."""
    import zenoh

    try:
        zenoh.KeyExpr(args.key)
    except zenoh.ZError as err:
        return error(f"{args.key!r} is not a valid key expression: {err}", EXIT_BAD_INPUT)
    try:
        client = await connect(args)
    except UrDaemonError as err:
        return error(str(err))
    async with client:
        collector = Collector(client.session, args.key, window=args.window or DEFAULT_WINDOW)
        try:
            return await _measure(args, client, collector)
        finally:
            collector.close()


async def _measure(args: argparse.Namespace, client: object, collector: Collector) -> int:
    from urdaemon.client import Client

    assert isinstance(client, Client)
    start = time.monotonic()
    next_report, looked = start + REPORT_S, False
    while True:
        await asyncio.sleep(POLL_S)
        collector.drain(limit=_left(args.count, collector.total))
        now = time.monotonic()
        if args.count is not None and collector.total >= args.count:
            break
        if args.duration is not None and now - start >= args.duration:
            break
        if collector.total == 0:
            if args.timeout is not None and now - start >= args.timeout:
                return error(f"no message on {args.key} within {args.timeout:g} s")
            if not looked and now - start >= SILENCE_S:
                looked = True
                verdict = explain(args.key, await survey(client), SILENCE_S)
                print(f"{'note' if verdict.published else 'warning'}: {verdict.text}", file=sys.stderr)
                if not verdict.published and args.timeout is None:
                    return EXIT_FAILED
        if now >= next_report and collector.total:
            print(report(collector), flush=True)
            next_report = now + REPORT_S  # once a period, never a burst after a silence
    elapsed = time.monotonic() - start
    print(f"{collector.total} message(s) in {elapsed:.2f} s on {args.key}")
    print(report(collector), flush=True)
    return EXIT_OK if collector.total else EXIT_FAILED


def _left(count: int | None, total: int) -> int | None:
    return None if count is None else max(count - total, 0)
