"""The flight recorder's pure parts: the ring of the last seconds, the triggers read from the stream,
and the bursts (at most one file per burst of triggers).

- ``Ring``: raw samples (key, payload, receive time), the oldest dropped once older than ``seconds``
  or once the ring holds more than ``max_bytes`` (counted with each sample's Python overhead).
- ``Triggers``: what in the stream itself calls for a file: a robot's status lifecycle turning to
  ``protective_stop`` or ``emergency_stop``; turning to ``disconnected`` or ``recovering`` from a
  connected state (a lost link); a goal's or a cell goal's result ``aborted``.
- ``Bursts``: a trigger opens a burst, written ``after_s`` later in the stream (the seconds after it,
  judged by the samples' own times, so a pipe that lags behind the wall clock still brings them; at
  most ``STREAM_WAIT_S`` more by the wall clock when the stream stops); triggers
  until then join it, and stream triggers within ``quiet_s`` of the burst's last one are the same
  incident (a protective stop aborts the goal, then the link recovers): no second file. A request
  (the daemon's: an internal error, a client's query) always gets a file: the open burst's, or its own.

No clocks, no IO: times are passed in (ns), so the tests drive them from tables.
"""

from __future__ import annotations

import json
import re
from collections import deque
from dataclasses import dataclass, field

__all__ = ["ITEM_OVERHEAD", "STREAM_WAIT_S", "Burst", "Bursts", "Ring", "Triggers", "file_name"]

ITEM_OVERHEAD = 200
"""Bytes a sample costs in the ring besides its key and payload (the tuple, the bytes and str objects,
the deque slot), measured with sys.getsizeof on CPython 3.11."""

STREAM_WAIT_S = 2.0
"""How long past a burst's end, by the wall clock, it waits for the stream to get there (the daemon
starved, or its pipe behind): after that it is written with what came."""

_STOPS = frozenset({"protective_stop", "emergency_stop"})
_LOST = frozenset({"disconnected", "recovering"})
_CONNECTED = frozenset({"idle", "running", "paused", "protective_stop", "emergency_stop"})


@dataclass(slots=True)
class Ring:
    """The last ``seconds`` of samples, at most ``max_bytes`` of them."""

    seconds: float
    max_bytes: int
    items: deque[tuple[str, bytes, int]] = field(default_factory=deque)
    size: int = 0
    """Bytes held (keys, payloads and ``ITEM_OVERHEAD`` each)."""
    dropped_for_size: int = 0
    """Samples dropped younger than ``seconds`` because the ring was full."""

    def add(self, key: str, payload: bytes, receive_ns: int) -> None:
        """Keep one sample; drop what is too old or too much."""
        self.items.append((key, payload, receive_ns))
        self.size += len(key) + len(payload) + ITEM_OVERHEAD
        oldest = receive_ns - int(self.seconds * 1e9)
        items = self.items
        while items and items[0][2] < oldest:
            self._drop()
        while self.size > self.max_bytes and len(items) > 1:
            self._drop()
            self.dropped_for_size += 1

    def _drop(self) -> None:
        key, payload, _ = self.items.popleft()
        self.size -= len(key) + len(payload) + ITEM_OVERHEAD

    @property
    def newest_ns(self) -> int:
        """The newest sample's receive time (0 when empty): how far the stream got."""
        return self.items[-1][2] if self.items else 0

    def snapshot(self, since_ns: int = 0) -> list[tuple[str, bytes, int]]:
        """The samples held received at ``since_ns`` or later, oldest first (a copy: the ring goes on)."""
        return [item for item in self.items if item[2] >= since_ns]


class Triggers:
    """Reads each sample's key (and, for status and results, its JSON) for a reason to write a file."""

    def __init__(self) -> None:
        self._lifecycle: dict[str, str] = {}

    def check(self, key: str, payload: bytes) -> str | None:
        """The reason ``key``'s sample calls for a file (``protective_stop_alice``), or None."""
        if key.endswith("/status"):
            return self._status(key, payload)
        if key.endswith("/result") and "/goal/" in key:
            return _aborted(key, payload)
        return None

    def _status(self, key: str, payload: bytes) -> str | None:
        parts = key.split("/")
        if len(parts) != 3:
            return None
        robot = parts[1]
        lifecycle = _field(payload, "lifecycle")
        if lifecycle is None:
            return None
        before = self._lifecycle.get(robot)
        self._lifecycle[robot] = lifecycle
        if lifecycle == before:
            return None
        if lifecycle in _STOPS:
            return f"{lifecycle}_{robot}"
        if lifecycle in _LOST and before in _CONNECTED:
            return f"lost_link_{robot}"
        return None


def _field(payload: bytes, name: str) -> str | None:
    try:
        message = json.loads(payload)
    except ValueError:
        return None
    value = message.get(name) if isinstance(message, dict) else None
    return value if isinstance(value, str) else None


def _aborted(key: str, payload: bytes) -> str | None:
    if _field(payload, "status") != "aborted":
        return None
    parts = key.split("/")
    return "aborted_cell_goal" if parts[1] == "goal" else f"aborted_{parts[1]}"


@dataclass(slots=True)
class Burst:
    """One file to write: when its first trigger came, why, and the requests waiting for it."""

    first_ns: int
    due_ns: int
    reasons: list[str]
    requests: list[str] = field(default_factory=list)

    @property
    def reason(self) -> str:
        """The reason the file is named after: the gravest (a stop before the goal it aborted)."""
        return min(self.reasons, key=_gravity)


_GRAVITY = ("emergency_stop", "protective_stop", "lost_link", "internal_error", "aborted", "request")


def _gravity(reason: str) -> int:
    for rank, prefix in enumerate(_GRAVITY):
        if reason.startswith(prefix):
            return rank
    return len(_GRAVITY)


class Bursts:
    """At most one file per burst of triggers (see the module's text)."""

    def __init__(self, after_s: float, quiet_s: float) -> None:
        self._after_ns = int(after_s * 1e9)
        self._quiet_ns = int(quiet_s * 1e9)
        self.open: Burst | None = None
        self._last_trigger_ns: int | None = None
        self.merged = 0
        """Stream triggers that were part of a burst already written."""

    def trigger(self, reason: str, now_ns: int, request: str | None = None) -> None:
        """A reason to write (``request``: an id to answer once the file is written)."""
        last, self._last_trigger_ns = self._last_trigger_ns, now_ns
        if self.open is not None:
            if reason not in self.open.reasons:
                self.open.reasons.append(reason)
            if request is not None:
                self.open.requests.append(request)
            return
        if request is None and last is not None and now_ns - last < self._quiet_ns:
            self.merged += 1
            return
        self.open = Burst(now_ns, now_ns + self._after_ns, [reason], [] if request is None else [request])

    def due(self, stream_ns: int, now_ns: int) -> Burst | None:
        """The burst to write now (it is closed): once the stream (its newest sample, ``stream_ns``)
        reached its end, or ``STREAM_WAIT_S`` after that by the wall clock (``now_ns``)."""
        burst = self.open
        if burst is None:
            return None
        if stream_ns < burst.due_ns and now_ns < burst.due_ns + int(STREAM_WAIT_S * 1e9):
            return None
        self.open = None
        return burst


_UNSAFE = re.compile(r"[^A-Za-z0-9_-]+")


def file_name(cell: str, first_ns: int, reason: str) -> str:
    """``<cell>_<UTC time>_<reason>.mcap``: ``demo_cell_20261128-173750.123_protective_stop_alice.mcap``."""
    import time

    seconds, ns = divmod(first_ns, 1_000_000_000)
    stamp = time.strftime("%Y%m%d-%H%M%S", time.gmtime(seconds)) + f".{ns // 1_000_000:03d}"
    return f"{cell}_{stamp}_{_UNSAFE.sub('_', reason).strip('_')[:60] or 'request'}.mcap"
