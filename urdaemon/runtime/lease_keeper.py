"""One robot's command lease served: its queryable, the wait for an acquirer's liveliness token, and
what follows a lease's end (the robot stops, an event, a log line). The decisions are the book's
(runtime/lease.py); the cell's one watch of the holders' tokens tells every robot's keeper
(``watch_lease_holders``, called once by the daemon).

An acquire whose token the daemon has not seen yet waits for it in a task of its own (at most
``MAX_WAITING`` at once), so it never holds up the loop nor another request.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable, Iterable
from typing import Any, Protocol

from urdaemon.cell.config import Cell
from urdaemon.errors import MessageError
from urdaemon.publish.keys import CellKeys, RobotKeys
from urdaemon.publish.node import LivelinessWatch, ZenohNode, attachment_of
from urdaemon.runtime.lease import LEASE_BIND_TIMEOUT_S, LeaseBook, LeaseOutcome, LeaseRequest, parse_request
from urdaemon.runtime.queries import SHUTTING_DOWN, Requests, payload, reply
from urdaemon.runtime.status import StatusPublisher

__all__ = ["MAX_WAITING", "LeaseKeeper", "watch_lease_holders"]

MAX_WAITING = 8
"""Most acquires of one robot waiting for their liveliness token at once (more are refused, busy)."""


class LeaseKeeper:
    """Serves one robot's lease queryable and acts on the book's decisions."""

    def __init__(
        self,
        keys: RobotKeys,
        book: LeaseBook,
        stop: Callable[[str], None],
        parts: tuple[Requests, StatusPublisher],
        log: logging.LoggerAdapter[logging.Logger],
    ) -> None:
        self.book = book
        self._keys = keys
        self._stop = stop
        self._requests, self._status = parts
        self._log = log
        self._watch: LivelinessWatch | None = None
        self._waiting: dict[asyncio.Event, str] = {}
        """Each waiting acquire's event (set when its token appears) and its session."""

    def declare(self, node: ZenohNode) -> None:
        """Declare the lease queryable (it never needs a lease itself)."""
        node.queryable(self._keys.lease, self.on_query)

    def attach(self, watch: LivelinessWatch) -> None:
        """Read the holders' tokens from ``watch`` from now on."""
        self._watch = watch
        self.tokens_changed()

    def tokens_changed(self) -> None:
        """Tokens came or went (on the loop): the holder's gone ends the lease; waiters go on."""
        lease = self.book.lease
        if lease is not None and not self._alive(lease.session):
            outcome = self.book.gone(lease.session)
            if outcome is not None:
                self._act(outcome)
        for event, session in self._waiting.items():
            if self._alive(session):
                event.set()

    def _alive(self, session: str) -> bool:
        return self._watch is not None and self._watch.alive(self._keys.lease_holder(session))

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
        elif len(self._waiting) >= MAX_WAITING:
            reply(
                query,
                {"ok": False, "reason": f"busy: {MAX_WAITING} acquires wait for their token; ask again"},
            )
        else:
            work = self._wait_then_grant(query, request)
            self._requests.spawn(work, query, {"ok": False, "reason": SHUTTING_DOWN})

    async def _wait_then_grant(self, query: Any, request: LeaseRequest) -> None:
        event = asyncio.Event()
        self._waiting[event] = request.session
        try:
            await asyncio.wait_for(event.wait(), LEASE_BIND_TIMEOUT_S)
        except TimeoutError:
            pass
        finally:
            del self._waiting[event]
        self._grant(query, request)

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
        if outcome.stop is not None:
            self._stop(outcome.stop)
        if outcome.warning is not None:
            self._log.warning("%s", outcome.warning)
        if outcome.event is not None:
            lease = self.book.lease
            self._status.lease = None if lease is None else {"holder": lease.holder, "since": lease.since}
            if outcome.warning is None:
                self._log.info("lease %s: %s", outcome.event["action"], outcome.event["holder"])
            self._status.event(outcome.event)
            self._status.publish()


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

    watch = node.liveliness_watch(CellKeys(cell.cell).lease_holders, changed)
    for keeper in keepers:
        keeper.attach(watch)
    return watch
