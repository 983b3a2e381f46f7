"""The one way in from Zenoh's threads: each sample's key and payload bytes put in a bounded queue
(no decoding there), taken by the bridge's converter thread. When the queue is full the sample is
dropped and counted: a slow Foxglove client or a busy machine never makes a Zenoh thread wait, so
nothing the bridge does reaches back to the daemon's cycle.
"""

from __future__ import annotations

import queue
import threading
import time
from typing import Any

__all__ = ["CAPACITY", "Handoff", "Item"]

CAPACITY = 4096
"""Samples waiting for the converter at most (a few seconds of two 500 Hz robots)."""

Item = tuple[str, bytes, int]
"""(key, payload, ``time.time_ns()`` when it came)."""


class Handoff:
    """Samples from Zenoh's threads to the converter thread, at most ``capacity`` waiting."""

    def __init__(self, capacity: int = CAPACITY) -> None:
        self._queue: queue.Queue[Item] = queue.Queue(capacity)
        self._count = threading.Lock()  # Zenoh calls back on several threads; never held long
        self.offered = 0
        """Samples offered (kept or dropped)."""
        self.dropped = 0
        """Samples dropped because the queue was full."""

    def on_sample(self, sample: Any) -> None:
        """A Zenoh subscriber's callback (on Zenoh's thread)."""
        self.offer(str(sample.key_expr), sample.payload.to_bytes())

    def offer(self, key: str, payload: bytes) -> bool:
        """Queue one message unless the queue is full (then it is dropped and counted)."""
        try:
            self._queue.put_nowait((key, payload, time.time_ns()))
        except queue.Full:
            with self._count:
                self.offered += 1
                self.dropped += 1
            return False
        with self._count:
            self.offered += 1
        return True

    def take(self, timeout: float) -> Item | None:
        """The oldest waiting message, waiting at most ``timeout`` for one; None when none came."""
        try:
            return self._queue.get(timeout=timeout)
        except queue.Empty:
            return None
