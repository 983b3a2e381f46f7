"""One robot's command lease book: who holds it, with which secret token, since when (pure: time
passed in, no Zenoh).

A client acquires the lease through the robot's lease queryable, bound to its Zenoh session by a
liveliness token ``<cell>/<robot>/lease/<session>``; from then on only messages carrying its token as
their attachment command the robot. The session id is a secret the client chose: whoever names it
gets the holder's token back, so the daemon never shows it, only its ``fingerprint``. The book
decides each request (``acquire``, ``release``, the holder gone) and says what follows: the reply,
the event, whether the robot must stop, what to log.
It does not act: runtime/lease_keeper.py does.

What Zenoh's threads read is one immutable :class:`LeaseView`, swapped whole on every change
(``LeaseBook.current``): the check of a commanding message is one attribute read and one
constant-time compare, and never sees a half-made change.
"""

from __future__ import annotations

import hmac
import secrets
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any

from urdaemon.model import TOKEN_BYTES, fingerprint
from urdaemon.publish.lease_request import LeaseRequest

__all__ = [
    "LEASE_BIND_TIMEOUT_S",
    "Lease",
    "LeaseBook",
    "LeaseOutcome",
    "LeaseView",
]

LEASE_BIND_TIMEOUT_S = 2.0
"""How long an acquire waits for the client's liveliness token before it is refused."""


@dataclass(frozen=True, slots=True)
class Lease:
    """A granted lease: who holds it (``holder``, for humans), its session (secret), since when, its
    token."""

    holder: str
    session: str
    since: float
    """Unix time of the grant."""
    token: str = field(repr=False)
    """The secret the holder attaches to every commanding message (32 lowercase hex characters)."""

    def body(self) -> dict[str, Any]:
        """What clients see of it (never the token, never the session id: its fingerprint)."""
        return {"holder": self.holder, "fingerprint": fingerprint(self.session), "since": self.since}


def _iso(since: float) -> str:
    return datetime.fromtimestamp(since, UTC).isoformat(timespec="seconds")


@dataclass(frozen=True, slots=True)
class LeaseView:
    """The lease as Zenoh's threads check it: immutable, replaced whole on every change."""

    enforced: bool
    """False with ``command_lease: false``: nothing is checked."""
    lease: Lease | None
    refusal_text: str
    """Why a message without the holder's token is refused (worded once, when the view is made)."""
    token: bytes = b""
    """The holder's token as the ASCII bytes clients attach (empty: nobody holds the lease)."""

    def refusal(self, attachment: bytes | None) -> str | None:
        """Why a commanding message with ``attachment`` is refused; None: it may command."""
        if not self.enforced:
            return None
        if self.token and attachment is not None and hmac.compare_digest(attachment, self.token):
            return None
        return self.refusal_text


@dataclass(frozen=True, slots=True)
class LeaseOutcome:
    """What a decision means: the reply, and what the keeper must do."""

    reply: dict[str, Any]
    event: dict[str, Any] | None = None
    """Published on the robot's events key (``kind: lease``)."""
    stop: str | None = None
    """Stop whatever moves the robot, for this reason."""
    warning: str | None = None
    """Logged as a warning."""


class LeaseBook:
    """One robot's lease: grants, releases, take-overs and the holder going away."""

    def __init__(self, robot: str, lease_key: str, *, enforced: bool = True) -> None:
        self.robot = robot
        self.lease_key = lease_key
        self.enforced = enforced
        self.current = self._view(None)
        """What Zenoh's threads read (replaced whole, never changed in place)."""

    def set_enforced(self, enforced: bool) -> None:
        """Check commanding messages (True) or not (``command_lease: false``)."""
        self.enforced = enforced
        self._set(self.lease)

    def refusal(self, attachment: bytes | None) -> str | None:
        """The node's guard (on Zenoh's thread): one read of ``current``, one compare."""
        return self.current.refusal(attachment)

    @property
    def lease(self) -> Lease | None:
        """The lease now (None: free)."""
        return self.current.lease

    def show(self) -> dict[str, Any]:
        """The reply to ``show``."""
        lease = self.lease
        return {"ok": True, "lease": None if lease is None else lease.body()}

    def refused_now(self, request: LeaseRequest) -> LeaseOutcome | None:
        """The refusal an acquire gets at once, before waiting for its token; None: it may wait."""
        lease = self.lease
        if lease is None or lease.session == request.session or request.force or not self.enforced:
            return None
        return LeaseOutcome({"ok": False, "reason": self.held_text(lease), "lease": lease.body()})

    def acquire(self, request: LeaseRequest, now: float) -> LeaseOutcome:
        """Grant the lease to ``request``'s session (its token seen), or refuse; ``now``: unix time."""
        refused = self.refused_now(request)
        if refused is not None:
            return refused
        previous = self.lease
        if previous is not None and previous.session == request.session:
            return LeaseOutcome({"ok": True, "token": previous.token, "lease": previous.body()})
        lease = Lease(request.holder, request.session, now, secrets.token_hex(TOKEN_BYTES))
        self._set(lease)
        reply = {"ok": True, "token": lease.token, "lease": lease.body()}
        if previous is None or not self.enforced:
            extra = {} if previous is None else {"previous": previous.body()}
            return LeaseOutcome(reply, self._event("acquired", lease, **extra))
        why = (
            f"lease of robot {self.robot!r} taken over by {lease.holder} from {previous.holder}: "
            f"{request.reason}"
        )
        return LeaseOutcome(
            reply,
            self._event("taken_over", lease, previous=previous.body(), reason=request.reason),
            stop=why,
            warning=why,
        )

    def release(self, attachment: bytes | None) -> LeaseOutcome:
        """Release the lease for its holder (``attachment``: the holder's token)."""
        lease = self.lease
        if lease is None:
            return LeaseOutcome({"ok": False, "reason": f"lease: robot {self.robot!r} is not held by anyone"})
        token = self.current.token
        if not token or attachment is None or not hmac.compare_digest(attachment, token):
            return LeaseOutcome({"ok": False, "reason": self.held_text(lease, releasing=True)})
        self._set(None)
        stop = f"lease of robot {self.robot!r} released by {lease.holder}" if self.enforced else None
        return LeaseOutcome({"ok": True}, self._event("released", lease), stop=stop)

    def gone(self, session: str) -> LeaseOutcome | None:
        """The liveliness token of ``session`` went away; what follows if it held the lease."""
        lease = self.lease
        if lease is None or lease.session != session:
            return None
        self._set(None)
        why = f"lease holder {lease.holder} is gone"
        return LeaseOutcome(
            {}, self._event("lost", lease, reason=why), stop=why if self.enforced else None, warning=why
        )

    def held_text(self, lease: Lease, *, releasing: bool = False) -> str:
        """Why someone but ``lease``'s holder is refused: the ways out, as commands of the CLI."""
        what = "only its holder may release it" if releasing else "only its holder may command it"
        return (
            f"lease: robot {self.robot!r} is held by {lease.holder} since {_iso(lease.since)}; {what}: "
            f"ask it to release the lease, stop the robot (anyone may: `urdaemon stop {self.robot}`), "
            f"or take the lease over: `urdaemon lease {self.robot} --take-over REASON`"
        )

    def _free_text(self) -> str:
        return (
            f"lease: robot {self.robot!r} needs its command lease for this (nobody holds it): a client "
            "acquires it by itself (`urdaemon move`, `RobotClient.ensure_lease()`); stopping needs none "
            f"(`urdaemon stop {self.robot}`)"
        )

    def _view(self, lease: Lease | None) -> LeaseView:
        if lease is None:
            return LeaseView(self.enforced, None, self._free_text())
        return LeaseView(self.enforced, lease, self.held_text(lease), lease.token.encode("ascii"))

    def _set(self, lease: Lease | None) -> None:
        self.current = self._view(lease)  # one store: a reader sees the old view or the new one

    def _event(self, action: str, lease: Lease, **extra: Any) -> dict[str, Any]:
        return {
            "kind": "lease",
            "action": action,
            "holder": lease.holder,
            "fingerprint": fingerprint(lease.session),
            **extra,
        }
