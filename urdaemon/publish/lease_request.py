"""A request to a robot's lease queryable (``<cell>/<robot>/lease``): ``show``, ``acquire`` (with a
secret session id and a holder, or taken over with ``force`` and a reason) or ``release``. The
client builds its body (``lease_body``) from the type the daemon decodes it to (``parse_request``);
the lease book that decides it is runtime/lease.py's."""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

from urdaemon.errors import MessageError
from urdaemon.model import HOLDER_MAX_CHARS
from urdaemon.publish.envelope import client_text, decode_message

__all__ = ["LeaseRequest", "lease_body", "parse_request"]

_SESSION = re.compile(r"[A-Za-z0-9_-]{16,64}")
_ACTIONS = ("show", "acquire", "release")
_FIELDS = {"v", "action", "session", "holder", "force", "reason"}


@dataclass(frozen=True, slots=True)
class LeaseRequest:
    """A decoded request to the lease queryable."""

    action: str
    session: str = ""
    holder: str = ""
    force: bool = False
    reason: str = ""


def lease_body(request: LeaseRequest) -> dict[str, Any]:
    """The message's fields of ``request`` (``parse_request``'s inverse): the action; an acquire's
    session and holder, and ``force`` with its reason only when taking over."""
    body: dict[str, Any] = {"action": request.action}
    if request.action == "acquire":
        body.update(session=request.session, holder=request.holder)
        if request.force:
            body.update(force=True, reason=request.reason)
    return body


def parse_request(payload: bytes | None) -> LeaseRequest:
    """A lease request from its payload; ``MessageError`` naming what is wrong."""
    data = decode_message(payload, "lease")
    unknown = sorted(set(data) - _FIELDS)
    if unknown:
        raise MessageError(f"lease: unknown field(s) {', '.join(client_text(k, 40) for k in unknown[:3])}")
    action = data.get("action")
    if action not in _ACTIONS:
        raise MessageError(
            f"lease: 'action' must be one of {', '.join(_ACTIONS)}, not {client_text(repr(action), 40)}"
        )
    if action != "acquire":
        return LeaseRequest(action)
    session, holder = data.get("session"), data.get("holder")
    if not isinstance(session, str) or not _SESSION.fullmatch(session):
        raise MessageError(
            "lease: 'session' must be 16 to 64 characters of A-Z, a-z, 0-9, '_' and '-' "
            "(a secret chosen per lease)"
        )
    if not isinstance(holder, str) or not 0 < len(holder) <= HOLDER_MAX_CHARS or not holder.isprintable():
        raise MessageError(f"lease: 'holder' must be 1 to {HOLDER_MAX_CHARS} printable characters")
    force = data.get("force", False)
    if not isinstance(force, bool):
        raise MessageError("lease: 'force' must be true or false")
    reason = data.get("reason", "")
    if not isinstance(reason, str) or (force and not reason.strip()):
        raise MessageError("lease: 'reason' must be a non-empty text saying why, to take the lease over")
    return LeaseRequest(action, session, holder, force, client_text(reason, 200))
