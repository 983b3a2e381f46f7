"""What Zenoh's threads let through to the loop, and why the rest is refused (publish/node.py).

A commanding message passes a ``Guard`` (the robot's command lease) on the token it carries as its
attachment (``attachment_of``). What waits for the loop is bounded: per queryable at most
``MAX_IN_FLIGHT`` queries (``InFlight``), per subscriber the newest sample only (``Latest``) and one
report of the refusals meanwhile (``Refusals``); each counter behind a small lock, as Zenoh's
threads and the loop both touch it. What Zenoh's threads do in Python for wildcard queries is
bounded per second (``Budget``): Zenoh calls every queryable a wildcard intersects, ~50 for ``**``,
and each holds the GIL the loop needs. The refusals' texts are here too, so every refusal reads the
same.
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any, Protocol

from urdaemon.publish.envelope import client_text, encode

__all__ = [
    "CELL_QUERIES_PER_S",
    "MAX_IN_FLIGHT",
    "WILDCARD_REPLIES_AT_ONCE",
    "WILDCARD_REPLIES_PER_S",
    "Budget",
    "Guard",
    "InFlight",
    "Latest",
    "Refusals",
    "Tarpit",
    "attachment_of",
    "busy_refusal",
    "refuse_query",
    "replaced_refusal",
    "size_refusal",
    "wildcard_refusal",
]

MAX_IN_FLIGHT = 4
"""Most queries of one key handed to the loop and not yet handled. A client waits for each reply,
so a well-behaved one has one in flight per key, and only for the microseconds of the hand-over;
4 leaves room for a few clients at once, while a flood of messages at the size limit (~0.25 ms
of loop time each) can queue at most ~1 ms of work per key ahead of a robot's cycle."""


WILDCARD_REPLIES_PER_S = 200.0
"""Error replies to wildcard queries the node builds per second, all its queryables together. Each
costs ~20 µs of GIL on Zenoh's thread (plus ~16 µs of Zenoh's own), so a flood's share is bounded
to well under 1 % of a core, whichever robot's keys it names; past it a wildcard query is dropped
on Zenoh's thread without a reply (no text, no JSON, no send) and held (``Tarpit``)."""

WILDCARD_REPLIES_AT_ONCE = 1000
"""... and at once, or as many as the node has queryables if more: a Zenoh browser's ``**`` (~50
replies for two robots), or a walk of every wildcard (docs/keys.md), is answered whole."""

CELL_QUERIES_PER_S = 50.0
"""Wildcard queries handed to the loop per second by each cell queryable (``<cell>/daemon``, which any
wildcard covering it reaches, and the unknown-robot answerer ``<cell>/*/**``); the rest are held on
Zenoh's thread. ``<cell>/daemon``'s answer costs ~0.25 ms of loop time: 50 a second bound a flood
of ``**`` to ~1 % of the loop, while ``urdaemon list`` asks once. Exact keys are not counted (every
query on a robot's key reaches ``<cell>/*/**`` too): they are bounded in flight (``MAX_IN_FLIGHT``)."""


class Budget:
    """A token bucket shared by Zenoh's threads: ``take()`` is True at most ``rate`` times per second
    on average and ``burst`` times at once; ``dropped`` counts the False ones (thread-safe)."""

    __slots__ = ("_level", "_lock", "_then", "burst", "clock", "dropped", "rate")

    def __init__(self, rate: float, burst: float | None = None, clock: Callable[[], float] = time.monotonic):
        self.rate = rate
        self.burst = rate if burst is None else burst
        self.clock = clock
        """The time source (seconds); tests inject their own."""
        self.dropped = 0
        self._level = self.burst
        self._then = clock()
        self._lock = threading.Lock()

    def widen(self, burst: float) -> None:
        """Allow at least ``burst`` at once (and now)."""
        with self._lock:
            if burst > self.burst:
                self._level += burst - self.burst
                self.burst = burst

    def take(self) -> bool:
        """Spend one token if there is one."""
        with self._lock:
            now = self.clock()
            self._level = min(self.burst, self._level + (now - self._then) * self.rate)
            self._then = now
            if self._level >= 1.0:
                self._level -= 1.0
                return True
            self.dropped += 1
            return False


TARPIT_HOLD_S = 5.0
"""How long a query dropped past a budget is held unanswered before it ends (a client that waits for
each reply, as a ``get`` loop does, then asks at most once per hold instead of as fast as it can)."""
TARPIT_SIZE = 4096
"""Most queries held at once (a few KB each in Zenoh); past it the oldest ends at once."""


class Tarpit:
    """Queries dropped past a budget, held unanswered for ``hold_s`` (thread-safe).

    A flood that waits for its replies is slowed to one query per hold; one that does not fills the
    pit, whose oldest entries then end at once. Held queries end on ``hold`` calls after their time,
    and all of them on ``release``."""

    __slots__ = ("_held", "_lock", "clock", "hold_s", "size")

    def __init__(
        self,
        hold_s: float = TARPIT_HOLD_S,
        size: int = TARPIT_SIZE,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.hold_s = hold_s
        self.size = size
        self.clock = clock
        self._held: deque[tuple[float, Any]] = deque()
        self._lock = threading.Lock()

    def __len__(self) -> int:
        return len(self._held)

    def hold(self, query: Any) -> None:
        """Keep ``query`` unanswered; end the ones held long enough (or past ``size``)."""
        now = self.clock()
        ended = []
        with self._lock:
            held = self._held
            held.append((now + self.hold_s, query))
            while held and (held[0][0] <= now or len(held) > self.size):
                ended.append(held.popleft()[1])
        for old in ended:
            _end(old)

    def release(self) -> None:
        """End every held query (the node is closing)."""
        with self._lock:
            ended, self._held = [q for _, q in self._held], deque()
        for old in ended:
            _end(old)


def _end(query: Any) -> None:
    with contextlib.suppress(Exception):
        query.drop()


class Guard(Protocol):
    """What decides, on Zenoh's thread, whether a commanding message may reach the loop."""

    def refusal(self, attachment: bytes | None) -> str | None:
        """Why a message with this attachment is refused; None: it passes."""


def attachment_of(message: Any, limit: int = 64) -> bytes | None:
    """A query's or sample's attachment, or None; one longer than ``limit`` is never copied (it
    cannot be a token) and reads as an empty one."""
    attachment = message.attachment
    if attachment is None:
        return None
    if len(attachment) > limit:
        return b""
    return bytes(attachment.to_bytes())


class InFlight:
    """How many messages of one key are handed to the loop and not yet handled (thread-safe)."""

    __slots__ = ("_count", "_lock", "cap", "refused")

    def __init__(self, cap: int) -> None:
        self.cap = cap
        self.refused = 0
        """Messages refused because ``cap`` were in flight."""
        self._count = 0
        self._lock = threading.Lock()

    def enter(self) -> bool:
        """Count one more in flight (on Zenoh's thread); ``False``, and counted as refused, at the cap."""
        with self._lock:
            if self._count >= self.cap:
                self.refused += 1
                return False
            self._count += 1
            return True

    def leave(self) -> None:
        """One fewer in flight (on the loop, once handled, or if it never got there)."""
        with self._lock:
            self._count -= 1


class Latest:
    """A subscriber's newest sample not yet handled, and how many it replaced (thread-safe).

    At most one sample is pending on the loop per key; one arriving while another waits replaces it.
    """

    __slots__ = ("_lock", "_pending", "_replaced", "replaced_total")

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._pending: tuple[bytes, bytes | None] | None = None
        self._replaced = 0
        self.replaced_total = 0
        """Samples replaced by a newer one before the loop handled them, since the start."""

    def offer(self, payload: bytes, attachment: bytes | None = None) -> bool:
        """Keep ``payload`` (and the ``attachment`` it came with) as the newest (on Zenoh's thread);
        ``True`` if the loop must be told."""
        with self._lock:
            first = self._pending is None
            if not first:
                self._replaced += 1
                self.replaced_total += 1
            self._pending = (payload, attachment)
            return first

    def take(self) -> tuple[tuple[bytes, bytes | None] | None, int]:
        """The newest sample (payload, attachment) and how many it replaced since the last take (on
        the loop)."""
        with self._lock:
            pending, replaced = self._pending, self._replaced
            self._pending, self._replaced = None, 0
            return pending, replaced


def wildcard_refusal(asked: str, key: str) -> str:
    """Why a query or put on a key expression that only covers ``key`` did nothing."""
    return (
        f"{client_text(asked, 80)} is not {key}: services, goals and commands act on their exact key "
        f"only, never on a wildcard; ask {key}"
    )


def size_refusal(key: str, size: int, limit: int) -> str:
    """Why a message too large to read was refused."""
    return f"{key}: message of {size} bytes exceeds the limit of {limit} bytes for this key"


def busy_refusal(key: str) -> str:
    """Why a query was refused because too many on its key were waiting for the loop."""
    return f"busy: too many requests in flight on {key} (at most {MAX_IN_FLIGHT}); ask again"


def replaced_refusal(key: str, replaced: int) -> str:
    """Why samples put on a streaming key were never acted on."""
    return (
        f"busy: {replaced} sample(s) on {key} replaced by a newer one before the daemon read them "
        "(only the newest streaming command is acted on)"
    )


class Refusals:
    """Refusals of one subscriber waiting for the loop: the newest, and how many (thread-safe)."""

    __slots__ = ("_count", "_lock", "_newest")

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._newest: tuple[str, str] | None = None
        self._count = 0

    def offer(self, put_on: str, reason: str) -> bool:
        """Keep this refusal (on Zenoh's thread); ``True`` if the loop must be told."""
        with self._lock:
            first = self._newest is None
            self._newest = (put_on, reason)
            self._count += 1
            return first

    def take(self) -> tuple[str, str] | None:
        """The newest refusal, saying how many arrived since the last take (on the loop)."""
        with self._lock:
            newest, count = self._newest, self._count
            self._newest, self._count = None, 0
        if newest is None:
            return None
        put_on, reason = newest
        return put_on, reason if count == 1 else f"{reason} (and {count - 1} more refused like it)"


def refuse_query(query: Any, reason: str, *, answer: str, error: bool = False) -> None:
    """Answer ``query`` with ``{answer: false, "reason": reason}`` and end it: an error reply (no key,
    so it can never pass for a real answer) for a wildcard, else a normal reply on the query's key."""
    body = encode({answer: False, "reason": reason})
    with contextlib.suppress(Exception):  # the querier may have timed out and gone
        if error:
            query.reply_err(body)
        else:
            query.reply(query.key_expr, body)
    with contextlib.suppress(Exception):
        query.drop()
