"""Messages of a key expression with the time each came: what ``hz`` and ``info`` measure rates from.

Zenoh's thread stamps each message as it receives it and appends it to a queue; the loop takes them
in batches (``drain``), so a 500 Hz stream costs the loop one wake-up per batch, not per message.
"""

from __future__ import annotations

import contextlib
import json
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any

from urdaemon.introspect.rates import DEFAULT_WINDOW, RateWindow

__all__ = ["HOST_TIME", "RECEIVE_TIME", "Collector", "KeyTimes", "message_time_ns"]

HOST_TIME = "host_time_ns"
"""The time source when every message carries the daemon's ``host_time_ns``."""
RECEIVE_TIME = "receive time"
"""The time source otherwise: when this process received each message."""
MAX_QUEUED = 100_000
"""Messages kept between two drains at most (the oldest are dropped, and counted)."""


def message_time_ns(payload: bytes) -> int | None:
    """The message's own ``host_time_ns`` (None: not a JSON object carrying an integer one)."""
    try:
        data = json.loads(payload)
    except (UnicodeDecodeError, ValueError):
        return None
    value = data.get(HOST_TIME) if isinstance(data, dict) else None
    return value if isinstance(value, int) and not isinstance(value, bool) else None


@dataclass
class KeyTimes:
    """One key's messages: their own times while all carry one, and when each was received."""

    window: int = DEFAULT_WINDOW
    own: RateWindow = field(init=False)
    received: RateWindow = field(init=False)
    all_own: bool = True
    """Every message so far carried ``host_time_ns``."""

    def __post_init__(self) -> None:
        self.own = RateWindow(self.window)
        self.received = RateWindow(self.window)

    def add(self, received_ns: int, payload: bytes) -> None:
        """One message, received at ``received_ns``."""
        self.received.add(received_ns)
        own = message_time_ns(payload) if self.all_own else None
        if own is None:
            self.all_own = False
        else:
            self.own.add(own)

    @property
    def source(self) -> str:
        """Where the times come from: ``HOST_TIME`` or ``RECEIVE_TIME``."""
        return HOST_TIME if self.all_own and self.own.count else RECEIVE_TIME

    @property
    def times(self) -> RateWindow:
        """The window the rate is measured from (the messages' own times where they all carry one)."""
        return self.own if self.source == HOST_TIME else self.received

    @property
    def count(self) -> int:
        """Messages received."""
        return self.received.count


class Collector:
    """Subscribes to a key expression on a Zenoh session; ``drain`` files what came by key."""

    def __init__(self, session: Any, key_expr: str, *, window: int = DEFAULT_WINDOW) -> None:
        self.key_expr = key_expr
        self.window = window
        self.keys: dict[str, KeyTimes] = {}
        self.dropped = 0
        self._queue: deque[tuple[str, int, bytes]] = deque(maxlen=MAX_QUEUED)
        self._sub = session.declare_subscriber(key_expr, self._on_sample)

    def _on_sample(self, sample: Any) -> None:  # Zenoh's thread: stamp and queue only
        if len(self._queue) == MAX_QUEUED:
            self.dropped += 1
        self._queue.append((str(sample.key_expr), time.time_ns(), bytes(sample.payload.to_bytes())))

    def drain(self, limit: int | None = None) -> int:
        """File the messages queued since the last drain (at most ``limit``; the rest stay queued);
        how many were filed."""
        taken = 0
        while self._queue and (limit is None or taken < limit):
            key, received_ns, payload = self._queue.popleft()
            times = self.keys.get(key)
            if times is None:
                times = self.keys[key] = KeyTimes(self.window)
            times.add(received_ns, payload)
            taken += 1
        return taken

    @property
    def total(self) -> int:
        """Messages filed so far, every key."""
        return sum(times.count for times in self.keys.values())

    def close(self) -> None:
        """Stop receiving."""
        with contextlib.suppress(Exception):
            self._sub.undeclare()
