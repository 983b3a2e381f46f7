"""Logging that never blocks the control loop.

Every record goes through a bounded queue (``put_nowait``); one writer thread takes records off the
queue and writes them to stderr. When stderr blocks (a pipe whose reader pauses: journald, a docker
log driver, a terminal in flow control) the writer waits there, the queue fills, and further records
are dropped and counted; once the writer moves again it says how many were lost.

Before a record is queued it is rate limited per call site (logger, file and line) and robot (a
``[name]`` prefix): at most
``burst`` records per ``interval`` seconds, then one ``suppressed K similar messages`` line when the
interval ends. The message (template and arguments) has its control characters escaped, so client
text can never forge a log line or drive the terminal; a traceback is kept as it is.
"""

from __future__ import annotations

import logging
import queue
import re
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

__all__ = [
    "QUEUE_SIZE",
    "RATE_BURST",
    "RATE_INTERVAL_S",
    "NonBlockingHandler",
    "RateLimit",
    "escape_control",
    "setup_logging",
]

QUEUE_SIZE = 1000
"""Records waiting for the writer; more are dropped (and counted) while it is blocked."""
RATE_BURST = 20
"""Records one call site may log per interval before the rest are suppressed."""
RATE_INTERVAL_S = 10.0
FORMAT = "%(asctime)s %(levelname)s %(name)s: %(message)s"

_CONTROL = re.compile("[\x00-\x1f\x7f-\x9f\u2028\u2029]")
_NAMED = {"\n": "\\n", "\r": "\\r", "\t": "\\t"}


def _escape_one(match: re.Match[str]) -> str:
    char = match.group()
    named = _NAMED.get(char)
    if named is not None:
        return named
    code = ord(char)
    return f"\\x{code:02x}" if code < 0x100 else f"\\u{code:04x}"


def escape_control(text: str) -> str:
    """``text`` with every control character (``\\n``, ``\\r``, ESC, C1, line separators) escaped."""
    if text.isprintable():  # the common case: one C-level scan, no regex
        return text
    return _CONTROL.sub(_escape_one, text)


def _subject(record: logging.LogRecord) -> str:
    """The robot a message is about, from its ``[name]`` prefix (literal or a first ``%s``
    argument), so that one robot's flood does not use up another's budget."""
    msg = record.msg
    if not isinstance(msg, str) or not msg.startswith("["):
        return ""
    if msg.startswith("[%s]") and isinstance(record.args, tuple) and record.args:
        return str(record.args[0])[:40]
    end = msg.find("]", 1, 42)
    return msg[1:end] if end > 0 else ""


@dataclass(slots=True)
class _Site:
    """One call site's interval: counts and what its summary line names. Not the first record
    itself: that would keep its ``exc_info`` (traceback, frames and their locals) alive."""

    start: float
    count: int
    suppressed: int
    name: str
    levelno: int
    pathname: str
    lineno: int
    template: str

    @classmethod
    def first(cls, now: float, record: logging.LogRecord) -> _Site:
        template = record.msg if isinstance(record.msg, str) else type(record.msg).__name__
        return cls(now, 0, 0, record.name, record.levelno, record.pathname, record.lineno, template)


class RateLimit(logging.Filter):
    """At most ``burst`` records per call site per ``interval`` s; the rest are counted.

    ``summaries()`` returns one record per call site whose interval ended with suppressed records.
    """

    MAX_SITES = 10_000

    def __init__(
        self,
        burst: int = RATE_BURST,
        interval: float = RATE_INTERVAL_S,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        super().__init__()
        self.burst = burst
        self.interval = interval
        self._clock = clock
        self._sites: dict[tuple[str, str, int, str], _Site] = {}
        self._ended: list[_Site] = []
        self._lock = threading.Lock()

    def filter(self, record: logging.LogRecord) -> bool:
        key = (record.name, record.pathname, record.lineno, _subject(record))
        now = self._clock()
        with self._lock:
            site = self._sites.get(key)
            if site is None or now - site.start >= self.interval:
                if site is not None and site.suppressed:
                    self._ended.append(site)
                if site is None and len(self._sites) >= self.MAX_SITES:
                    self._prune(now)
                site = self._sites[key] = _Site.first(now, record)
            site.count += 1
            if site.count <= self.burst:
                return True
            site.suppressed += 1
            return False

    def _prune(self, now: float) -> None:
        for key, site in list(self._sites.items()):
            if now - site.start >= self.interval:
                if site.suppressed:
                    self._ended.append(site)
                del self._sites[key]

    def summaries(self, final: bool = False) -> list[logging.LogRecord]:
        """One ``suppressed K similar messages`` record for each call site whose interval has ended
        (``final``: for every call site that suppressed something, ended or not)."""
        now = self._clock()
        with self._lock:
            for key, site in list(self._sites.items()):
                if final or now - site.start >= self.interval:
                    if site.suppressed:
                        self._ended.append(site)
                    del self._sites[key]
            ended, self._ended = self._ended, []
        return [self._summary(site) for site in ended]

    def _summary(self, site: _Site) -> logging.LogRecord:
        return logging.LogRecord(
            site.name,
            site.levelno,
            site.pathname,
            site.lineno,
            "suppressed %d similar messages in %.0f s (%s)",
            (site.suppressed, self.interval, site.template),
            None,
        )


class NonBlockingHandler(logging.Handler):
    """Queue records without ever waiting; a writer thread formats them onto ``stream()``.

    ``stream`` is called for every write (so it follows ``sys.stderr`` when that is replaced).
    """

    def __init__(
        self,
        stream: Callable[[], object] = lambda: sys.stderr,
        *,
        maxsize: int = QUEUE_SIZE,
        rate_limit: RateLimit | None = None,
        tick: float = 1.0,
    ) -> None:
        super().__init__()
        self._stream = stream
        self._queue: queue.Queue[logging.LogRecord | None] = queue.Queue(maxsize)
        self.dropped = 0
        """Records dropped because the queue was full (the writer was blocked)."""
        self._reported = 0
        self.rate_limit = rate_limit
        if rate_limit is not None:
            self.addFilter(rate_limit)
        self._tick = tick
        self._traceback = logging.Formatter()
        self._thread = threading.Thread(target=self._write_loop, name="log-writer", daemon=True)
        self._thread.start()

    def handle(self, record: logging.LogRecord) -> bool:  # no handler lock: the queue is thread-safe
        if not self.filter(record):
            return False
        self.emit(record)
        return True

    def emit(self, record: logging.LogRecord) -> None:
        try:
            prepared = self._prepare(record)
        except Exception:
            self.handleError(record)
            return
        try:
            self._queue.put_nowait(prepared)
        except queue.Full:
            self.dropped += 1

    def _prepare(self, record: logging.LogRecord) -> logging.LogRecord:
        """A copy with the message merged and escaped, the traceback as text (arguments may change
        after this call returns, and may not be thread-safe to format later)."""
        message = escape_control(record.getMessage())
        prepared = logging.makeLogRecord(record.__dict__)
        prepared.msg = message
        prepared.args = None
        prepared.message = message
        if record.exc_info and not record.exc_text:
            prepared.exc_text = self._traceback.formatException(record.exc_info)
        prepared.exc_info = None
        return prepared

    def _write_loop(self) -> None:
        while True:
            try:
                record = self._queue.get(timeout=self._tick)
            except queue.Empty:
                record = None
                stop = False
            else:
                stop = record is None
            self._write_notes(final=stop)
            if record is not None:
                self._write(record)
            if stop:
                return

    def _write_notes(self, final: bool = False) -> None:
        dropped = self.dropped
        if dropped > self._reported:
            note = logging.LogRecord(
                "urdaemon.logs",
                logging.WARNING,
                __file__,
                0,
                "%d log records dropped: the log writer (stderr) was blocked",
                (dropped - self._reported,),
                None,
            )
            self._reported = dropped
            self._write(note)
        if self.rate_limit is not None:
            for summary in self.rate_limit.summaries(final):
                self._write(summary)

    def _write(self, record: logging.LogRecord) -> None:
        try:
            text = self.format(record)
            stream = self._stream()
            stream.write(text + "\n")  # type: ignore[attr-defined]
            stream.flush()  # type: ignore[attr-defined]
        except Exception:
            self.handleError(record)

    def close(self, timeout: float = 2.0) -> None:
        """Write what is queued (for at most ``timeout`` s: a blocked writer must not hold up exit)."""
        try:
            self._queue.put(None, timeout=timeout)
        except queue.Full:
            pass
        else:
            self._thread.join(timeout)
        super().close()


_installed: NonBlockingHandler | None = None


def setup_logging(verbose: bool = False) -> NonBlockingHandler | None:
    """Log to stderr through a ``NonBlockingHandler`` with rate limits.

    Like ``logging.basicConfig``, it does nothing when the root logger already has a handler (a host
    program, or pytest, configured logging): returns the handler installed, or None.
    """
    global _installed
    root = logging.getLogger()
    if _installed is not None and _installed in root.handlers:
        root.setLevel(logging.DEBUG if verbose else logging.INFO)
        return _installed
    if root.handlers:
        return None
    handler = NonBlockingHandler(rate_limit=RateLimit())
    handler.setFormatter(logging.Formatter(FORMAT))
    root.addHandler(handler)
    root.setLevel(logging.DEBUG if verbose else logging.INFO)
    logging.captureWarnings(True)  # warnings.warn writes to stderr directly otherwise
    _installed = handler
    return handler


def shutdown_logging() -> None:
    """Write the queued records (bounded in time) and remove the handler ``setup_logging`` installed."""
    global _installed
    handler, _installed = _installed, None
    if handler is not None:
        logging.captureWarnings(False)
        logging.getLogger().removeHandler(handler)
        handler.close()
