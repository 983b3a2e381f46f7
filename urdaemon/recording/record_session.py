"""One run of ``urdaemon record``: connect, find the cell, subscribe, write until Ctrl-C or the
duration, then say what was kept (record_command.py parses the command line).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import signal
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from urdaemon.cell_lookup import cell_description
from urdaemon.client import Client, default_holder
from urdaemon.errors import UrDaemonError
from urdaemon.recording.channels import kind_of, recorded_keys
from urdaemon.recording.mcap_file import RecordingWriter
from urdaemon.recording.output import (
    EXIT_BAD_INPUT,
    EXIT_FAILED,
    EXIT_OK,
    Output,
    cannot_write,
    default_output,
    error,
)
from urdaemon.recording.subscription import Inbox, subscribe
from urdaemon.recording.write_loop import WriteLoop

__all__ = ["FLIGHT_TIMEOUT_S", "KEY_CHECK_S", "ask_flight_record", "find_cell", "key_expressions", "record"]

KEY_CHECK_S = 3.0
"""After this long, each ``--key`` that matched nothing is named in a warning."""
POLL_S = 0.1
FLIGHT_TIMEOUT_S = 120.0
"""How long ``--flight`` waits for the file (the seconds after, then the writing)."""
SHOWN_KEYS = 30
"""At most this many published keys are named when a ``--key`` matches nothing."""


def find_cell(served: list[tuple[str, str]], cell: str | None, robots: list[str], endpoint: str) -> str:
    """The cell to record (``cell``, else the one served) with every robot of ``robots`` in it;
    ``UrDaemonError`` naming what is served otherwise."""
    cells = sorted({c for c, _ in served})
    if not cells:
        raise UrDaemonError(f"no cell is served at {endpoint}")
    if cell is None:
        if len(cells) > 1:
            raise UrDaemonError(
                f"several cells are served at {endpoint} ({', '.join(cells)}); name one with --cell"
            )
        cell = cells[0]
    elif cell not in cells:
        raise UrDaemonError(f"no cell {cell!r} is served at {endpoint}; served: {', '.join(cells)}")
    mine = sorted(r for c, r in served if c == cell)
    unknown = [r for r in robots if r not in mine]
    if unknown:
        raise UrDaemonError(
            f"no robot {', '.join(map(repr, unknown))} in cell {cell!r}; its robots: {', '.join(mine)}"
        )
    return cell


def key_expressions(cell: str, robots: list[str], keys: list[str]) -> list[str]:
    """What to subscribe to: each ``--key`` under the cell, else every recorded key (of ``robots``
    only, when named)."""
    if keys:
        return [k if k.startswith(f"{cell}/") else f"{cell}/{k}" for k in keys]
    everything = recorded_keys(cell)
    if not robots:
        return list(everything)
    robot_level = [e for e in everything if e.startswith(f"{cell}/*/")]
    cell_level = [e for e in everything if not e.startswith(f"{cell}/*/")]
    return [e.replace(f"{cell}/*/", f"{cell}/{r}/", 1) for r in robots for e in robot_level] + cell_level


def _keep(robots: list[str]) -> Callable[[str], bool] | None:
    if not robots:
        return None
    wanted = frozenset(robots)

    def keep(key: str) -> bool:
        where = kind_of(key)
        return where is not None and (where.robot is None or where.robot in wanted)

    return keep


async def record(args: argparse.Namespace, output: Output | None) -> int:
    """Record as ``args`` say into ``output`` (None: the default file, once the cell is known)."""
    import zenoh

    try:
        client = await Client.connect(
            args.connect, config_file=args.zenoh_config, holder=default_holder("urdaemon record")
        )
    except UrDaemonError as err:
        _discard(output)
        return error(str(err), EXIT_FAILED)
    async with client:
        try:
            cell = find_cell(await client.robots(), args.cell, args.robot, args.connect)
            expressions = key_expressions(cell, args.robot, args.key)
            for expression in expressions:
                zenoh.KeyExpr(expression)
        except (UrDaemonError, zenoh.ZError) as err:
            _discard(output)
            return error(str(err), EXIT_BAD_INPUT)
        if output is None:
            try:
                output = default_output(cell, args.ros2)
            except OSError as err:
                return error(cannot_write(f"the recording of {cell}", err), EXIT_BAD_INPUT)
        urdf = await _urdf(client, cell)
        return await _record_into(client, args, cell, expressions, urdf, output)


async def ask_flight_record(args: argparse.Namespace) -> int:
    """``record --flight``: the daemon's flight recorder writes its last seconds; print the file."""
    from urdaemon.client import NoSuchService
    from urdaemon.publish.keys import CellKeys

    try:
        async with await Client.connect(args.connect, config_file=args.zenoh_config) as client:
            cell = find_cell(await client.robots(), args.cell, [], args.connect)
            try:
                answer = await client.request(CellKeys(cell).flight_record, timeout=FLIGHT_TIMEOUT_S)
            except NoSuchService:
                return error(
                    f"cell {cell!r} has no flight recorder (no 'record' in its cell file)", EXIT_FAILED
                )
    except UrDaemonError as err:
        return error(str(err), EXIT_FAILED)
    if not answer.get("ok"):
        return error(f"no flight record: {answer.get('reason')}", EXIT_FAILED)
    print(answer.get("path"))
    return EXIT_OK


async def _urdf(client: Client, cell: str) -> str | None:
    try:
        return await cell_description(client, cell)  # asked again while the queryable is new to us
    except UrDaemonError as err:
        print(f"warning: recording without the cell URDF: {err}", file=sys.stderr)
        return None


async def _record_into(
    client: Client,
    args: argparse.Namespace,
    cell: str,
    expressions: list[str],
    urdf: str | None,
    output: Output,
) -> int:
    try:
        writer = RecordingWriter(
            output.stream, cell=cell, urdf=urdf, ros2_only=args.ros2, metadata={"keys": " ".join(expressions)}
        )
    except OSError as err:
        _discard(output)
        return error(cannot_write(output.path, err), EXIT_FAILED)
    inbox = Inbox()
    loop = WriteLoop(inbox, writer, keep=_keep(args.robot))
    loop.start()
    subscribers = subscribe(client.session, expressions, inbox)
    check = _KeyCheck(client.session, cell, inbox, expressions) if args.key else None
    started = time.monotonic()
    where = output.bag or output.path
    print(f"recording cell {cell!r} to {where} (Ctrl-C to stop)", file=sys.stderr, flush=True)
    try:
        await _wait(args.duration, loop, check)
    finally:
        if check is not None:
            check.close()
        for subscriber in subscribers:
            with contextlib.suppress(Exception):
                subscriber.undeclare()
        await asyncio.get_running_loop().run_in_executor(None, loop.stop)
        with contextlib.suppress(OSError):
            output.stream.close()
    return _report(output, writer, loop, inbox, time.monotonic() - started)


async def _wait(duration: float | None, loop: WriteLoop, check: _KeyCheck | None) -> None:
    """Until the duration passed, Ctrl-C or SIGTERM came, or the writer stopped (a failed write)."""
    stop = asyncio.Event()
    running = asyncio.get_running_loop()
    handled: list[signal.Signals] = []
    for sig in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(ValueError, RuntimeError, NotImplementedError):  # not the main thread
            running.add_signal_handler(sig, stop.set)
            handled.append(sig)
    start = running.time()
    try:
        while not stop.is_set() and loop.alive:
            now = running.time()
            if duration is not None and now - start >= duration:
                return
            if check is not None and now - start >= KEY_CHECK_S:
                check.warn()
                check = None
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(stop.wait(), POLL_S)
    finally:
        for sig in handled:
            running.remove_signal_handler(sig)


class _KeyCheck:
    """Which keys the cell publishes (a subscriber of ``<cell>/**`` while the check lasts), and after
    ``KEY_CHECK_S`` a warning for each ``--key`` that matched nothing, naming them."""

    def __init__(self, session: Any, cell: str, inbox: Inbox, expressions: list[str]) -> None:
        self._inbox = inbox
        self._expressions = expressions
        self._published: set[str] = set()
        self._subscriber: Any = session.declare_subscriber(f"{cell}/**", self._heard)

    def _heard(self, sample: Any) -> None:
        if len(self._published) < 10_000:
            self._published.add(str(sample.key_expr))

    def warn(self) -> None:
        """Warn of every key expression that matched nothing; stop listening to the cell."""
        self.close()
        recordable = sorted(k for k in set(self._published) if kind_of(k) is not None)
        shown = ", ".join(recordable[:SHOWN_KEYS]) + (" ..." if len(recordable) > SHOWN_KEYS else "")
        for expression in self._expressions:
            if not self._inbox.received.get(expression, 0):
                print(
                    f"warning: --key {expression} matched nothing in {KEY_CHECK_S:g} s; "
                    f"the cell publishes: {shown or 'nothing recordable'}",
                    file=sys.stderr,
                    flush=True,
                )

    def close(self) -> None:
        """Stop listening to the whole cell."""
        subscriber, self._subscriber = self._subscriber, None
        if subscriber is not None:
            with contextlib.suppress(Exception):
                subscriber.undeclare()


def _report(output: Output, writer: RecordingWriter, loop: WriteLoop, inbox: Inbox, seconds: float) -> int:
    counts = writer.counts
    for key, problem in sorted(counts.malformed.items()):
        print(f"warning: messages on {key} not recorded: {problem}", file=sys.stderr)
    if loop.error is not None:
        return _failed_write(output, loop.error, sum(counts.written.values()))
    if output.bag is not None:
        from urdaemon.recording.rosbag2 import write_bag_metadata

        try:
            write_bag_metadata(output.path)
        except (OSError, ValueError) as err:
            return error(f"the bag's metadata.yaml not written: {err}", EXIT_FAILED)
    total = sum(counts.written.values())
    size = output.path.stat().st_size if output.path.exists() else 0
    print(
        f"recorded {total} messages on {len(counts.written)} topics in {seconds:.1f} s to "
        f"{output.bag or output.path} ({size / 1e6:.1f} MB); dropped {inbox.dropped} (inbox full)",
        file=sys.stderr,
    )
    if inbox.dropped:
        print(f"warning: {inbox.dropped} messages were dropped: the writer fell behind", file=sys.stderr)
    return EXIT_OK


def _failed_write(output: Output, err: OSError, added: int) -> int:
    from urdaemon.recording.recover import scan

    reason = "the disk is full" if err.errno == 28 else (err.strerror or str(err))
    try:
        with output.path.open("rb") as stream:
            kept = scan(stream)
        held = f"The file holds the {kept.messages} messages of its complete chunks"
    except OSError as read_err:
        held = f"The file cannot be read back ({read_err.strerror or read_err})"
    fixed = output.path.with_name(f"{output.path.stem}_recovered.mcap")
    return error(
        f"writing {output.path} failed ({reason}) after {added} messages; recording stopped. {held}: "
        f"`urdaemon record --recover {output.path} -o {fixed}` writes them into a complete file",
        EXIT_FAILED,
    )


def _discard(output: Output | None) -> None:
    """Remove the file (and bag directory) created for a recording that never started."""
    if output is None:
        return
    with contextlib.suppress(OSError):
        output.stream.close()
        output.path.unlink()
        if output.bag is not None:
            Path(output.bag).rmdir()
