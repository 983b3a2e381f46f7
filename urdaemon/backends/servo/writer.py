"""The thread that puts a servo output's frames on its device, so the robot's cycle never waits on
a bus: the cycle hands over its newest frame and goes on; a frame the device had no time for is
replaced by the next one (and counted). A device that fails is closed, and opened again after a
backoff, until it answers; the report says what happened for the backend to tell users.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from urdaemon.backends.servo.link import BoardLink

__all__ = ["PROBE_EVERY_S", "RETRY_S", "OutputReport", "OutputWriter"]

RETRY_S = (0.1, 0.25, 0.5, 1.0, 2.0, 5.0)
"""Waits before each attempt to open a failed device again; the last repeats."""
PROBE_EVERY_S = 1.0
"""With no frame to write for this long, the writer asks the device whether it is still there
(``BoardLink.check``), so a board lost while the arm rests is found before the next motion."""


@dataclass(frozen=True, slots=True)
class OutputReport:
    """One output's counters and condition, as its writer last saw them."""

    label: str
    state: str
    """``connecting`` (never opened yet), ``ok``, ``lost`` (failed; opening again), ``stopped``."""
    error: str
    """The last failure (empty: none since the output last opened)."""
    retry_in_s: float
    """How long until the next attempt to open it (while ``connecting`` or ``lost``)."""
    frames: int
    """Frames put on the device."""
    transfers: int
    """Bus transfers those took (I²C block writes, serial lines)."""
    superseded: int
    """Frames replaced by a newer one before the device took them (the device was slower)."""
    failures: int
    """Failed opens and writes."""
    reopened: int
    """Times the output came back after failing."""

    def as_dict(self) -> dict[str, object]:
        """The report as the ``status`` message's ``outputs`` list carries it."""
        return {
            "output": self.label,
            "state": self.state,
            "error": self.error,
            "frames": self.frames,
            "transfers": self.transfers,
            "superseded": self.superseded,
            "failures": self.failures,
            "reopened": self.reopened,
        }


class OutputWriter:
    """Drives one ``BoardLink`` from a thread of its own; ``submit`` never blocks."""

    def __init__(
        self,
        link: BoardLink,
        *,
        retry_s: Sequence[float] = RETRY_S,
        probe_every_s: float = PROBE_EVERY_S,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.label = link.label
        self._link = link
        self._retry = tuple(retry_s)
        self._probe_every = probe_every_s
        self._clock = clock
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._stopping = threading.Event()
        self._pending: Sequence[float] | None = None
        self._last: Sequence[float] | None = None
        self._off_at_stop = False
        self._thread: threading.Thread | None = None
        self.changes = 0
        """Counts changes of ``state`` or ``error``: a reader compares it with the value it last saw."""
        self._state = "connecting"
        self._error = ""
        self._retry_at = 0.0
        self._frames = self._transfers = self._superseded = self._failures = self._reopened = 0

    # ---- the loop's side ------------------------------------------------------------------------

    def submit(self, pulses: Sequence[float]) -> None:
        """Make ``pulses`` the next frame to write (replacing one not yet written)."""
        with self._lock:
            if self._pending is not None and self._state == "ok":  # a frame the device had no time for
                self._superseded += 1
            self._pending = pulses
        self._wake.set()

    def report(self) -> OutputReport:
        """The output's condition and counters now."""
        with self._lock:
            retry = max(0.0, self._retry_at - self._clock()) if self._state in ("connecting", "lost") else 0.0
            return OutputReport(
                self.label,
                self._state,
                self._error,
                retry,
                self._frames,
                self._transfers,
                self._superseded,
                self._failures,
                self._reopened,
            )

    def start(self) -> None:
        """Start the thread (it opens the device first)."""
        self._thread = threading.Thread(target=self._run, name=f"servo output {self.label}", daemon=True)
        self._thread.start()

    def stop(self, off: bool) -> None:
        """End the thread, first stopping every pulse if ``off``; blocks until it ended (run it off the
        event loop)."""
        self._off_at_stop = off
        self._stopping.set()
        self._wake.set()
        if self._thread is not None:
            self._thread.join()

    # ---- the thread -----------------------------------------------------------------------------

    def _run(self) -> None:
        attempt = 0
        opened = False
        try:
            while not self._stopping.is_set():
                if not opened:
                    opened = self._open(attempt)
                    attempt = 0 if opened else attempt + 1
                    if not opened:
                        self._stopping.wait(self._retry[min(attempt - 1, len(self._retry) - 1)])
                    continue
                woke = self._wake.wait(self._probe_every)
                self._wake.clear()
                if self._stopping.is_set():
                    break
                with self._lock:
                    frame, self._pending = self._pending, None
                if frame is not None:
                    opened = self._attempt(self._write, frame)
                elif not woke:  # nothing to write for a while: is the board still there?
                    opened = self._attempt(self._probe, ())
                if not opened:
                    attempt = 1
                    self._stopping.wait(self._retry[0])
        finally:
            self._finish(opened)

    def _open(self, attempt: int) -> bool:
        try:
            self._link.open()
            with self._lock:  # the newest frame wanted: the pose the robot's state shows
                frame = self._pending if self._pending is not None else self._last
                self._pending = None
            if frame is not None:  # the board may have been reset: write it whole
                self._write(frame)
        except Exception as err:  # OSError: the device; else a bug, told the same way
            self._link.close()
            self._failed(err, self._retry[min(attempt, len(self._retry) - 1)])
            return False
        with self._lock:
            if self._state == "lost":
                self._reopened += 1
            self._set("ok", "")
        return True

    def _attempt(self, action: Callable[[Sequence[float]], None], frame: Sequence[float]) -> bool:
        """Run ``action``; when it fails close the link and report it (False). A device fails with
        ``OSError``; anything else is a bug, reported and retried the same way rather than ending the
        thread, so the robot is never left "ok" with nobody driving its servos."""
        try:
            action(frame)
        except Exception as err:
            self._link.close()
            self._failed(err, self._retry[0])
            return False
        return True

    def _write(self, frame: Sequence[float]) -> None:
        self._last = frame  # what the board should show: written again if the output has to reopen
        transfers = self._link.write(frame)
        with self._lock:
            self._frames += 1
            self._transfers += transfers

    def _probe(self, _: Sequence[float]) -> None:
        self._link.check()

    def _failed(self, err: Exception, retry_in: float) -> None:
        with self._lock:
            self._failures += 1
            self._retry_at = self._clock() + retry_in
            self._state = "connecting" if self._state == "connecting" else "lost"
            self._error = _describe(err)
            self.changes += 1  # every failure, even the same again: the reason's "again in" moves on

    def _set(self, state: str, error: str) -> None:
        if (state, error) != (self._state, self._error):
            self._state, self._error = state, error
            self.changes += 1

    def _finish(self, opened: bool) -> None:
        if opened and self._off_at_stop:
            try:
                self._link.off()
            except Exception as err:  # the link closes whatever happened
                with self._lock:
                    self._failures += 1
                    self._error = _describe(err)
        self._link.close()
        with self._lock:
            self._set("stopped", self._error)


def _describe(err: Exception) -> str:
    """A failure as users read it: an OSError's message with its errno when there is one; anything
    else with its type (a bug: say what it was)."""
    if not isinstance(err, OSError):
        return f"{type(err).__name__}: {err}"
    text = err.strerror or str(err) or type(err).__name__
    return f"{text} (errno {err.errno})" if err.errno is not None and err.strerror else text
