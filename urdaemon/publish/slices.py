"""Long checks of client input run in slices between robot cycles, even when they cannot yield.

A trajectory goal's points are checked by the controller in one call of plain Python (~10 µs a
point: 50 ms for 5 000 points). Run on the loop, that call would hold every robot's cycle; in an
ordinary worker thread it would hold the GIL, and the loop would get it back only when the
interpreter forces a switch, late and unfairly on a busy machine (measured: 30 ms stalls).

``SlicedCall`` runs the call in a worker thread that only runs while the loop waits for it, for
one slice at a time: ``step(slice_s)`` hands the thread the baton and waits until the thread hands
it back, which a profile hook in the thread does at the first function call or return after
``slice_s``. So the loop is held for about one slice at a time, as by a generator's step, and the
caller turns the loop between steps (``await asyncio.sleep(0)``).
"""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable
from types import FrameType
from typing import Any, Generic, TypeVar

__all__ = ["SlicedCall"]

T = TypeVar("T")

_CHECK_EVERY = 32
"""Profile events between two looks at the clock."""


class _Abandoned(BaseException):
    """Raised in the worker when the call is closed before it finished."""


class SlicedCall(Generic[T]):
    """``fn(*args)`` run in slices: ``step`` until it returns False, then ``result()``; ``close()``
    if abandoned."""

    def __init__(self, fn: Callable[..., T], *args: Any) -> None:
        self._fn = fn
        self._args = args
        self._run = threading.Semaphore(0)  # the worker may run a slice
        self._paused = threading.Semaphore(0)  # the worker handed the baton back
        self._slice = 0.0
        self._deadline = 0.0
        self._count = 0
        self._running = False
        self._done = False
        self._abandoned = False
        self._value: T | None = None
        self._error: BaseException | None = None
        self._thread: threading.Thread | None = None

    def step(self, slice_s: float) -> bool:
        """Let the call run for one slice of ``slice_s`` (this thread waits meanwhile); True while it
        has not finished.

        The slice starts when the worker wakes. A worker slow to wake (a busy machine) is waited
        for at most ``2 * slice_s``: it then runs its slice alongside the caller and pauses by
        itself, and the next ``step`` waits for that pause before handing out another slice.
        """
        if self._done:
            return False
        self._slice = slice_s
        if self._thread is None:
            self._running = True
            self._thread = threading.Thread(target=self._work, name="sliced-call", daemon=True)
            self._thread.start()
        elif not self._running:
            self._running = True
            self._run.release()
        if self._paused.acquire(timeout=2 * slice_s):
            self._running = False
        return not self._done

    def result(self) -> T:
        """The call's return value; raises what the call raised."""
        if not self._done:
            raise RuntimeError("the call has not finished")
        if self._error is not None:
            raise self._error
        return self._value  # type: ignore[return-value]

    def close(self) -> None:
        """Abandon an unfinished call: its thread ends at its next function call or return."""
        if self._thread is not None and not self._done:
            self._abandoned = True
            self._run.release()

    # ---- the worker thread -------------------------------------------------------------------------

    def _work(self) -> None:
        self._deadline = time.perf_counter() + self._slice
        sys.setprofile(self._profile)
        try:
            self._value = self._fn(*self._args)
        except _Abandoned:
            return
        except BaseException as err:  # handed to the caller by result()
            self._error = err
        finally:
            sys.setprofile(None)
        self._done = True
        self._paused.release()

    def _profile(self, frame: FrameType, event: str, arg: Any) -> None:
        self._count += 1
        if self._count % _CHECK_EVERY or time.perf_counter() < self._deadline:
            return
        self._paused.release()
        self._run.acquire()
        if self._abandoned:
            raise _Abandoned
        self._deadline = time.perf_counter() + self._slice
