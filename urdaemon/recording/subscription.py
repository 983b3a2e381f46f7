"""A recorder's subscriptions: Zenoh callbacks that only copy what arrived into a bounded inbox.

A callback runs on one of Zenoh's threads: it takes the sample's key, its payload as bytes and the
time it arrived, appends them to the inbox and returns; converting and writing is the consumer's
(one thread: ``urdaemon record``'s writer). The flight recorder's process fills an ``Inbox`` too,
from the thread that reads its pipe (recording/flight.py), for its ring. A full inbox drops the sample
and counts it (``Inbox.dropped``), so a slow disk never backs up into Zenoh.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

__all__ = ["DEFAULT_CAPACITY", "Arrived", "Inbox", "subscribe"]

DEFAULT_CAPACITY = 200_000
"""Samples the inbox holds before it drops: 25 s of 8 robots' joint states and poses at 500 Hz."""

Arrived = tuple[str, bytes, int]
"""One sample as it arrived: key, payload, receive time (Unix ns)."""


@dataclass(slots=True)
class Inbox:
    """A bounded FIFO of arrived samples: filled by Zenoh callbacks, emptied by one consumer thread.

    ``deque.append`` and ``popleft`` are atomic under the GIL, so no lock is taken on either side.
    """

    capacity: int = DEFAULT_CAPACITY
    dropped: int = 0
    """Samples refused because the inbox was full."""
    received: dict[str, int] = field(default_factory=dict)
    """Samples received, by the key expression subscribed to."""
    _items: deque[Arrived] = field(default_factory=deque)

    def offer(self, key: str, payload: bytes, receive_ns: int) -> None:
        """Keep one sample, or count it dropped when the inbox is full."""
        if len(self._items) >= self.capacity:
            self.dropped += 1
            return
        self._items.append((key, payload, receive_ns))

    def take(self, limit: int = 10_000) -> list[Arrived]:
        """Up to ``limit`` samples, oldest first (empty when none waits)."""
        items = self._items
        out: list[Arrived] = []
        pop = items.popleft
        for _ in range(min(limit, len(items))):
            out.append(pop())
        return out

    def __len__(self) -> int:
        return len(self._items)


def _callback(inbox: Inbox, expression: str) -> Any:
    counts = inbox.received
    counts[expression] = 0
    offer = inbox.offer
    now = time.time_ns

    def on_sample(sample: Any) -> None:
        counts[expression] += 1
        offer(str(sample.key_expr), sample.payload.to_bytes(), now())

    return on_sample


def subscribe(session: Any, expressions: Sequence[str], inbox: Inbox) -> list[Any]:
    """Declare one subscriber per key expression, each copying its samples into ``inbox``; the
    subscribers (undeclare them to stop)."""
    return [session.declare_subscriber(e, _callback(inbox, e)) for e in expressions]
