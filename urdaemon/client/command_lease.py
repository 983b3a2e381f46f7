"""A client's command lease on one robot (docs/security.md): acquired, watched, released.

``Lease`` works through the client's session (client/session.py): the liveliness token that binds
the lease to it, the lease queryable, the robot's events that may say the lease ended. The facts the
daemon shares (the holder's length, the token's size, the fingerprint) are model.py's.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import re
import secrets
import socket
import sys
from pathlib import Path
from typing import Any

import zenoh

from urdaemon.client.session import QUERY_TIMEOUT_S, ClientSession, NoSuchService, zenoh_message
from urdaemon.errors import GoalRejected, UrDaemonError
from urdaemon.model import HOLDER_MAX_CHARS, TOKEN_BYTES, fingerprint
from urdaemon.publish.envelope import client_text
from urdaemon.publish.keys import RobotKeys
from urdaemon.publish.lease_request import LeaseRequest, lease_body

__all__ = ["LEASE_SESSION_BYTES", "Lease", "LeaseHeld", "default_holder", "holder_text"]

LEASE_SESSION_BYTES = 16
"""A lease's secret session id is this many random bytes, as hex (a fresh one per lease)."""
_LEASE_TOKEN = re.compile(rf"[0-9a-f]{{{2 * TOKEN_BYTES}}}")
BUSY_RETRY_S = QUERY_TIMEOUT_S
"""How long an acquire asks again while the daemon answers busy."""


def _busy(reply: dict[str, Any]) -> bool:
    """Whether the daemon refused an acquire as busy (ask again), not for another's lease."""
    reason = reply.get("reason")
    return reply.get("ok") is not True and isinstance(reason, str) and reason.startswith("busy")


class LeaseHeld(GoalRejected):
    """The daemon refused a command for the robot's command lease: another client holds it (the
    reason names the holder and since when), or this client's lease ended (taken over, released)."""


def default_holder(program: str | None = None) -> str:
    """The holder text a lease shows to humans: the program, its pid and host
    (``"urdaemon move (pid 1234 on cell-pc)"``), cut to what the daemon takes."""
    name = program or _program_name(sys.argv[0] if sys.argv else "")
    text = f"{name} (pid {os.getpid()} on {socket.gethostname()})"
    return holder_text(text)


def _program_name(argv0: str) -> str:
    """The script's name; a package's for ``python -m package``; "python" for ``-c`` or none."""
    path = Path(argv0)
    if path.name == "__main__.py" and path.parent.name:
        return path.parent.name
    if not path.name or path.name.startswith("-"):
        return "python"
    return path.name


def holder_text(text: str) -> str:
    """``text`` as a lease's holder: printable, stripped, cut to what the daemon takes ("python" if empty)."""
    shown = "".join(c if c.isprintable() else "?" for c in text).strip()
    return shown[:HOLDER_MAX_CHARS] or "python"


class Lease:
    """A client's command lease on one robot (docs/security.md): the liveliness token that binds it
    to the client's session, and the token the daemon granted, attached to every command.

    Each acquire that declares a token picks a fresh secret session id S (``secrets.token_hex(16)``):
    the liveliness token is ``<cell>/<robot>/lease/<S>`` and the daemon binds the lease to it. The
    daemon never shows S, only its fingerprint (``urdaemon.model.fingerprint``), so nobody
    can acquire in this client's name. A refusal, a release or a lease that ended undeclares the token.

    A lease that ended without this client releasing it (taken over, lost, released: heard on the
    robot's events and confirmed by asking the daemon, or a command refused for the lease) is not
    acquired again behind the program's back: commands raise ``LeaseHeld`` saying why until
    ``acquire(again=True)`` (``RobotClient.ensure_lease``). A forced take-over would mean little if
    the client it stopped took the lease back with its next command. An event alone never ends it:
    anyone can publish on the events key, so the client asks ``show`` first.
    """

    def __init__(self, client: ClientSession, keys: RobotKeys) -> None:
        self.client = client
        self.keys = keys
        self.token: str | None = None
        """The daemon's grant while this client holds the lease, else None."""
        self.unchecked = False
        """The daemon serves no lease for this robot (one older than leases): commands go without."""
        self.ended_reason: str | None = None
        """Why this client's lease ended without its release (None: it did not)."""
        self.refusal: str | None = None
        """The daemon's reason when this client last asked for the lease in vain (None: granted)."""
        self.ended = asyncio.Event()
        """Set when the lease ends without this client's release; cleared when it acquires again."""
        self.fingerprint: str | None = None
        """What the daemon shows of this client's lease (None while no liveliness token is declared)."""
        self.checks = 0
        """Lease events about this lease confirmed or denied by asking the daemon (``show``)."""
        self.checking: asyncio.Task[None] | None = None
        """The check under way, if any (one at a time: a flood of events asks once more at most)."""
        self._session = ""
        self._heard: dict[str, Any] | None = None
        self._again = False
        self._alive: Any = None
        self._events: Any = None
        self._lock = asyncio.Lock()

    @property
    def usable(self) -> bool:
        """Whether commands can be sent now: the lease is held, or the daemon checks none."""
        return self.token is not None or self.unchecked

    def attachment(self) -> bytes | None:
        """What goes with a command: the token's ASCII bytes (None without one)."""
        return None if self.token is None else self.token.encode()

    async def acquire(self, *, force: bool = False, reason: str = "", again: bool = False) -> dict[str, Any]:
        """The daemon's grant (acquired unless held already, or taken over with ``force``); raises
        ``LeaseHeld`` with the daemon's reason when refused, or why the lease ended unless ``again``."""
        async with self._lock:
            if self.usable and not force:
                return {"ok": True, "token": self.token}
            if self.ended_reason is not None and not (again or force):
                raise LeaseHeld(self.ended_reason)
            self._declare()
            request = LeaseRequest("acquire", self._session, self.client.holder, force, reason)
            try:
                reply = await self._ask_while_busy(request)
            except NoSuchService:
                self._undeclare()
                self.unchecked = True
                return {"ok": True, "token": None}
            except BaseException:
                self._undeclare()
                raise
            token = reply.get("token")
            if reply.get("ok") is True and isinstance(token, str) and _LEASE_TOKEN.fullmatch(token):
                self._granted(token)
                return reply
            self._undeclare()
            self.refusal = str(reply.get("reason") or f"lease: not granted ({reply})")
            if _busy(reply):  # nobody holds it against this client: the daemon was too busy to decide
                raise UrDaemonError(
                    f"lease of robot {self.keys.robot!r} not granted: the daemon stayed busy for "
                    f"{BUSY_RETRY_S:g} s ({self.refusal})"
                )
            raise LeaseHeld(self.refusal)

    async def _ask_while_busy(self, request: LeaseRequest) -> dict[str, Any]:
        """The daemon's answer to ``request``, asked again while it answers busy (acquires waiting for
        their tokens, a flood of them among them), for up to ``BUSY_RETRY_S``."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + BUSY_RETRY_S
        pause = 0.05
        for _ in range(1000):
            reply = await self.client.request(self.keys.lease, lease_body(request))
            if not _busy(reply) or loop.time() + pause > deadline:
                return reply
            await asyncio.sleep(pause)
            pause = min(2 * pause, 0.5)
        return reply

    def _granted(self, token: str) -> None:
        self.token = token
        self.ended_reason = self.refusal = None
        self.ended.clear()
        if self._events is None:  # an end is published there: streams stop at once, not silently
            loop = asyncio.get_running_loop()

            def on_event(sample: Any) -> None:
                payload = sample.payload.to_bytes()
                if _may_end_a_lease(payload):  # the loop parses only what may end a lease
                    with contextlib.suppress(RuntimeError):
                        loop.call_soon_threadsafe(self._on_event, payload)

            self._events = self.client.session.declare_subscriber(self.keys.events, on_event)
            self.client.on_close(self._events.undeclare)

    def _on_event(self, payload: bytes) -> None:
        """A lease event that says this client's lease ended (taken over, lost, released): ask the
        daemon whether it did (whoever can publish on the events key can forge one)."""
        event = _ending_event(payload)
        if event is None or self.token is None or self.fingerprint is None:
            return
        if _ended_fingerprint(event) != self.fingerprint:
            return  # another lease's end (an earlier one of this client's, or someone else's)
        self._heard = event
        if self.checking is not None and not self.checking.done():
            self._again = True  # the check under way may have asked before this end happened
            return
        self.checking = self.client.spawn(self._check())

    async def _check(self) -> None:
        """Ask ``show`` (off Zenoh's thread; the loop keeps running) until no event came meanwhile;
        end the lease when the daemon shows it free or another's. A failed ask ends nothing."""
        again = True
        while again and self.token is not None:
            self._again = False
            token, mine = self.token, self.fingerprint
            try:
                shown = await self.show()
            except UrDaemonError:
                return
            self.checks += 1
            if self.token == token and (shown is None or shown.get("fingerprint") != mine):
                self.end(_ended_text(self.keys.robot, self._heard, shown))
                return
            again = self._again

    async def confirm_end(self, reason: str) -> None:
        """A command was refused for the lease: end it for ``reason`` unless the daemon still shows
        it as this client's (the refusal came from another session answering the command's query),
        or when the daemon cannot be asked."""
        token, mine = self.token, self.fingerprint
        if token is None:
            return
        try:
            shown = await self.show()
        except UrDaemonError:
            shown = None
        if self.token == token and (shown is None or shown.get("fingerprint") != mine):
            self.end(reason)

    async def release(self, *, timeout: float = QUERY_TIMEOUT_S) -> dict[str, Any] | None:
        """Give the lease back (stops whatever still moves the robot); the daemon's reply, or None
        when this client held none."""
        async with self._lock:
            attachment = self.attachment()
            self.token = None
            try:
                if attachment is None:
                    return None
                return await self.client.request(
                    self.keys.lease,
                    lease_body(LeaseRequest("release")),
                    timeout=timeout,
                    attachment=attachment,
                )
            finally:
                self._undeclare()

    def end(self, reason: str) -> None:
        """The lease is no longer this client's, for ``reason`` (taken over, lost, or a command
        refused for it: released by whoever took it over, or a daemon that restarted)."""
        self.token = None
        self.ended_reason = reason
        self.ended.set()
        self._undeclare()

    async def show(self) -> dict[str, Any] | None:
        """The lease as the daemon shows it (``holder``, ``fingerprint``, ``since``), None when free."""
        reply = await self.client.request(self.keys.lease, lease_body(LeaseRequest("show")))
        if reply.get("ok") is not True:
            raise UrDaemonError(str(reply.get("reason") or f"lease: no answer to show ({reply})"))
        lease = reply.get("lease")
        return lease if isinstance(lease, dict) else None

    def _declare(self) -> None:
        if self._alive is None:
            session = secrets.token_hex(LEASE_SESSION_BYTES)  # a secret per lease: never shown
            key = self.keys.lease_holder(session)
            try:
                self._alive = self.client.session.liveliness().declare_token(key)
            except zenoh.ZError as err:
                raise UrDaemonError(f"cannot declare the lease token {key}: {zenoh_message(err)}") from err
            self._session, self.fingerprint = session, fingerprint(session)

    def _undeclare(self) -> None:
        alive, self._alive = self._alive, None
        if alive is not None:
            with contextlib.suppress(Exception):
                alive.undeclare()


_ENDING_ACTIONS = ("taken_over", "lost", "released")


def _may_end_a_lease(payload: bytes) -> bool:
    """On Zenoh's thread: whether an event may be a lease's end (cheap; the loop parses it)."""
    return b"lease" in payload and any(action.encode() in payload for action in _ENDING_ACTIONS)


def _ending_event(payload: bytes) -> dict[str, Any] | None:
    """``payload`` decoded if it is a lease event saying a lease ended, else None."""
    try:
        event = json.loads(payload)
    except ValueError:
        return None
    if not isinstance(event, dict) or event.get("kind") != "lease":
        return None
    return event if event.get("action") in _ENDING_ACTIONS else None


def _ended_fingerprint(event: dict[str, Any]) -> object:
    """The fingerprint of the lease an ending event says ended (a take-over names it as previous)."""
    if event.get("action") == "taken_over":
        previous = event.get("previous")
        return previous.get("fingerprint") if isinstance(previous, dict) else None
    return event.get("fingerprint")


def _ended_text(robot: str, heard: dict[str, Any] | None, shown: dict[str, Any] | None) -> str:
    """Why a lease ended, as the daemon shows the robot's lease now (``shown``), in the words of the
    event heard when it agrees with the daemon (a take-over by the holder shown, or a free lease)."""
    heard = heard or {}
    why = heard.get("reason")
    again = "ensure_lease() acquires it again"
    if shown is None:
        cause = why if isinstance(why, str) and heard.get("action") == "lost" else "it is free now"
        return f"lease: robot {robot!r} is no longer this client's ({client_text(cause, 200)}); {again}"
    holder = client_text(str(shown.get("holder")), HOLDER_MAX_CHARS)
    if heard.get("action") == "taken_over" and heard.get("fingerprint") == shown.get("fingerprint"):
        return f"lease: robot {robot!r} was taken over by {holder}: {client_text(str(why), 200)}; {again}"
    return f"lease: robot {robot!r} is held by {holder} now, no longer by this client; {again}"
