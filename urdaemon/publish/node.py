"""The daemon's Zenoh session: publishers, queryables and subscribers whose handlers run on the loop.

Zenoh calls back on its own threads; every callback here only copies what it needs and hands it
to the event loop with ``call_soon_threadsafe`` (measured: 5–15 µs more than the bare callback), so
all daemon logic runs on one thread and never races.

What is handed to the loop is bounded, so that no flood of messages, each within its size limit,
can fill the loop's queue ahead of the robots' cycles: each queryable has at most
``MAX_IN_FLIGHT`` queries handed over and not yet handled (the rest are refused, "busy", on Zenoh's
thread), and each subscriber at most one sample: a newer sample replaces the pending one (for a
streaming command only the newest matters) and the replaced ones are counted and reported. What
Zenoh's threads do in Python for wildcard queries is bounded too, per second: Zenoh calls every
queryable a wildcard covers (~50 for ``**``), each holding the GIL the loop needs, so the node
builds a bounded number of wildcard error replies (``wildcards``) and each cell queryable hands a
bounded number to the loop (``cell_queries``); a query past a budget is held unanswered a while
(``tarpit``), so a client flooding in a loop waits. The counters are the node's own, behind a small
lock (admission.py); no daemon state is touched off the loop.

A commanding queryable or subscriber has a guard (the robot's command lease): a message whose
attachment is not the lease holder's token is refused on Zenoh's thread too, after the wildcard and
size checks, so a flood of them never displaces the holder's messages, and again on the loop right
before its handler runs (with the attachment it arrived with), so a message that passed while its
sender held the lease does not act after the lease ended. The guard's check reads one immutable
object (runtime/lease.py). Lease holders' liveliness tokens are watched with ``liveliness_watch``
(liveliness.py): only the keys the daemon asked about are kept (a holder's, an acquire's), every other
token's sample is dropped on Zenoh's thread, and the loop hears that a watched key changed. The
session's config, TLS and access control included, is session_config.py's.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import zenoh

from urdaemon.cell.zenoh_options import ZenohOptions
from urdaemon.errors import UrDaemonError
from urdaemon.publish.admission import (
    CELL_QUERIES_PER_S,
    MAX_IN_FLIGHT,
    WILDCARD_REPLIES_AT_ONCE,
    WILDCARD_REPLIES_PER_S,
    Budget,
    Guard,
    InFlight,
    Latest,
    Refusals,
    Tarpit,
    attachment_of,
    busy_refusal,
    refuse_query,
    replaced_refusal,
    size_refusal,
    wildcard_refusal,
)
from urdaemon.publish.envelope import SMALL_MESSAGE_BYTES, client_text
from urdaemon.publish.liveliness import LivelinessWatch
from urdaemon.publish.session_config import serve_config
from urdaemon.publish.tap import Matching, Tap, TappedPublisher

__all__ = ["ZenohNode", "declare_state_publisher"]

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


class ZenohNode:
    """One Zenoh session owned by the daemon; every declared entity is undeclared on ``close``."""

    def __init__(
        self,
        options: ZenohOptions,
        loop: asyncio.AbstractEventLoop,
        *,
        listen: tuple[str, ...] | None = None,
        cell: str | None = None,
        tap: Tap | None = None,
    ) -> None:
        self._loop = loop
        self.tap = tap
        """The flight recorder's tap (cell file ``record``): every message published goes to it too
        (publish/tap.py); None: publishers are Zenoh's own."""
        endpoints = options.listen if listen is None else listen
        try:
            self.session: Any = zenoh.open(serve_config(options, endpoints, cell))
        except zenoh.ZError as err:
            raise UrDaemonError(f"cannot open Zenoh session (listen {list(endpoints)}): {err}") from err
        self._entities: list[Any] = []
        self._closed = False
        self._asker: ThreadPoolExecutor | None = None
        """Sends liveliness queries off the loop (``liveliness_watch``)."""
        self.latest: dict[str, Latest] = {}
        """Each subscriber's pending sample, by key (``replaced_total``: samples replaced unhandled)."""
        self.wildcards = Budget(WILDCARD_REPLIES_PER_S, WILDCARD_REPLIES_AT_ONCE)
        """The error replies to wildcard queries, every queryable's together: a flood of ``**`` or of
        ``<cell>/alice/**`` costs every robot's loop a bounded share of the GIL (admission.py)."""
        self._queryables = 0
        self.cell_queries: dict[str, Budget] = {}
        self.tarpit = Tarpit()
        """Queries dropped past a budget, held unanswered a while: a ``get`` loop that floods slows to
        one query per hold (admission.py)."""
        """Each cell queryable's queries handed to the loop, by key."""

    def publisher(self, key: str, *, realtime: bool = False) -> Any:
        """Declare a publisher; ``realtime`` for state streams (express, top priority).

        Every publisher drops a sample rather than block when the network is congested: a stalled
        subscriber must never stall the event loop, which clocks every robot. What must not be lost
        (goal results) can also be asked for with a query.

        With the flight recorder's tap, a ``TappedPublisher``: every message goes to the tap, and
        to Zenoh only while a subscriber matches.
        """
        if realtime:
            pub = declare_state_publisher(self.session, key)
        else:
            pub = self.session.declare_publisher(key, congestion_control=zenoh.CongestionControl.DROP)
        self._entities.append(pub)
        if self.tap is None:
            return pub
        return TappedPublisher(key, pub, self._listen(pub), self.tap.add)

    def matching(self, publisher: Any) -> Matching:
        """A :class:`Matching` for ``publisher`` (undeclared with everything else on ``close``).

        With the flight recorder's tap, a stream the tap wants always (``Tap.always``: joint_states)
        is always active, so it is computed every cycle for the ring; any other (tcp_pose, tf:
        derived from joint_states and the URDF, at the cost of forward kinematics) says only
        whether a real subscriber matches.
        """
        if isinstance(publisher, TappedPublisher):
            assert self.tap is not None, "a tapped publisher comes from a node with a tap"
            return Matching(True) if self.tap.always(publisher.key) else publisher.wanted
        return self._listen(publisher)

    def _listen(self, publisher: Any) -> Matching:
        flag = Matching(bool(publisher.matching_status.matching))
        self._entities.append(publisher.declare_matching_listener(flag.update))
        # a subscriber may have appeared between the first read and the listener's declaration
        flag.active = flag.active or bool(publisher.matching_status.matching)
        return flag

    def put(self, key: str, payload: bytes, *, attachment: bytes | None = None) -> None:
        """Publish once on ``key``, with ``attachment`` if given (a goal message's signature),
        dropped rather than blocking when congested; the tap, if any, gets it too."""
        if self.tap is not None:
            self.tap.add(key, payload)
        if not self._closed:
            self.session.put(
                key, payload, attachment=attachment, congestion_control=zenoh.CongestionControl.DROP
            )

    def queryable(
        self,
        key: str,
        handler: Callable[[Any], None],
        *,
        max_bytes: int | None = SMALL_MESSAGE_BYTES,
        answer: str = "ok",
        any_id: bool = False,
        guard: Guard | None = None,
    ) -> None:
        """Declare a queryable whose ``handler(query)`` runs on the loop; it must reply.

        Only a query on exactly ``key`` reaches the handler: one whose key expression merely
        intersects it (``<cell>/**``, ``**``, ``<cell>/*/goal/move``) is answered with an error reply
        naming the key to ask, on Zenoh's thread, and never acts. With ``any_id`` (a key with one
        ``*`` chunk, the goal results) any concrete key matching it is handled and a wildcard query is
        not answered. A payload larger than ``max_bytes`` is refused before anyone reads it, with
        ``{answer: false, "reason": ...}``, and so is a query arriving while ``MAX_IN_FLIGHT`` of
        this key's queries wait for the loop ("busy: too many requests in flight on <key>"). With a
        ``guard``, a query it refuses (one without the lease holder's token) is answered
        ``{answer: false, "reason": ...}`` there too, and again on the loop right before the handler
        (the lease may have ended while the query waited).
        """

        def on_query(query: Any) -> None:
            asked = str(query.key_expr)
            if asked != key and (not any_id or "*" in asked):
                if any_id:  # a goal's result answers a concrete id only
                    _drop(query)
                elif wildcards.take():
                    refuse_query(query, wildcard_refusal(asked, key), error=True, answer=answer)
                else:  # past the budget: no reply, and held a while (a flood slows down)
                    self.tarpit.hold(query)
                    _log_dropped(wildcards, "wildcard queries")
                return
            payload = query.payload
            size = 0 if payload is None else len(payload)
            if max_bytes is not None and size > max_bytes:
                refuse_query(query, size_refusal(key, size, max_bytes), error=False, answer=answer)
                return
            if guard is None:
                work = handler
            else:
                attachment = attachment_of(query)
                refusal = guard.refusal(attachment)
                if refusal is not None:
                    refuse_query(query, refusal, error=False, answer=answer)
                    return
                work = _rechecked(guard, attachment, handler, answer)
            if not flight.enter():
                refuse_query(query, busy_refusal(key), error=False, answer=answer)
                _log_refusals(flight, key)
                return
            self._to_loop_counted(flight, work, query)

        flight = InFlight(MAX_IN_FLIGHT)  # this key's messages waiting for the loop
        wildcards = self.wildcards
        self._queryables += 1
        wildcards.widen(self._queryables)  # one ``**`` is answered by every queryable, whole
        self._entities.append(self.session.declare_queryable(key, on_query, complete=True))

    def cell_queryable(self, key: str, handler: Callable[[Any], None]) -> None:
        """Declare a queryable, not complete (other queryables answer within ``key`` too), whose
        ``handler(query)`` runs on the loop for every query; the handler decides whether to reply.
        Beyond ``MAX_IN_FLIGHT`` queries waiting for the loop, or ``CELL_QUERIES_PER_S`` wildcard
        queries a second, a query gets no answer from it."""

        def on_query(query: Any) -> None:
            # a wildcard past the budget: no answer from here, held a while (a flood slows down); an
            # exact key (every robot key's query reaches ``<cell>/*/**`` too) is bounded in flight only
            if "*" in str(query.key_expr) and not budget.take():
                self.tarpit.hold(query)
                _log_dropped(budget, f"wildcard queries on {key}")
            elif flight.enter():
                self._to_loop_counted(flight, handler, query)
            else:  # others may answer it; this one stays silent rather than queue without bound
                _drop(query)

        flight = InFlight(MAX_IN_FLIGHT)
        budget = self.cell_queries[key] = Budget(CELL_QUERIES_PER_S)
        self._entities.append(self.session.declare_queryable(key, on_query, complete=False))

    def subscriber(
        self,
        key: str,
        handler: Callable[[str, bytes], None],
        *,
        max_bytes: int = SMALL_MESSAGE_BYTES,
        refused: Callable[[str, str], None] | None = None,
        guard: Guard | None = None,
    ) -> None:
        """Declare a subscriber whose ``handler(key, payload)`` runs on the loop.

        Only a sample put on exactly ``key`` is handled: a put on a wildcard expression that covers
        it (``<cell>/*/command/joint_position``) never acts. Such a sample, or one larger than
        ``max_bytes``, or one the ``guard`` refuses (not the lease holder's), is not copied;
        ``refused(key expression, reason)`` hears of it on the loop. The guard checks a sample's
        attachment again on the loop before ``handler``: one sent while the lease was its sender's
        does not act after the lease ended.

        Only the newest sample is handled: one that arrives while another still waits for the
        loop replaces it, and ``refused`` hears how many were replaced along with the newest.
        Refusals are bounded the same way: at most one report waits for the loop, counting the
        refusals that arrived meanwhile.
        """
        latest = Latest()
        pending_refusals = Refusals()
        handle_latest = _latest_handler(key, latest, handler, refused, guard)

        def report_refusals() -> None:
            taken = pending_refusals.take()
            if taken is not None and refused is not None:
                refused(*taken)

        def on_sample(sample: Any) -> None:
            put_on = str(sample.key_expr)
            size = len(sample.payload)
            if put_on != key:
                reason = wildcard_refusal(put_on, key)
            elif size > max_bytes:
                reason = size_refusal(key, size, max_bytes)
            else:
                attachment = None if guard is None else attachment_of(sample)
                refusal = None if guard is None else guard.refusal(attachment)
                if refusal is None:
                    if latest.offer(sample.payload.to_bytes(), attachment):
                        self._to_loop(handle_latest)
                    return
                reason = refusal
            if refused is not None and pending_refusals.offer(client_text(put_on, 80), reason):
                self._to_loop(report_refusals)

        self.latest[key] = latest
        self._entities.append(self.session.declare_subscriber(key, on_sample))

    def liveliness_token(self, key: str) -> None:
        """Declare a liveliness token held until ``close``."""
        self._entities.append(self.session.liveliness().declare_token(key))

    def liveliness_watch(self, key: str, changed: Callable[[], None], timeout: float) -> LivelinessWatch:
        """Watch the liveliness tokens under ``key`` that the daemon asks about (one subscriber for
        all); ``changed()`` runs on the loop after a watched token came or went, at most one call
        waiting for the loop at a time. ``timeout``: how long a ``probe`` waits for Zenoh's answer.

        A probe is sent off the loop, by one thread of its own (started at the first probe), and
        answered on Zenoh's threads: the loop neither sends it nor waits for it."""

        def ask(token: str) -> None:
            if self._closed:
                return
            if self._asker is None:
                self._asker = ThreadPoolExecutor(1, thread_name_prefix="urdaemon-liveliness")
            with contextlib.suppress(RuntimeError):  # shut down: the daemon is closing
                self._asker.submit(self._ask_liveliness, token, watch.heard, timeout)

        watch = LivelinessWatch(lambda: self._to_loop(watch.handed), ask)
        watch.changed = changed
        subscriber = self.session.liveliness().declare_subscriber(key, watch.on_sample)
        self._entities.append(subscriber)
        return watch

    def _ask_liveliness(self, token: str, heard: Callable[[str], None], timeout: float) -> None:
        """Ask Zenoh whether the liveliness token ``token`` is there (on the asker's thread);
        ``heard(token)`` on Zenoh's thread if it is."""

        def on_reply(reply: Any) -> None:
            found = reply.ok
            if found is not None and str(found.key_expr) == token:
                heard(token)

        if self._closed:
            return
        try:
            self.session.liveliness().get(token, zenoh.handlers.Callback(on_reply), timeout=timeout)
        except zenoh.ZError as err:
            log.warning("liveliness query of %s failed: %s", token, err)

    def close(self) -> None:
        """Undeclare everything and close the session."""
        if self._closed:
            return
        self._closed = True
        if self._asker is not None:
            self._asker.shutdown(wait=False, cancel_futures=True)
        self.tarpit.release()
        for entity in reversed(self._entities):
            try:
                entity.undeclare()
            except Exception as err:  # a session already half closed must not stop the shutdown
                log.debug("undeclare failed: %s", err)
        self._entities.clear()
        self.session.close()

    def _to_loop(self, handler: Callable[..., None], *args: Any) -> bool:
        if self._closed:
            return False
        try:
            self._loop.call_soon_threadsafe(handler, *args)
        except RuntimeError:  # the loop closed while Zenoh was delivering
            return False
        return True

    def _to_loop_counted(self, flight: InFlight, handler: Callable[[Any], None], query: Any) -> None:
        """Hand ``query`` to ``handler`` on the loop; it leaves ``flight`` once handled."""

        def handle() -> None:
            try:
                handler(query)
            finally:
                flight.leave()

        if not self._to_loop(handle):
            flight.leave()
            _drop(query)


def _log_refusals(flight: InFlight, key: str) -> None:
    """Say so at the 1st, 10th, 100th, ... refusal: a flood logs a handful of lines, not one each."""
    refused = flight.refused
    if refused > 0 and 10 ** (len(str(refused)) - 1) == refused:
        log.warning("%s: %d requests refused as too many in flight (a client floods it)", key, refused)


def _log_dropped(budget: Budget, what: str) -> None:
    """Say so at the 1st, 10th, 100th, ... query dropped past a budget (from Zenoh's thread)."""
    dropped = budget.dropped
    if dropped > 0 and 10 ** (len(str(dropped)) - 1) == dropped:
        log.warning(
            "%d %s dropped unanswered, more than %g a second (a client floods them)",
            dropped,
            what,
            budget.rate,
        )


def _latest_handler(
    key: str,
    latest: Latest,
    handler: Callable[[str, bytes], None],
    refused: Callable[[str, str], None] | None,
    guard: Guard | None,
) -> Callable[[], None]:
    """What runs on the loop for a subscriber's pending sample: report the samples it replaced, check
    the ``guard`` again (the lease may have ended since Zenoh's thread let it pass), then hand it on."""

    def handle_latest() -> None:
        pending, replaced = latest.take()
        if replaced and refused is not None:
            refused(key, replaced_refusal(key, replaced))
        if pending is None:
            return
        payload, attachment = pending
        refusal = None if guard is None else guard.refusal(attachment)
        if refusal is None:
            handler(key, payload)
        elif refused is not None:
            refused(key, refusal)

    return handle_latest


def _rechecked(
    guard: Guard, attachment: bytes | None, handler: Callable[[Any], None], answer: str
) -> Callable[[Any], None]:
    """``handler``, run only if ``guard`` still lets ``attachment`` pass on the loop: the lease may
    have ended (released, taken over, its holder gone) while the query waited for the loop."""

    def handle(query: Any) -> None:
        refusal = guard.refusal(attachment)
        if refusal is None:
            handler(query)
        else:
            refuse_query(query, refusal, error=False, answer=answer)

    return handle


def _drop(query: Any) -> None:
    with contextlib.suppress(Exception):
        query.drop()
