"""The daemon's Zenoh session: publishers, queryables and subscribers whose handlers run on the loop.

Zenoh calls back on its own threads; every callback here only copies what it needs and hands it
to the event loop with ``call_soon_threadsafe`` (measured: 5–15 µs more than the bare callback), so
all daemon logic runs on one thread and never races.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
from collections.abc import Callable
from typing import Any

import zenoh

from urdaemon.cell.config import ZenohOptions
from urdaemon.errors import UrDaemonError
from urdaemon.publish.codec import SMALL_MESSAGE_BYTES, client_text, encode

__all__ = [
    "Matching",
    "ZenohNode",
    "declare_state_publisher",
    "size_refusal",
    "wildcard_refusal",
    "zenoh_config",
]

log = logging.getLogger(__name__)


def declare_state_publisher(session: Any, key: str) -> Any:
    """A publisher with the state streams' settings: express (no batching), real-time priority, and
    a sample dropped rather than the caller blocked when the network is congested."""
    return session.declare_publisher(
        key,
        congestion_control=zenoh.CongestionControl.DROP,
        priority=zenoh.Priority.REAL_TIME,
        express=True,
    )


def zenoh_config(
    mode: str,
    listen: tuple[str, ...] | list[str],
    connect: tuple[str, ...] | list[str],
    *,
    multicast: bool = False,
    low_latency: bool = False,
) -> Any:
    """A ``zenoh.Config`` with explicit endpoints, multicast scouting and the low-latency transport
    (which needs QoS off) as given."""
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps(mode))
    conf.insert_json5("listen/endpoints", json.dumps(list(listen)))
    conf.insert_json5("connect/endpoints", json.dumps(list(connect)))
    conf.insert_json5("scouting/multicast/enabled", json.dumps(multicast))
    if low_latency:
        conf.insert_json5("transport/unicast/lowlatency", "true")
        conf.insert_json5("transport/unicast/qos/enabled", "false")
    return conf


class Matching:
    """Whether a publisher has subscribers anywhere, kept up to date by a Zenoh matching listener.

    The 500 Hz streams read ``active`` to skip computing and encoding what nobody would receive
    (forward kinematics and JSON for ``tcp_pose``, the whole cell's link poses for ``tf``).
    """

    def __init__(self, active: bool) -> None:
        self.active = active

    def update(self, status: Any) -> None:
        """The listener's callback (on a Zenoh thread: one attribute store, atomic under the GIL)."""
        self.active = bool(status.matching)


class ZenohNode:
    """One Zenoh session owned by the daemon; every declared entity is undeclared on ``close``."""

    def __init__(
        self, options: ZenohOptions, loop: asyncio.AbstractEventLoop, *, listen: tuple[str, ...] | None = None
    ) -> None:
        self._loop = loop
        endpoints = options.listen if listen is None else listen
        try:
            self.session: Any = zenoh.open(
                zenoh_config(
                    options.mode,
                    endpoints,
                    options.connect,
                    multicast=options.multicast_scouting,
                    low_latency=options.low_latency,
                )
            )
        except zenoh.ZError as err:
            raise UrDaemonError(f"cannot open Zenoh session (listen {list(endpoints)}): {err}") from err
        self._entities: list[Any] = []
        self._closed = False

    def publisher(self, key: str, *, realtime: bool = False) -> Any:
        """Declare a publisher; ``realtime`` for state streams (express, top priority).

        Every publisher drops a sample rather than block when the network is congested: a stalled
        subscriber must never stall the event loop, which clocks every robot. What must not be lost
        (goal results) can also be asked for with a query.
        """
        if realtime:
            pub = declare_state_publisher(self.session, key)
        else:
            pub = self.session.declare_publisher(key, congestion_control=zenoh.CongestionControl.DROP)
        self._entities.append(pub)
        return pub

    def matching(self, publisher: Any) -> Matching:
        """A :class:`Matching` for ``publisher`` (undeclared with everything else on ``close``)."""
        flag = Matching(bool(publisher.matching_status.matching))
        self._entities.append(publisher.declare_matching_listener(flag.update))
        # a subscriber may have appeared between the first read and the listener's declaration
        flag.active = flag.active or bool(publisher.matching_status.matching)
        return flag

    def put(self, key: str, payload: bytes) -> None:
        """Publish once on ``key`` (dropped rather than blocking when congested)."""
        if not self._closed:
            self.session.put(key, payload, congestion_control=zenoh.CongestionControl.DROP)

    def queryable(
        self,
        key: str,
        handler: Callable[[Any], None],
        *,
        max_bytes: int | None = SMALL_MESSAGE_BYTES,
        answer: str = "ok",
        any_id: bool = False,
    ) -> None:
        """Declare a queryable whose ``handler(query)`` runs on the loop; it must reply.

        Only a query on exactly ``key`` reaches the handler: one whose key expression merely
        intersects it (``<cell>/**``, ``**``, ``<cell>/*/goal/move``) is answered with an error reply
        naming the key to ask, on Zenoh's thread, and never acts. With ``any_id`` (a key with one
        ``*`` chunk, the goal results) any concrete key matching it is handled and a wildcard query is
        not answered. A payload larger than ``max_bytes`` is refused before anyone reads it, with
        ``{answer: false, "reason": ...}``.
        """

        def on_query(query: Any) -> None:
            asked = str(query.key_expr)
            if asked != key and (not any_id or "*" in asked):
                if not any_id:
                    _refuse_query(query, wildcard_refusal(asked, key), error=True, answer=answer)
                else:
                    _drop(query)
                return
            payload = query.payload
            size = 0 if payload is None else len(payload)
            if max_bytes is not None and size > max_bytes:
                _refuse_query(query, size_refusal(key, size, max_bytes), error=False, answer=answer)
                return
            self._to_loop(handler, query)

        self._entities.append(self.session.declare_queryable(key, on_query, complete=True))

    def cell_queryable(self, key: str, handler: Callable[[Any], None]) -> None:
        """Declare a queryable, not complete (other queryables answer within ``key`` too), whose
        ``handler(query)`` runs on the loop for every query; the handler decides whether to reply."""

        def on_query(query: Any) -> None:
            self._to_loop(handler, query)

        self._entities.append(self.session.declare_queryable(key, on_query, complete=False))

    def subscriber(
        self,
        key: str,
        handler: Callable[[str, bytes], None],
        *,
        max_bytes: int = SMALL_MESSAGE_BYTES,
        refused: Callable[[str, str], None] | None = None,
    ) -> None:
        """Declare a subscriber whose ``handler(key, payload)`` runs on the loop.

        Only a sample put on exactly ``key`` is handled: a put on a wildcard expression that covers
        it (``<cell>/*/command/joint_position``) never acts. Such a sample, or one larger than
        ``max_bytes``, is not copied; ``refused(key expression, reason)`` hears of it on the loop.
        """

        def on_sample(sample: Any) -> None:
            put_on = str(sample.key_expr)
            size = len(sample.payload)
            if put_on != key:
                reason = wildcard_refusal(put_on, key)
            elif size > max_bytes:
                reason = size_refusal(key, size, max_bytes)
            else:
                self._to_loop(handler, put_on, sample.payload.to_bytes())
                return
            if refused is not None:
                self._to_loop(refused, client_text(put_on, 80), reason)

        self._entities.append(self.session.declare_subscriber(key, on_sample))

    def liveliness_token(self, key: str) -> None:
        """Declare a liveliness token held until ``close``."""
        self._entities.append(self.session.liveliness().declare_token(key))

    def close(self) -> None:
        """Undeclare everything and close the session."""
        if self._closed:
            return
        self._closed = True
        for entity in reversed(self._entities):
            try:
                entity.undeclare()
            except Exception as err:  # a session already half closed must not stop the shutdown
                log.debug("undeclare failed: %s", err)
        self._entities.clear()
        self.session.close()

    def _to_loop(self, handler: Callable[..., None], *args: Any) -> None:
        if self._closed:
            return
        with contextlib.suppress(RuntimeError):  # the loop closed while Zenoh was delivering
            self._loop.call_soon_threadsafe(handler, *args)


def wildcard_refusal(asked: str, key: str) -> str:
    """Why a query or put on a key expression that only covers ``key`` did nothing."""
    return (
        f"{client_text(asked, 80)} is not {key}: services, goals and commands act on their exact key "
        f"only, never on a wildcard; ask {key}"
    )


def size_refusal(key: str, size: int, limit: int) -> str:
    """Why a message too large to read was refused."""
    return f"{key}: message of {size} bytes exceeds the limit of {limit} bytes for this key"


def _refuse_query(query: Any, reason: str, *, error: bool, answer: str) -> None:
    """Answer ``query`` with a refusal on Zenoh's thread: an error reply (no key, so it can never
    pass for a real answer) for a wildcard, else a normal reply on the query's key."""
    body = encode({answer: False, "reason": reason})
    with contextlib.suppress(Exception):  # the querier may have timed out and gone
        if error:
            query.reply_err(body)
        else:
            query.reply(query.key_expr, body)
    _drop(query)


def _drop(query: Any) -> None:
    with contextlib.suppress(Exception):
        query.drop()
