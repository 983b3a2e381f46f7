"""The log rate limit keeps no record, and so no exception or frame, alive (review of issue 13)."""

from __future__ import annotations

import gc
import logging
import sys
import weakref

from urdaemon.logs import RateLimit


class _Boom(Exception):
    pass


class _Big:
    """Stands for a failing frame's large local (a 2 MiB goal)."""


def _failing_record(logger: logging.Logger, big_refs: list[weakref.ref[_Big]]) -> logging.LogRecord:
    def fail() -> None:
        goal = _Big()  # a local of the failing frame
        big_refs.append(weakref.ref(goal))
        raise _Boom("goal failed")

    try:
        fail()
    except _Boom:
        return logger.makeRecord(
            logger.name, logging.ERROR, __file__, 42, "goal failed: %s", ("x",), sys.exc_info()
        )
    raise AssertionError("unreachable")


def test_a_rate_limited_burst_keeps_no_exception_or_frame_alive() -> None:
    """Reproduction: log 5 records with ``exc_info`` from one call site through a ``RateLimit``
    whose burst is 2, then drop every reference the test holds. The site's rate-limit state kept
    the first record (with its ``exc_info``) for the whole interval, so the exception, its traceback
    and the failing frame's locals stayed alive; the summary still names the template."""
    now = [0.0]
    limit = RateLimit(burst=2, interval=10.0, clock=lambda: now[0])
    logger = logging.getLogger("test.review.ratelimit")
    big_refs: list[weakref.ref[_Big]] = []
    exc_refs: list[weakref.ref[BaseException]] = []
    passed = 0
    for _ in range(5):
        record = _failing_record(logger, big_refs)
        assert record.exc_info is not None
        assert record.exc_info[1] is not None
        exc_refs.append(weakref.ref(record.exc_info[1]))
        passed += limit.filter(record)
        del record
    assert passed == 2
    gc.collect()
    assert [ref() for ref in exc_refs] == [None] * 5, "an exception is kept by the rate limit"
    assert [ref() for ref in big_refs] == [None] * 5, "a failing frame's local is kept by the rate limit"
    now[0] = 11.0
    (summary,) = limit.summaries()
    text = summary.getMessage()
    assert "suppressed 3 similar messages" in text
    assert "goal failed: %s" in text
    assert summary.levelno == logging.ERROR
    assert summary.name == logger.name
    assert summary.lineno == 42
