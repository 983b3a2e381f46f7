"""What the flight recorder's tap sees: every message the daemon publishes, kept in memory until the
flight recorder's supervisor sends it to its process (runtime/flight_recorder.py).

With the cell file's ``record`` the daemon's node (publish/node.py) is made with a ``Tap``: each of
its publishers is a ``TappedPublisher``, whose ``put`` hands (key, payload) to the tap (one list
append: no copy, no clock, no parsing) and puts it on Zenoh only while a subscriber matches; the
node's one-off ``put`` (goal feedback and results) hands it to the tap too. Without ``record`` there
is no tap and the publishers are Zenoh's own.

``Matching`` is whether a publisher has subscribers, kept up to date by a Zenoh matching listener.
"""

from __future__ import annotations

from collections.abc import Callable, Collection
from typing import Any

__all__ = ["Matching", "Tap", "TappedPublisher"]

Tapped = tuple[str, bytes]
"""One published message: its key and payload."""


class Matching:
    """Whether a publisher has subscribers anywhere, kept up to date by a Zenoh matching listener.

    The 500 Hz streams read ``active`` to skip computing and encoding what nobody would receive
    (forward kinematics and JSON for ``tcp_pose``, the whole cell's link poses for ``tf``).
    """

    __slots__ = ("active",)

    def __init__(self, active: bool) -> None:
        self.active = active

    def update(self, status: Any) -> None:
        """The listener's callback (on a Zenoh thread: one attribute store, atomic under the GIL)."""
        self.active = bool(status.matching)


class Tap:
    """The messages published since the last ``take`` (on the loop's thread only).

    ``always``: the streams (a key's last chunk: ``joint_states``) computed for the tap even while no
    subscriber wants them (recording/channels.py ``RING_STREAMS``); every other stream that is
    computed only for subscribers (``tcp_pose``, ``tf``) reaches the tap only while one matches.
    """

    __slots__ = ("_always", "_items")

    def __init__(self, always: Collection[str] = ()) -> None:
        self._items: list[Tapped] = []
        self._always = frozenset(always)

    def always(self, key: str) -> bool:
        """Whether the stream on ``key`` is computed for the tap whoever subscribes."""
        return key.rpartition("/")[2] in self._always

    def add(self, key: str, payload: bytes) -> None:
        """Keep one published message (the hot path: one append)."""
        self._items.append((key, payload))

    def take(self) -> list[Tapped]:
        """Everything kept since the last take, oldest first; the tap starts a new list."""
        items, self._items = self._items, []
        return items


class TappedPublisher:
    """A Zenoh publisher whose every message also goes to the tap; Zenoh's ``put`` runs only while a
    subscriber matches (``wanted``: the publisher's own matching listener)."""

    __slots__ = ("_add", "_publisher", "key", "wanted")

    def __init__(self, key: str, publisher: Any, wanted: Matching, add: Callable[[str, bytes], None]) -> None:
        self.key = key
        self._publisher = publisher
        self.wanted = wanted
        """Whether a real subscriber matches (what the tap wants does not count)."""
        self._add = add

    def put(self, payload: bytes) -> None:
        """Publish ``payload`` to the subscribers, if any, and hand it to the tap."""
        if self.wanted.active:
            self._publisher.put(payload)
        self._add(self.key, payload)
