"""The log handler: never blocks, drops and counts when stderr is blocked, rate limits per call
site, escapes control characters (issue 13, finding 3).

Reproductions (before the fix, ``logging.basicConfig`` wrote straight to stderr): a log call while
stderr's reader paused blocked the caller until it read again; a client's field name containing
``\\n`` forged a second log line; a client could drive one warning per message without limit.
"""

from __future__ import annotations

import io
import logging
import os
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest

from urdaemon.logs import NonBlockingHandler, RateLimit, escape_control

ROOT = Path(__file__).resolve().parents[1]


class _BlockedStream(io.StringIO):
    """A stream whose ``write`` waits until ``release`` is set (a pipe whose reader paused)."""

    def __init__(self) -> None:
        super().__init__()
        self.release = threading.Event()
        self.entered = threading.Event()

    def write(self, text: str) -> int:
        self.entered.set()
        assert self.release.wait(30.0), "the test never released the stream"
        return super().write(text)


@pytest.fixture
def logger() -> Iterator[logging.Logger]:
    log = logging.getLogger("test_logs.isolated")
    log.propagate = False
    log.setLevel(logging.DEBUG)
    yield log
    for handler in list(log.handlers):
        log.removeHandler(handler)
        handler.close()


def test_a_blocked_writer_drops_and_counts_and_says_so_once_it_moves(logger: logging.Logger) -> None:
    stream = _BlockedStream()
    handler = NonBlockingHandler(lambda: stream, maxsize=10)
    handler.setFormatter(logging.Formatter("%(message)s"))
    logger.addHandler(handler)
    logger.info("first")  # the writer takes it and blocks in write
    assert stream.entered.wait(10.0)
    done = threading.Event()

    def flood() -> None:
        for i in range(500):
            logger.warning("record %d", i)
        done.set()

    thread = threading.Thread(target=flood)
    thread.start()
    assert done.wait(10.0), "logging blocked while the writer was blocked"
    thread.join()
    assert handler.dropped >= 500 - 10
    stream.release.set()
    logger.removeHandler(handler)
    handler.close()
    lines = stream.getvalue().splitlines()
    assert lines[0] == "first"
    assert f"{handler.dropped} log records dropped: the log writer (stderr) was blocked" in lines
    assert sum(1 for line in lines if line.startswith("record ")) == 500 - handler.dropped


def test_control_characters_cannot_forge_a_line_but_a_traceback_prints(logger: logging.Logger) -> None:
    out = io.StringIO()
    handler = NonBlockingHandler(lambda: out)
    handler.setFormatter(logging.Formatter("%(levelname)s %(message)s"))
    logger.addHandler(handler)
    logger.warning("unknown field(s) %s", "a\n2026-01-01 INFO forged\r\x1b[2Jb")
    try:
        raise ValueError("boom")
    except ValueError:
        logger.exception("it failed: %s", "x\ny")
    logger.removeHandler(handler)
    handler.close()
    lines = out.getvalue().splitlines()
    assert lines[0] == "WARNING unknown field(s) a\\n2026-01-01 INFO forged\\r\\x1b[2Jb"
    assert lines[1] == "ERROR it failed: x\\ny"
    assert lines[2] == "Traceback (most recent call last):"
    assert lines[-1] == "ValueError: boom"


def test_escape_control_escapes_c0_c1_and_line_separators() -> None:
    assert escape_control("plain text ü") == "plain text ü"
    assert escape_control("\t\x00\x7f\x85\u2028") == "\\t\\x00\\x7f\\x85\\u2028"


def test_rate_limit_per_call_site_then_one_summary() -> None:
    now = [0.0]
    limit = RateLimit(burst=3, interval=10.0, clock=lambda: now[0])

    def record(line: int) -> logging.LogRecord:
        return logging.LogRecord("urdaemon.x", logging.WARNING, "f.py", line, "refused %s", ("a",), None)

    passed = [limit.filter(record(1)) for _ in range(100)]
    assert passed.count(True) == 3
    assert limit.filter(record(2))  # another call site has its own budget
    assert limit.summaries() == []  # the interval has not ended
    now[0] = 10.0
    summaries = limit.summaries()
    assert [s.getMessage() for s in summaries] == ["suppressed 97 similar messages in 10 s (refused %s)"]
    assert limit.filter(record(1))  # a new interval, a new budget


def test_rate_limit_budgets_are_per_robot() -> None:
    """One robot's flood must not silence another robot's lines from the same call site."""
    limit = RateLimit(burst=2, interval=10.0, clock=lambda: 0.0)

    def record(line: int, msg: str, *args: object) -> logging.LogRecord:
        return logging.LogRecord("urdaemon.robot", logging.WARNING, "r.py", line, msg, args, None)

    # a logger adapter's literal prefix (robot.py), and the name as the first argument (backends)
    assert [limit.filter(record(7, "[alice] refused %s", "x")) for _ in range(5)].count(True) == 2
    assert limit.filter(record(7, "[bob] refused %s", "x"))
    assert [limit.filter(record(9, "[%s] not ready", "alice")) for _ in range(5)].count(True) == 2
    assert limit.filter(record(9, "[%s] not ready", "bob"))
    assert not limit.filter(record(9, "[%s] not ready", "alice"))


def test_setup_logging_installs_the_rate_limited_queue_in_a_fresh_process() -> None:
    """What ``urdaemon serve`` installs: 100 warnings from one call site print 20 and one summary."""
    code = (
        "import logging\n"
        "from urdaemon import logs\n"
        "handler = logs.setup_logging(False)\n"
        "assert isinstance(handler, logs.NonBlockingHandler), handler\n"
        "for i in range(100):\n"
        "    logging.getLogger('urdaemon.test').warning('same site %d', i)\n"
        "logs.shutdown_logging()\n"
    )
    run = subprocess.run(
        [sys.executable, "-c", code],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    assert run.returncode == 0, run.stderr
    lines = run.stderr.splitlines()
    assert sum(1 for line in lines if "same site" in line and "suppressed" not in line) == 20
    assert any("suppressed 80 similar messages" in line for line in lines), run.stderr
