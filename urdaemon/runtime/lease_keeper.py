"""One robot's command lease served: its queryable, the wait for an acquirer's liveliness token, and
what follows a lease's end (the robot stops, an event, a log line). The decisions are the book's
(runtime/lease.py); the cell's one watch of lease tokens tells every robot's keeper
(``watch_lease_holders``, called once by the daemon).

The watch keeps only the keys a keeper asks about: the holder's token (its going ends the lease)
and the tokens of acquires waiting (their coming grants). An acquire watches its key, asks Zenoh
whether the token is there already (answered off the loop) and waits, in a task of its own (at
most ``MAX_WAITING`` at once), for either answer or a sample; it never holds up the loop nor
another request.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable, Iterable
from typing import Any, Protocol

from urdaemon.cell.config import Cell
from urdaemon.errors import MessageError
from urdaemon.publish.admission import attachment_of
from urdaemon.publish.endpoints import ROBOT, Endpoint
from urdaemon.publish.keys import CellKeys, RobotKeys
from urdaemon.publish.lease_request import LeaseRequest, parse_request
from urdaemon.publish.liveliness import LivelinessWatch
from urdaemon.publish.node import ZenohNode
from urdaemon.runtime.lease import LEASE_BIND_TIMEOUT_S, LeaseBook, LeaseOutcome
from urdaemon.runtime.motion import How, RobotMotion
from urdaemon.runtime.queries import SHUTTING_DOWN, Requests, payload, reply
from urdaemon.runtime.status import StatusPublisher

__all__ = ["MAX_WAITING", "LeaseKeeper", "watch_lease_holders"]

LEASE_PROBE_EVERY_S = 0.25
"""How often an acquire that waits for its holder's token asks Zenoh for it again."""
MAX_WAITING = 8
"""Most acquires of one robot waiting for their liveliness token at once: a newer one takes the place
of the oldest, which is refused ("busy: ... gave way"), so acquires whose token never comes cannot
keep a free lease from everyone else (a present token is found by the first probe, in a moment)."""


class _Waiter:
    """An acquire waiting for its liveliness token: set when it appears, or when it gives way."""

    __slots__ = ("event", "gave_way", "session")

    def __init__(self, session: str) -> None:
        self.session = session
        self.event = asyncio.Event()
        self.gave_way = False


class LeaseKeeper:
    """Serves one robot's lease queryable and acts on the book's decisions."""

    def __init__(
        self,
        *,
        keys: RobotKeys,
        book: LeaseBook,
        motion: RobotMotion,
        requests: Requests,
        status: StatusPublisher,
        log: logging.LoggerAdapter[logging.Logger],
    ) -> None:
        self.book = book
        self._keys = keys
        self._motion = motion
        self._requests = requests
        self._status = status
        self._log = log
        self._watch: LivelinessWatch | None = None
        self._waiting: list[_Waiter] = []
        """The acquires waiting for their token, oldest first."""
        self._holder_key: str | None = None
        """The holder's token key, watched while it holds the lease."""

    def endpoints(self) -> dict[Endpoint, Callable[[Any], None]]:
        """The rows of the endpoint table this part answers (the lease, which needs no lease itself)."""
        return {ROBOT.lease: self.on_query}

    @property
    def watch(self) -> LivelinessWatch | None:
        """The cell's watch of lease tokens (None until attached)."""
        return self._watch

    def attach(self, watch: LivelinessWatch) -> None:
        """Read the holders' tokens from ``watch`` from now on."""
        self._watch = watch
        self._follow_holder()
        self.tokens_changed()

    def tokens_changed(self) -> None:
        """Tokens came or went (on the loop): the holder's gone ends the lease; waiters go on."""
        lease = self.book.lease
        if lease is not None and not self._alive(lease.session):
            outcome = self.book.gone(lease.session)
            if outcome is not None:
                self._act(outcome)
        for waiter in self._waiting:
            if self._alive(waiter.session):
                waiter.event.set()

    def _alive(self, session: str) -> bool:
        return self._watch is not None and self._watch.alive(self._keys.lease_holder(session))

    def _follow_holder(self) -> None:
        """Watch the holder's token key (the new one before the old is let go: no gap)."""
        lease, watch = self.book.lease, self._watch
        key = None if lease is None else self._keys.lease_holder(lease.session)
        if watch is None or key == self._holder_key:
            return
        if key is not None:
            watch.watch(key)
        if self._holder_key is not None:
            watch.unwatch(self._holder_key)
        self._holder_key = key

    def on_query(self, query: Any) -> None:
        """A lease request: show, acquire (perhaps after waiting for its token) or release."""
        try:
            request = parse_request(payload(query))
        except MessageError as err:
            reply(query, {"ok": False, "reason": str(err)})
            return
        if request.action == "show":
            reply(query, self.book.show())
        elif request.action == "release":
            outcome = self.book.release(attachment_of(query))
            self._act(outcome)
            reply(query, outcome.reply)
        else:
            self._acquire(query, request)

    def _acquire(self, query: Any, request: LeaseRequest) -> None:
        if self._watch is not None:  # a holder whose token is gone holds nothing (its change may wait)
            self.tokens_changed()
        refused = self.book.refused_now(request)
        if refused is not None:
            reply(query, refused.reply)
        elif self._alive(request.session):
            self._grant(query, request)
        else:
            if len(self._waiting) >= MAX_WAITING:  # the oldest gives way: a flood cannot hold the slots
                oldest = self._waiting.pop(0)
                oldest.gave_way = True
                oldest.event.set()
            work = self._wait_then_grant(query, request)
            self._requests.spawn(work, query, {"ok": False, "reason": SHUTTING_DOWN})

    async def _wait_then_grant(self, query: Any, request: LeaseRequest) -> None:
        key = self._keys.lease_holder(request.session)
        waiter = _Waiter(request.session)
        self._waiting.append(waiter)
        watch = self._watch
        if watch is not None:
            watch.watch(key)  # before asking: a sample arriving meanwhile is kept
            watch.probe(key)
        try:
            try:
                await self._token_heard(waiter.event, key)
            finally:
                if waiter in self._waiting:
                    self._waiting.remove(waiter)
            if waiter.gave_way and not self._alive(request.session):
                reply(query, {"ok": False, "reason": _gave_way(self._keys.robot)})
                return
            self._grant(query, request)  # a grant watches the key as the holder's before this lets go
        finally:
            if watch is not None:
                watch.unwatch(key)

    async def _token_heard(self, event: asyncio.Event, key: str) -> None:
        """Wait up to ``LEASE_BIND_TIMEOUT_S`` for the token ``key``, asking Zenoh again every
        ``LEASE_PROBE_EVERY_S``: through a Zenoh router a liveliness query can miss a token declared
        a moment before (its sample came before the key was watched, and was not kept)."""
        for _ in range(round(LEASE_BIND_TIMEOUT_S / LEASE_PROBE_EVERY_S)):
            try:
                await asyncio.wait_for(event.wait(), LEASE_PROBE_EVERY_S)
                return
            except TimeoutError:
                if self._watch is not None:
                    self._watch.probe(key)

    def _grant(self, query: Any, request: LeaseRequest) -> None:
        if not self._alive(request.session):
            token = self._keys.lease_holder(request.session)
            reply(
                query,
                {
                    "ok": False,
                    "reason": (
                        f"lease: no liveliness token {token} within {LEASE_BIND_TIMEOUT_S:g} s: declare it "
                        "on the session that acquires, before acquiring, and keep it while holding the lease"
                    ),
                },
            )
            return
        outcome = self.book.acquire(request, time.time())
        self._act(outcome)
        reply(query, outcome.reply)

    def _act(self, outcome: LeaseOutcome) -> None:
        """Do what a decision says: stop first, then log and tell."""
        if outcome.stop is not None:  # stop whatever moves the robot, as ``stop`` does, and end
            # freedrive (nobody may keep it on now)
            self._motion.end(outcome.stop, How.STOP, end_freedrive=True)
        event = outcome.event
        shown = "" if event is None else f" (lease {event['fingerprint']})"  # never the session id
        if outcome.warning is not None:
            self._log.warning("%s%s", outcome.warning, shown)
        self._follow_holder()
        if event is not None:
            lease = self.book.lease
            self._status.lease = None if lease is None else lease.body()
            if outcome.warning is None:
                self._log.info("lease %s: %s%s", event["action"], event["holder"], shown)
            self._status.event(event)
            self._status.publish()


def _gave_way(robot: str) -> str:
    """Why an acquire that waited for its token gave way to a newer one."""
    return (
        f"busy: lease of robot {robot!r}: {MAX_WAITING} newer acquires came while this one waited for its "
        "liveliness token, and the oldest gives way; ask again"
    )


class _Runtime(Protocol):
    @property
    def lease(self) -> LeaseKeeper: ...


def watch_lease_holders(node: ZenohNode, cell: Cell, runtimes: Iterable[_Runtime]) -> LivelinessWatch:
    """Whether the cell's leases are checked (``command_lease``); watch every lease holder's token of
    the cell and tell each robot's keeper when tokens change."""
    keepers = [runtime.lease for runtime in runtimes]
    for keeper in keepers:
        keeper.book.set_enforced(cell.command_lease)

    def changed() -> None:
        for keeper in keepers:
            try:
                keeper.tokens_changed()
            except Exception:  # one robot's failure must not keep the others' leases from ending
                logging.getLogger(__name__).exception("lease holders' tokens: a keeper failed")

    watch = node.liveliness_watch(CellKeys(cell.cell).lease_holders, changed, LEASE_BIND_TIMEOUT_S)
    for keeper in keepers:
        keeper.attach(watch)
    return watch
