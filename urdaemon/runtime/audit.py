"""The audit log: every commanding request the daemon sees (who asked, what, accepted or refused and
why), each Zenoh session that connects or goes, as one JSON line to a rotating file (optional) and
on ``<cell>/audit`` (docs/security.md, "The audit log").

``record`` may be called on any thread (Zenoh's, where a lease refusal happens, or the loop) and
never waits: it puts the entry on a bounded queue (``AUDIT_QUEUE`` entries; beyond, entries are
dropped and counted) through the logging module's ``QueueHandler``; one ``QueueListener`` thread
writes the file (``RotatingFileHandler``) and publishes. Nothing here runs in a robot's cycle.

What an entry says of who asked: the requester's relation to the robot's command lease (the
holder, with the holder's name and fingerprint; or not the holder, with who holds it), since a
Zenoh query carries no sender; the peer's address and TLS identity are in the ``session`` entries
Zenoh reports for each link (``connected``/``disconnected``).
"""

from __future__ import annotations

import contextlib
import hmac
import json
import logging
import logging.handlers
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from urdaemon.model import fingerprint
from urdaemon.runtime.lease import LeaseBook

__all__ = [
    "AUDIT_QUEUE",
    "AuditLog",
    "AuditOptions",
    "AuditedQuery",
    "CellAudit",
    "RobotAudit",
    "watch_links",
    "zenoh_log_from_env",
]

AUDIT_QUEUE = 10_000
"""Entries waiting for the writer thread at most; more are dropped (and counted in ``dropped``)."""
PAYLOAD_READ_BYTES = 2048
"""A request's body is read for the audit's ``what`` (lease action, dashboard line) up to this size."""
_WHAT_FIELDS = ("action", "holder", "force", "reason", "command", "goal_id", "fraction")
"""The request fields an entry repeats (never a token, never a lease's secret session id)."""
_TEXT_CHARS = 200


@dataclass(frozen=True, slots=True)
class AuditOptions:
    """Where the audit goes besides ``<cell>/audit``: a rotating file (None: no file)."""

    file: Path | None = None
    max_bytes: int = 10 * 1024 * 1024
    """A file is rotated when it would pass this size."""
    backups: int = 5
    """Rotated files kept (``audit.log.1`` … ``audit.log.5``)."""


class _Enqueue(logging.handlers.QueueHandler):
    """Puts a record on the bounded queue without waiting; a full queue drops it, counted."""

    def __init__(self, target: queue.Queue[Any]) -> None:
        super().__init__(target)
        self.dropped = 0
        self._lock = threading.Lock()

    def prepare(self, record: logging.LogRecord) -> logging.LogRecord:
        return record  # formatted by the writer thread, never on the caller's

    def enqueue(self, record: logging.LogRecord) -> None:
        try:
            self.queue.put_nowait(record)
        except queue.Full:
            with self._lock:
                self.dropped += 1


class _Lines(logging.Formatter):
    """An entry as one JSON line (ASCII: a client's text cannot forge a line or a terminal escape)."""

    def format(self, record: logging.LogRecord) -> str:
        return json.dumps(_summarised(record.msg), separators=(",", ":"), default=str)


class _Publish(logging.Handler):
    """Publishes each entry's line on ``<cell>/audit`` (on the writer thread)."""

    def __init__(self, publish: Callable[[bytes], None]) -> None:
        super().__init__()
        self._publish = publish

    def emit(self, record: logging.LogRecord) -> None:
        with contextlib.suppress(Exception):  # the session closing: the file keeps the entry
            self._publish(self.format(record).encode())


class AuditLog:
    """The cell's audit: ``record`` from any thread; a writer thread writes and publishes."""

    def __init__(self, cell: str, options: AuditOptions | None = None) -> None:
        self.cell = cell
        self.options = options or AuditOptions()
        self._queue: queue.Queue[Any] = queue.Queue(AUDIT_QUEUE)
        self._enqueue = _Enqueue(self._queue)
        self._handlers: list[logging.Handler] = []
        self._listener: logging.handlers.QueueListener | None = None
        self._seq = 0
        self._seq_lock = threading.Lock()

    @property
    def dropped(self) -> int:
        """Entries dropped because the writer fell ``AUDIT_QUEUE`` behind."""
        return self._enqueue.dropped

    def start(self, publish: Callable[[bytes], None] | None = None) -> None:
        """Start the writer thread: to the file (if configured) and to ``publish`` (``<cell>/audit``)."""
        lines = _Lines()
        if self.options.file is not None:
            self.options.file.parent.mkdir(parents=True, exist_ok=True)
            file = logging.handlers.RotatingFileHandler(
                self.options.file,
                maxBytes=self.options.max_bytes,
                backupCount=self.options.backups,
                encoding="utf-8",
            )
            self._handlers.append(file)
        if publish is not None:
            self._handlers.append(_Publish(publish))
        for handler in self._handlers:
            handler.setFormatter(lines)
        self._listener = logging.handlers.QueueListener(self._queue, *self._handlers)
        self._listener.start()

    def close(self) -> None:
        """Write what is queued, then stop the writer thread and close the file."""
        listener, self._listener = self._listener, None
        if listener is not None:
            listener.stop()
        for handler in self._handlers:
            handler.close()
        self._handlers.clear()

    def record(self, entry: dict[str, Any]) -> None:
        """Queue ``entry`` (any thread, never waits): the time and a sequence number are added."""
        with self._seq_lock:
            self._seq += 1
            seq = self._seq
        now = time.time_ns()
        stamped = {
            "time": datetime.fromtimestamp(now / 1e9, UTC).isoformat(timespec="milliseconds"),
            "host_time_ns": now,
            "seq": seq,
        }
        stamped.update(cell=self.cell, **entry)
        self._enqueue.handle(logging.makeLogRecord({"msg": stamped, "levelno": logging.INFO}))

    def session(self, event: str, link: Any) -> None:
        """A Zenoh session connected or went (``link``: Zenoh's ``Link``): its peer address and TLS
        identity, as far as Zenoh tells them."""
        self.record(
            {
                "event": event,
                "zid": str(getattr(link, "zid", "")),
                "peer": _text(getattr(link, "dst", None)),
                "local": _text(getattr(link, "src", None)),
                "tls_identity": _text(getattr(link, "auth_identifier", None)),
                "interfaces": [_text(i) for i in (getattr(link, "interfaces", None) or [])],
            }
        )


def watch_links(session: Any, log: AuditLog) -> Any:
    """Tell ``log`` of every link of ``session`` that comes or goes (those already there first):
    the listener, to undeclare; None when this Zenoh cannot tell."""
    import zenoh

    def on_event(event: Any) -> None:
        gone = event.kind == zenoh.SampleKind.DELETE
        log.session("disconnected" if gone else "connected", event.link)

    try:
        return session.info.declare_link_events_listener(on_event, history=True)
    except (AttributeError, zenoh.ZError):
        return None


def zenoh_log_from_env() -> None:
    """Let Zenoh log to stdout as ``RUST_LOG`` says (nothing without it): what its access control
    denies before the daemon sees it is logged under ``zenoh::net::routing::interceptor::access_control``
    (docs/security.md, "The audit log")."""
    import os

    import zenoh

    if os.environ.get("RUST_LOG"):
        with contextlib.suppress(Exception):  # set up already (once per process)
            zenoh.try_init_log_from_env()  # type: ignore[no-untyped-call]


def _text(value: object) -> str | None:
    if value is None:
        return None
    shown = "".join(c if c.isprintable() else "?" for c in str(value))
    return shown[:_TEXT_CHARS]


def _summarised(entry: Any) -> Any:
    """An entry as written: a request's body read (``body``) into its ``what`` fields, and its
    reply (``reply``) into ``outcome`` and ``reason`` (done here, on the writer thread)."""
    if not isinstance(entry, dict):
        return entry
    entry = dict(entry)
    body = entry.pop("body", None)
    if body is not None:
        what = _fields(body)
        if what:
            entry["request"] = what
    if "reply" in entry:
        reply, error = entry.pop("reply"), entry.pop("reply_error", False)
        answer = entry.pop("answer", None)
        decoded = _decoded(reply)
        said = decoded.get(answer) if isinstance(decoded, dict) and answer else None
        if error:
            entry["outcome"] = "refused"
        elif reply is None:
            entry["outcome"] = "no answer"
        else:
            entry["outcome"] = "refused" if said is False else "accepted"
        if isinstance(decoded, dict):
            for name in ("reason", "goal_id", "canceled"):
                if name in decoded:
                    value = decoded[name]
                    entry[name] = value if isinstance(value, bool) else _text(value)
        elif error and decoded is not None:
            entry["reason"] = _text(decoded)
    return entry


def _decoded(data: Any) -> Any:
    if data is None:
        return None
    try:
        return json.loads(data)
    except (ValueError, TypeError):
        return _text(bytes(data)[:_TEXT_CHARS].decode(errors="replace")) if isinstance(data, bytes) else None


def _fields(body: bytes) -> dict[str, Any]:
    """The request fields worth repeating, from a body (garbage: none)."""
    decoded = _decoded(body)
    if not isinstance(decoded, dict):
        return {}
    return {
        name: decoded[name] if isinstance(decoded[name], bool | int | float) else _text(decoded[name])
        for name in _WHAT_FIELDS
        if name in decoded
    }


def _bytes(payload: Any) -> bytes | None:
    """A reply's or request's payload as bytes (a large one is not copied)."""
    if payload is None:
        return None
    if isinstance(payload, bytes | bytearray):
        return bytes(payload[:PAYLOAD_READ_BYTES]) if len(payload) > PAYLOAD_READ_BYTES else bytes(payload)
    try:
        if len(payload) > PAYLOAD_READ_BYTES:
            return None
        return bytes(payload.to_bytes())
    except (AttributeError, TypeError):
        return str(payload).encode()


class AuditedQuery:
    """A query as a handler sees it, telling the audit the one answer it gets (every other
    attribute is the query's own)."""

    __slots__ = ("_answered", "_entry", "_log", "_query")

    def __init__(self, query: Any, log: AuditLog, entry: dict[str, Any]) -> None:
        self._query = query
        self._log = log
        self._entry = entry
        self._answered = False

    def __getattr__(self, name: str) -> Any:
        return getattr(self._query, name)

    def _told(self, payload: Any, error: bool) -> None:
        if not self._answered:
            self._answered = True
            self._log.record({**self._entry, "reply": _bytes(payload), "reply_error": error})

    def reply(self, key: Any, payload: Any, *args: Any, **kwargs: Any) -> Any:
        self._told(payload, False)
        return self._query.reply(key, payload, *args, **kwargs)

    def reply_err(self, payload: Any, *args: Any, **kwargs: Any) -> Any:
        self._told(payload, True)
        return self._query.reply_err(payload, *args, **kwargs)

    def drop(self) -> None:
        self._told(None, False)
        self._query.drop()


class _Audit:
    """What an endpoint's audit does for one robot or the cell (publish/endpoints.py's ``Audit``)."""

    def __init__(self, log: AuditLog, robot: str | None) -> None:
        self.log = log
        self.robot = robot

    def who(self, attachment: bytes | None) -> dict[str, Any]:
        """Who asked, as far as the lease tells (a query carries no sender)."""
        return {"lease_token": "none" if attachment is None else "attached"}

    def refused(self, key: str, reason: str, attachment: bytes | None) -> None:
        """A message refused before its handler (the lease, a read-only robot): on Zenoh's thread."""
        self.log.record(
            {
                "event": "request",
                "robot": self.robot,
                "key": key,
                "who": self.who(attachment),
                "outcome": "refused",
                "reason": reason,
            }
        )

    def asked(self, key: str, query: Any, answer: str) -> Any:
        """A commanding query reaching its handler (on the loop): the query the handler gets, which
        reports its answer."""
        attachment = query.attachment
        # one longer than a token is not copied (and is none)
        token = None if attachment is None else b"" if len(attachment) > 64 else bytes(attachment.to_bytes())
        entry = {
            "event": "request",
            "robot": self.robot,
            "key": key,
            "who": self.who(token),
            "body": _bytes(query.payload),
            "answer": answer,
        }
        return AuditedQuery(query, self.log, entry)


class RobotAudit(_Audit):
    """One robot's endpoints' audit: who asked is told by the robot's lease book."""

    def __init__(self, log: AuditLog, robot: str, book: LeaseBook) -> None:
        super().__init__(log, robot)
        self._book = book

    def who(self, attachment: bytes | None) -> dict[str, Any]:
        view = self._book.current  # one read: the lease as Zenoh's threads see it
        lease = view.lease
        if not view.enforced:
            return {"lease": "not checked (command_lease: false)", **super().who(attachment)}
        if lease is None:
            return {"lease_holder": False, "lease": "free", **super().who(attachment)}
        holder = {"holder": lease.holder, "fingerprint": fingerprint(lease.session)}
        if view.token and attachment is not None and hmac.compare_digest(attachment, view.token):
            return {"lease_holder": True, **holder}
        return {"lease_holder": False, "lease": holder, **super().who(attachment)}


class CellAudit(_Audit):
    """The cell's endpoints' audit (the cell stop, the cell goals)."""

    def __init__(self, log: AuditLog) -> None:
        super().__init__(log, None)
