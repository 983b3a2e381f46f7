"""The daemon's side of the flight recorder (cell file ``record``, docs/recording.md): start its
process (``python -m urdaemon.recording.flight``), restart it with a backoff when it dies, stop it with
the daemon, feed it what the daemon publishes, and pass it what the stream cannot show: an internal
error the daemon logged, and a client's request on ``<cell>/service/flight_record`` (answered with the
file's path once written).

The process is fed through its stdin (recording/flight_frames.py): the cell URDF when it starts, then
every ``FEED_INTERVAL_S`` what the node's tap (publish/tap.py) kept of the messages published since,
in one write that never waits. A batch is dropped, and counted, while the process is not running or
while the pipe holds ``MAX_BUFFERED`` bytes it has not read yet: the daemon's memory stays bounded.
The ring, the conversion and the disk are the process's: the daemon's loop only encodes a batch and
reads a line per file written, so the recorder never holds up a robot's cycle.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from urdaemon.cell.config import Cell, RecordOptions
from urdaemon.errors import ConfigError
from urdaemon.publish.endpoints import CELL, Endpoint
from urdaemon.publish.node import ZenohNode
from urdaemon.publish.tap import Tap
from urdaemon.recording.flight_frames import REQUEST, URDF, encode_frame, encode_samples
from urdaemon.runtime.queries import reply

__all__ = [
    "FEED_INTERVAL_S",
    "HEALTHY_RUN_S",
    "MAX_BUFFERED",
    "REQUEST_INTERVAL_S",
    "REQUEST_TIMEOUT_S",
    "RESTART_BACKOFF_S",
    "FlightRecorder",
    "flight_recorder",
    "restart_wait",
]

log = logging.getLogger(__name__)

RESTART_BACKOFF_S = (1.0, 2.0, 5.0, 10.0, 30.0)
"""Waits before each restart of a process that died; a process that ran a minute starts it over."""
HEALTHY_RUN_S = 60.0
"""A process that ran this long before it died restarts after the first wait again."""


def restart_wait(failures: int, ran_s: float) -> tuple[int, float]:
    """The failures in a row counting the process that just died after ``ran_s``, and the wait before
    the next start: a process that ran ``HEALTHY_RUN_S`` died of something new, so it counts as the
    first again."""
    failures = 1 if ran_s > HEALTHY_RUN_S else failures + 1
    return failures, RESTART_BACKOFF_S[min(failures, len(RESTART_BACKOFF_S)) - 1]


REQUEST_INTERVAL_S = 2.0
"""A new request is taken at most this often (one waiting joins the file of the one before)."""
REQUEST_TIMEOUT_S = 120.0
"""A request not answered by then is answered with a failure."""
STOP_WAIT_S = 10.0
"""How long the process may take to write its open burst when the daemon stops."""
FEED_INTERVAL_S = 0.05
"""How often the tap's messages are sent to the process (one write each time). Each send wakes the
daemon's loop and the process: measured at 1 robot, 20 ms cost the daemon about 0.3 % of a core more
than 50 ms (docs/performance.md). A request flushes the tap first, so a file misses nothing that was
published before it was asked for."""
MAX_BUFFERED = 16 * 1024 * 1024
"""Bytes the pipe may hold unread by the process; beyond, batches are dropped (counted, logged)."""
DROP_LOG_S = 10.0
"""Drops are logged at most this often."""


def flight_recorder(cell: Cell, node: ZenohNode, urdf: str) -> FlightRecorder | None:
    """The cell's flight recorder, fed from the node's tap (its queryable is declared with the cell's
    other keys: ``endpoints``); None when the cell file has no ``record`` (the node then has no tap)."""
    if cell.record is None or node.tap is None:
        return None
    _check_directory(cell.record.dir)
    return FlightRecorder(cell.cell, cell.record, node, node.tap, urdf)


def _check_directory(directory: str) -> None:
    """Make ``record.dir`` if missing; ``ConfigError`` when files cannot be written there (found at
    start, not at the first stop)."""
    path = Path(directory)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise ConfigError(f"record.dir: cannot make {path}: {err.strerror or err}") from None
    if not os.access(path, os.W_OK | os.X_OK):
        raise ConfigError(f"record.dir: {path} is not writable by this user")


class FlightRecorder:
    """Supervises the flight recorder's process and forwards requests to it."""

    def __init__(self, cell: str, options: RecordOptions, node: ZenohNode, tap: Tap, urdf: str) -> None:
        self.cell = cell
        self.options = options
        self._node = node
        self._tap = tap
        self._urdf = urdf.encode()
        self.ready = asyncio.Event()
        """Set while the process runs and reads its stdin."""
        self.written: list[dict[str, Any]] = []
        """Every file the process reported (``written``, ``reasons``, ``messages``), oldest first."""
        self.file_written = asyncio.Event()
        """Set at each file written (clear it to wait for the next)."""
        self.restarts = 0
        self.sent = 0
        """Messages sent to the process since start."""
        self.dropped = 0
        """Messages dropped since start: the process not running, or its pipe full."""
        self._dropped_logged = 0
        self._drop_logged_at = -DROP_LOG_S
        self._proc: asyncio.subprocess.Process | None = None
        self._waiting: dict[str, list[Any]] = {}
        self._next_id = 0
        self._last_request = -REQUEST_INTERVAL_S
        self._last_internal_error = -REQUEST_INTERVAL_S
        self._feeding: asyncio.TimerHandle | None = None

    @property
    def pid(self) -> int | None:
        """The process's id while it runs."""
        return None if self._proc is None else self._proc.pid

    def endpoints(self) -> dict[Endpoint, Callable[[Any], None]]:
        """The row of the endpoint table this part answers (``<cell>/service/flight_record``)."""
        return {CELL.flight_record: self._on_query}

    async def run(self) -> None:
        """Keep the process running until cancelled; then stop it."""
        handler = _InternalErrors(self, asyncio.get_running_loop())
        logging.getLogger("urdaemon").addHandler(handler)
        self._feed()  # and every FEED_INTERVAL_S from now on
        failures = 0
        try:
            while True:
                started = time.monotonic()
                await self._run_once()
                failures, wait = restart_wait(failures, time.monotonic() - started)
                log.warning("flight recorder stopped; starting it again in %g s", wait)
                await asyncio.sleep(wait)
                self.restarts += 1
        finally:
            if self._feeding is not None:
                self._feeding.cancel()
            logging.getLogger("urdaemon").removeHandler(handler)
            await self._stop()

    def _feed(self) -> None:
        """Every ``FEED_INTERVAL_S`` on the loop (a timer, not a task: the cheapest wake-up)."""
        self._feeding = asyncio.get_running_loop().call_later(FEED_INTERVAL_S, self._feed)
        self._send()

    def _send(self) -> None:
        """Send what the tap kept since the last call in one write, or drop it (never waits)."""
        items = self._tap.take()
        if not items:
            return
        stdin = self._stdin()
        if stdin is None or stdin.transport.get_write_buffer_size() > MAX_BUFFERED:
            self.dropped += len(items)
            now = time.monotonic()
            if now - self._drop_logged_at >= DROP_LOG_S:
                self._drop_logged_at = now
                full = stdin is not None  # else it is (re)starting: its stop was logged already
                log.log(
                    logging.WARNING if full else logging.INFO,
                    "flight recorder: %d messages dropped (%s; %d since start)",
                    self.dropped - self._dropped_logged,
                    "its pipe is full" if full else "it is not running",
                    self.dropped,
                )
                self._dropped_logged = self.dropped
            return
        stdin.write(encode_samples(items, time.time_ns()))
        self.sent += len(items)

    def _stdin(self) -> asyncio.StreamWriter | None:
        """The process's stdin while it runs and its pipe is open."""
        proc = self._proc
        if proc is None or proc.stdin is None or proc.stdin.transport.is_closing():
            return None
        return proc.stdin

    async def _run_once(self) -> None:
        options = self.options
        command = [
            sys.executable,
            "-m",
            "urdaemon.recording.flight",
            *("--cell", self.cell, "--dir", options.dir),
            *("--ring-s", str(options.ring_s), "--after-s", str(options.after_s)),
            *("--max-mb", str(options.max_mb)),
        ]
        try:  # in a session of its own: a terminal's Ctrl-C is the daemon's, which then closes its stdin
            proc = await asyncio.create_subprocess_exec(
                *command,
                stdin=asyncio.subprocess.PIPE,
                stdout=asyncio.subprocess.PIPE,
                start_new_session=True,
            )
        except OSError as err:
            log.error("flight recorder not started: %s", err)
            return
        self._proc = proc
        assert proc.stdin is not None
        assert proc.stdout is not None
        proc.stdin.write(encode_frame(URDF, "", self._urdf, time.time_ns()))
        try:
            async for line in proc.stdout:
                self._on_line(line)
        except asyncio.CancelledError:  # the daemon stops: the process writes its open burst and ends
            await self._stop()
            raise
        self.ready.clear()
        code = await proc.wait()
        self._proc = None
        self._fail_waiting(f"the flight recorder stopped (exit code {code})")
        if code:
            log.error("flight recorder exited with code %d", code)

    async def _stop(self) -> None:
        self._send()  # what was published last
        proc, self._proc = self._proc, None
        self.ready.clear()
        if proc is None:
            return
        if proc.stdin is not None:
            proc.stdin.close()  # the process writes its open burst and ends
        try:
            await asyncio.wait_for(proc.wait(), STOP_WAIT_S)
        except TimeoutError:
            with contextlib.suppress(ProcessLookupError):
                proc.kill()
            await proc.wait()
        if proc.stdout is not None:  # a file written while stopping is still logged
            for line in (await proc.stdout.read()).splitlines():
                self._on_line(line)

    def _on_line(self, line: bytes) -> None:
        try:
            message = json.loads(line)
        except ValueError:
            log.warning("flight recorder said: %.200r", line)
            return
        if message.get("ready"):
            self.ready.set()
            return
        requests = message.get("requests") or []
        reasons = ", ".join(message.get("reasons") or ())
        if "written" in message:
            log.warning(
                "flight record (%s): %d messages written to %s",
                reasons,
                message.get("messages", 0),
                message["written"],
            )
            self.written.append(message)
            self.file_written.set()
            body = {
                "ok": True,
                "path": message["written"],
                "reasons": message.get("reasons"),
                "messages": message.get("messages"),
            }
        else:
            log.error("flight record (%s) not written: %s", reasons, message.get("failed"))
            body = {"ok": False, "reason": str(message.get("failed"))}
        for ident in requests:
            for query in self._waiting.pop(str(ident), ()):
                reply(query, body)

    def request(self, reason: str, ident: str | None = None) -> bool:
        """Ask the process for a file; False when it is not running."""
        stdin = self._stdin()
        if stdin is None or not self.ready.is_set():
            return False
        self._send()  # what was published before the request goes before it
        body = {"reason": reason} if ident is None else {"reason": reason, "id": ident}
        stdin.write(encode_frame(REQUEST, "", json.dumps(body).encode(), time.time_ns()))
        return True

    def internal_error(self) -> None:
        """The daemon logged an internal error: a file of the seconds around it (at most one per
        ``REQUEST_INTERVAL_S``; the process merges a burst of them)."""
        now = time.monotonic()
        if now - self._last_internal_error >= REQUEST_INTERVAL_S:
            self._last_internal_error = now
            self.request("internal_error")

    def _on_query(self, query: Any) -> None:
        if self._waiting:  # one waiting already: this one gets the same file
            next(iter(self._waiting.values())).append(query)
            return
        now = time.monotonic()
        if now - self._last_request < REQUEST_INTERVAL_S:
            wait = REQUEST_INTERVAL_S - (now - self._last_request)
            busy = f"busy: one flight record per {REQUEST_INTERVAL_S:g} s; ask again in {wait:.1f} s"
            reply(query, {"ok": False, "reason": busy})
            return
        self._next_id += 1
        ident = str(self._next_id)
        if not self.request("request", ident):
            reply(
                query,
                {"ok": False, "reason": "the flight recorder is not running (it is being started again)"},
            )
            return
        self._last_request = now
        self._waiting[ident] = [query]
        asyncio.get_running_loop().call_later(REQUEST_TIMEOUT_S, self._expire, ident)

    def _expire(self, ident: str) -> None:
        for query in self._waiting.pop(ident, ()):
            reply(query, {"ok": False, "reason": f"no flight record written within {REQUEST_TIMEOUT_S:g} s"})

    def _fail_waiting(self, reason: str) -> None:
        waiting, self._waiting = self._waiting, {}
        for queries in waiting.values():
            for query in queries:
                reply(query, {"ok": False, "reason": reason})


class _InternalErrors(logging.Handler):
    """Passes each internal error the daemon logs (an ERROR with its traceback) to the recorder."""

    def __init__(self, recorder: FlightRecorder, loop: asyncio.AbstractEventLoop) -> None:
        super().__init__(logging.ERROR)
        self._recorder = recorder
        self._loop = loop

    def emit(self, record: logging.LogRecord) -> None:
        if record.exc_info is None or record.name == __name__:
            return
        with contextlib.suppress(RuntimeError):  # the loop closed
            self._loop.call_soon_threadsafe(self._recorder.internal_error)
