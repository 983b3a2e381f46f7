"""The daemon's Zenoh session: publishers, queryables and subscribers whose handlers run on the loop.

Zenoh calls back on its own threads; every callback here only copies what it needs and hands it
to the event loop with ``call_soon_threadsafe`` (measured: 5–15 µs more than the bare callback), so
all daemon logic runs on one thread and never races.

What is handed to the loop is bounded, so that no flood of messages, each within its size limit,
can fill the loop's queue ahead of the robots' cycles: each queryable has at most
``MAX_IN_FLIGHT`` queries handed over and not yet handled (the rest are refused, "busy", on Zenoh's
thread), and each subscriber at most one sample: a newer sample replaces the pending one (for a
streaming command only the newest matters) and the replaced ones are counted and reported. The
counters are the node's own, behind a small lock; no daemon state is touched off the loop.

A commanding queryable or subscriber has a guard (the robot's command lease): a message whose
attachment is not the lease holder's token is refused on Zenoh's thread too, after the wildcard and
size checks, so a flood of them never displaces the holder's messages, and again on the loop right
before its handler runs (with the attachment it arrived with), so a message that passed while its
sender held the lease does not act after the lease ended. The guard's check reads one immutable
object (runtime/lease.py). Lease holders' liveliness tokens are watched with ``liveliness_watch``:
only the keys the daemon asked about are kept (a holder's, an acquire's), every other token's
sample is dropped on Zenoh's thread, and the loop hears that a watched key changed.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any, Protocol

import zenoh

from urdaemon.cell.config import ZenohOptions
from urdaemon.errors import ConfigError, UrDaemonError
from urdaemon.publish.envelope import SMALL_MESSAGE_BYTES, client_text, encode
from urdaemon.publish.tap import Matching, Tap, TappedPublisher
from urdaemon.transport_security import configure_daemon

__all__ = [
    "MAX_IN_FLIGHT",
    "Guard",
    "LivelinessWatch",
    "Matching",
    "ZenohNode",
    "attachment_of",
    "busy_refusal",
    "declare_state_publisher",
    "serve_config",
    "size_refusal",
    "wildcard_refusal",
    "zenoh_config",
]

log = logging.getLogger(__name__)

MAX_IN_FLIGHT = 4
"""Most queries of one key handed to the loop and not yet handled. A client waits for each reply,
so a well-behaved one has one in flight per key, and only for the microseconds of the hand-over;
4 leaves room for a few clients at once, while a flood of messages at the size limit (~0.25 ms
of loop time each) can queue at most ~1 ms of work per key ahead of a robot's cycle."""


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


class _InFlight:
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

    def log_refusals(self, key: str) -> None:
        """Say so at the 1st, 10th, 100th, ... refusal: a flood logs a handful of lines, not one each."""
        refused = self.refused
        if refused > 0 and 10 ** (len(str(refused)) - 1) == refused:
            log.warning("%s: %d requests refused as too many in flight (a client floods it)", key, refused)


class _Latest:
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


def serve_config(options: ZenohOptions, listen: tuple[str, ...], cell: str | None = None) -> Any:
    """The daemon's session: the cell file's mode, endpoints, scouting and transport, without shared
    memory.

    Zenoh's shared memory moves a payload of 3 KiB or more to a peer on the same host through a
    16 MiB pool, mapped (and resident) from the first such message on: for the daemon, the first
    client asking for the URDF. Its messages are small JSON, so the pool bought nothing and cost a
    fifth of the process's memory; peers that use shared memory still connect, over the network
    transport (docs/performance.md, "The serve process"). ``cell``: the cell the access rules
    name (transport_security.py); without it they name any cell.

    A daemon in ``client`` mode listens nowhere (the cell file refuses ``listen`` there), so a
    ``listen`` given anyway (``urdaemon serve --listen``) is refused: ``ConfigError``.
    """
    if options.mode == "client" and listen:
        raise ConfigError(
            f"the cell's zenoh mode is 'client' (it dials {list(options.connect)}) and accepts no sessions; "
            f"cannot listen on {list(listen)} (leave out --listen, or use mode 'peer')"
        )
    conf = zenoh_config(
        options.mode,
        listen,
        options.connect,
        multicast=options.multicast_scouting,
        low_latency=options.low_latency,
    )
    conf.insert_json5("transport/shared_memory/enabled", "false")
    configure_daemon(conf, options, cell)
    return conf


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
        self._flights: dict[str, _InFlight] = {}
        self._asker: ThreadPoolExecutor | None = None
        """Sends liveliness queries off the loop (``liveliness_watch``)."""
        self.latest: dict[str, _Latest] = {}
        """Each subscriber's pending sample, by key (``replaced_total``: samples replaced unhandled)."""

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
            if guard is None:
                work = handler
            else:
                attachment = attachment_of(query)
                refusal = guard.refusal(attachment)
                if refusal is not None:
                    _refuse_query(query, refusal, error=False, answer=answer)
                    return
                work = _rechecked(guard, attachment, handler, answer)
            if not flight.enter():
                _refuse_query(query, busy_refusal(key), error=False, answer=answer)
                flight.log_refusals(key)
                return
            self._to_loop_counted(flight, work, query)

        flight = self._flight(key)
        self._entities.append(self.session.declare_queryable(key, on_query, complete=True))

    def in_flight(self, key: str) -> _InFlight:
        """The in-flight counter of a queryable declared on ``key`` (its ``refused`` count)."""
        return self._flights[key]

    def _flight(self, key: str) -> _InFlight:
        flight = self._flights[key] = _InFlight(MAX_IN_FLIGHT)
        return flight

    def cell_queryable(self, key: str, handler: Callable[[Any], None]) -> None:
        """Declare a queryable, not complete (other queryables answer within ``key`` too), whose
        ``handler(query)`` runs on the loop for every query; the handler decides whether to reply.
        Beyond ``MAX_IN_FLIGHT`` queries waiting for the loop, a query gets no answer from it."""

        def on_query(query: Any) -> None:
            if flight.enter():
                self._to_loop_counted(flight, handler, query)
            else:  # others may answer it; this one stays silent rather than queue without bound
                _drop(query)

        flight = self._flight(key)
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
        latest = _Latest()
        pending_refusals = _Refusals()
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

    def _to_loop_counted(self, flight: _InFlight, handler: Callable[[Any], None], query: Any) -> None:
        """Hand ``query`` to ``handler`` on the loop; it leaves ``flight`` once handled."""

        def handle() -> None:
            try:
                handler(query)
            finally:
                flight.leave()

        if not self._to_loop(handle):
            flight.leave()
            _drop(query)


class LivelinessWatch:
    """Whether the liveliness tokens of the keys the daemon asked about are present (thread-safe).

    Interest only: the daemon ``watch``es a key (a lease holder's, an acquire's) and ``unwatch``es it
    when done; a sample of any other key is dropped on Zenoh's thread, never stored nor handed to
    the loop, so the state kept is bounded by the keys asked about, whatever tokens others declare.
    A watched key is present, gone, or not heard of yet (a token declared before the key was
    watched: ``probe`` asks Zenoh for it). At most one "changed" call waits for the loop, however
    many watched tokens come and go meanwhile.
    """

    def __init__(self, notify: Callable[[], bool], ask: Callable[[str], None] | None = None) -> None:
        self._lock = threading.Lock()
        self._wanted: dict[str, int] = {}
        """Each watched key and how many of the daemon's parts watch it."""
        self._present: dict[str, bool] = {}
        """What was heard of each watched key (missing: nothing yet)."""
        self._notify = notify
        self._ask = ask
        self._pending = False
        self.changed: Callable[[], None] = lambda: None
        """Runs on the loop after a change (set by the node)."""
        self.ignored = 0
        """Samples of keys nobody watched, dropped (a count, nothing kept of them)."""

    @property
    def tracked(self) -> int:
        """How many keys the watch keeps state for (only those asked about)."""
        with self._lock:
            return len(self._wanted)

    def watch(self, key: str) -> None:
        """Keep what is heard of ``key`` from now on (until as many ``unwatch`` calls)."""
        with self._lock:
            self._wanted[key] = self._wanted.get(key, 0) + 1

    def unwatch(self, key: str) -> None:
        """One part of the daemon no longer cares about ``key``; the last forgets it."""
        with self._lock:
            count = self._wanted.get(key, 0) - 1
            if count > 0:
                self._wanted[key] = count
            else:
                self._wanted.pop(key, None)
                self._present.pop(key, None)

    def probe(self, key: str) -> None:
        """Ask Zenoh whether the token ``key`` (watched) is there already; the answer arrives off the
        loop, as a sample would (``heard``)."""
        if self._ask is not None:
            self._ask(key)

    def alive(self, key: str) -> bool:
        """Whether the watched token ``key`` is present."""
        with self._lock:
            return self._present.get(key, False)

    def on_sample(self, sample: Any) -> None:
        """A token came (PUT) or went (DELETE): on Zenoh's thread."""
        self._record(str(sample.key_expr), sample.kind != zenoh.SampleKind.DELETE, overwrite=True)

    def heard(self, key: str) -> None:
        """A liveliness query found the token ``key`` (on Zenoh's thread). It counts only if no sample
        of the key arrived since it was watched: a DELETE after the answer was made wins."""
        self._record(key, True, overwrite=False)

    def _record(self, key: str, present: bool, *, overwrite: bool) -> None:
        with self._lock:
            if key not in self._wanted:
                self.ignored += 1
                return
            if not overwrite and key in self._present:
                return
            self._present[key] = present
            notify, self._pending = not self._pending, True
        if notify and not self._notify():
            with self._lock:
                self._pending = False

    def handed(self) -> None:
        """On the loop: tell ``changed`` (changes arriving from now on ask for another call)."""
        with self._lock:
            self._pending = False
        self.changed()


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


class _Refusals:
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


def _latest_handler(
    key: str,
    latest: _Latest,
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
            _refuse_query(query, refusal, error=False, answer=answer)

    return handle


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
