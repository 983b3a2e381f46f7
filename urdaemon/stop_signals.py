"""How a ``urdaemon`` process is stopped by signals, one policy for every command that runs until stopped.

The serving processes (``serve``, ``fake-robot``, ``router``) stop cleanly on SIGINT, SIGTERM and SIGHUP
(``STOP_SIGNALS``): ``stop_on_signals`` sets their stop event, a repeat while stopping is only logged, and
``end_stop_signals`` decides what the signals do once the clean stop is done (``stop_signal_handlers``
takes the handlers to put back). The viewers (``view``, ``foxglove``) stop on SIGINT and SIGTERM
(``VIEWER_STOP_SIGNALS``) through their loop's handlers, for as long as ``stopped_by_signals`` holds them.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import signal
import threading
from collections.abc import Iterator
from typing import Any

__all__ = [
    "STOP_SIGNALS",
    "VIEWER_STOP_SIGNALS",
    "end_stop_signals",
    "stop_on_signals",
    "stop_signal_handlers",
    "stopped_by_signals",
]

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
"""Each stops ``serve``, ``fake-robot`` and ``router`` cleanly; a repeat while stopping is only logged."""
VIEWER_STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)
"""Each stops ``view`` and ``foxglove``."""


def stop_on_signals(stop: asyncio.Event, what: str) -> None:
    """SIGINT, SIGTERM and SIGHUP set ``stop`` (a clean stop: every goal ends with a result).

    A repeated signal while stopping is logged and otherwise ignored, so it cannot cut the clean stop
    short; the handlers stay after the loop has ended, so a signal during the process's exit is
    ignored too (asyncio's own handlers fall back to the default, which kills the process). Call it
    on the running loop, in the main thread (elsewhere it does nothing).
    """
    if threading.current_thread() is not threading.main_thread():
        return
    loop = asyncio.get_running_loop()
    log = logging.getLogger("urdaemon")

    def deliver(signum: int) -> None:
        name = signal.Signals(signum).name
        if stop.is_set():
            log.warning("%s: %s is already stopping cleanly (SIGKILL would skip that)", name, what)
            return
        log.info("%s: stopping %s", name, what)
        stop.set()

    def handler(signum: int, frame: object) -> None:
        # RuntimeError: the loop has ended: the clean stop is done and the process exits
        with contextlib.suppress(RuntimeError):
            loop.call_soon_threadsafe(deliver, signum)

    for sig in STOP_SIGNALS:
        signal.signal(sig, handler)


def stop_signal_handlers() -> dict[signal.Signals, Any]:
    """The stop signals' handlers now, to put back with ``end_stop_signals`` (main thread only)."""
    if threading.current_thread() is not threading.main_thread():
        return {}
    return {sig: signal.getsignal(sig) for sig in STOP_SIGNALS}


def end_stop_signals(previous: dict[signal.Signals, Any] | None) -> None:
    """After a clean stop. A command that owns its process (``previous`` None: run as ``urdaemon``)
    ignores the stop signals for the rest of the exit (Python resets its own handlers to the default,
    fatal one while it finalizes; an ignored signal stays ignored). Run in-process (``main`` given
    its arguments: a test, a program), the handlers ``previous`` are put back instead: an ignored
    SIGINT would outlive the command, and every process started afterwards would inherit it
    (Ctrl-C would no longer stop a ``urdaemon move`` started by the same test worker)."""
    if threading.current_thread() is not threading.main_thread():
        return
    for sig in STOP_SIGNALS:
        handler = signal.SIG_IGN if previous is None else previous.get(sig)
        if handler is not None:
            signal.signal(sig, handler)


@contextlib.contextmanager
def stopped_by_signals(stop: asyncio.Event) -> Iterator[None]:
    """Inside: SIGINT and SIGTERM set ``stop``, as handlers of the running loop (only the main thread
    may add them; elsewhere none is added). Leaving removes the handlers it added."""
    loop = asyncio.get_running_loop()
    handled = []
    for sig in VIEWER_STOP_SIGNALS:
        with contextlib.suppress(ValueError, RuntimeError):  # only the main thread may
            loop.add_signal_handler(sig, stop.set)
            handled.append(sig)
    try:
        yield
    finally:
        for sig in handled:
            loop.remove_signal_handler(sig)
