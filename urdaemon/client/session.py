"""A client's Zenoh session and what lives on it: queries and their answers, subscriptions whose
samples are delivered to the loop, and the background tasks and Zenoh declarations that end with it.

``ClientSession`` is what each part of the client works through (a robot's commands, its goals'
messages, its lease); ``Client`` (client/cell_connection.py) is one, opened on an endpoint. It knows nothing
of robots.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import re
from collections.abc import AsyncIterator, Callable, Coroutine
from typing import Any, NamedTuple

import zenoh

from urdaemon.errors import UrDaemonError, UrTimeoutError
from urdaemon.publish import services
from urdaemon.publish.envelope import SCHEMA_VERSION

__all__ = [
    "QUERY_TIMEOUT_S",
    "ClientSession",
    "NoSuchService",
    "Received",
    "Subscription",
    "encode_body",
    "zenoh_message",
]

QUERY_TIMEOUT_S = services.CLIENT_TIMEOUT_S
"""How long a query waits for its answer unless told (a service's own wait is in its table entry)."""

_RUST_LOCATION = re.compile(r"\s+at\s+\S+\.rs:\d+(:\d+)?\.?")


def zenoh_message(err: BaseException) -> str:
    """A Zenoh error's text without the Rust source location it carries (``at /root/.cargo/...rs:1``)."""
    return _RUST_LOCATION.sub("", str(err)).strip()


class NoSuchService(UrDaemonError):
    """Nothing answers the key: the daemon serves no such service (or goal key) for that robot."""


def encode_body(body: dict[str, Any]) -> bytes:
    """A request or command body as sent: JSON with the schema version."""
    return json.dumps({"v": SCHEMA_VERSION, **body}, separators=(",", ":")).encode()


class Received(NamedTuple):
    """One sample as a subscription received it: its key, payload and Zenoh attachment (or None)."""

    key: str
    payload: bytes
    attachment: bytes | None


class Subscription:
    """Samples of a key expression, delivered to the loop; iterate with ``async for`` over
    ``(key, payload)``, or over ``samples()`` for each sample's attachment too."""

    def __init__(
        self, session: Any, key_expr: str, loop: asyncio.AbstractEventLoop, maxsize: int = 1000
    ) -> None:
        self.key_expr = key_expr
        self._queue: asyncio.Queue[Received] = asyncio.Queue(maxsize)
        self._loop = loop
        self.dropped = 0
        self._sub = session.declare_subscriber(key_expr, self._on_sample)

    def _on_sample(self, sample: Any) -> None:
        item = _received(sample)
        with contextlib.suppress(RuntimeError):
            self._loop.call_soon_threadsafe(self._put, item)

    def _put(self, item: Received) -> None:
        try:
            self._queue.put_nowait(item)
        except asyncio.QueueFull:
            self.dropped += 1

    async def get_sample(self, timeout: float | None = None) -> Received:
        """The next sample with its attachment; raises ``UrTimeoutError`` after ``timeout`` seconds."""
        try:
            return await asyncio.wait_for(self._queue.get(), timeout)
        except TimeoutError as err:
            raise UrTimeoutError(f"no sample on {self.key_expr} within {timeout} s") from err

    async def get(self, timeout: float | None = None) -> tuple[str, bytes]:
        """The next (key, payload); raises ``UrTimeoutError`` after ``timeout`` seconds."""
        item = await self.get_sample(timeout)
        return item.key, item.payload

    async def get_json(self, timeout: float | None = None) -> dict[str, Any]:
        """The next sample decoded as JSON."""
        _, payload = await self.get(timeout)
        data: dict[str, Any] = json.loads(payload)
        return data

    def __aiter__(self) -> AsyncIterator[tuple[str, bytes]]:
        return self._iterate()

    async def _iterate(self) -> AsyncIterator[tuple[str, bytes]]:
        while True:
            item = await self._queue.get()
            yield item.key, item.payload

    async def samples(self) -> AsyncIterator[Received]:
        """Every sample with its attachment, as it comes."""
        while True:
            yield await self._queue.get()

    def close(self) -> None:
        """Stop receiving."""
        with contextlib.suppress(Exception):
            self._sub.undeclare()


class ClientSession:
    """A Zenoh session connected to a urdaemon cell, and what ends with it."""

    def __init__(self, session: Any, loop: asyncio.AbstractEventLoop, endpoint: str, holder: str) -> None:
        self.session = session
        self.endpoint = endpoint
        """Where this client connected (named in error messages)."""
        self.holder = holder
        """Who this client is, as its leases show it to others (``urdaemon lease``)."""
        self._loop = loop
        self._subscriptions: list[Subscription] = []
        self._tasks: list[asyncio.Task[None]] = []
        self._closers: list[Callable[[], object]] = []

    async def close(self) -> None:
        """Stop background tasks, undeclare what was declared and every subscription, close the session."""
        tasks = list(self._tasks)  # each forgets itself from the list as it ends
        for task in tasks:
            task.cancel()
        for task in tasks:
            with contextlib.suppress(asyncio.CancelledError):
                await task
        for closer in self._closers:
            with contextlib.suppress(Exception):
                closer()
        for sub in self._subscriptions:
            sub.close()
        await self._loop.run_in_executor(None, self.session.close)

    def spawn(self, work: Coroutine[Any, Any, None]) -> asyncio.Task[None]:
        """Run ``work`` in the background until it ends, or until the session closes (cancelled then)."""
        task = asyncio.get_running_loop().create_task(work)
        self._tasks.append(task)
        task.add_done_callback(self._forget_task)
        return task

    def _forget_task(self, task: asyncio.Task[None]) -> None:
        with contextlib.suppress(ValueError):
            self._tasks.remove(task)

    def on_close(self, closer: Callable[[], object]) -> None:
        """Call ``closer`` when the session closes (a Zenoh declaration's ``undeclare``; errors ignored)."""
        self._closers.append(closer)

    def unsubscribe(self, sub: Subscription) -> None:
        """Close ``sub`` and forget it."""
        sub.close()
        with contextlib.suppress(ValueError):
            self._subscriptions.remove(sub)

    def subscribe(self, key_expr: str, maxsize: int = 1000) -> Subscription:
        """Subscribe to ``key_expr`` (closed with the client)."""
        try:
            sub = Subscription(self.session, key_expr, self._loop, maxsize)
        except zenoh.ZError as err:
            raise UrDaemonError(f"cannot subscribe to {key_expr!r}: {zenoh_message(err)}") from err
        self._subscriptions.append(sub)
        return sub

    async def query(
        self,
        key: str,
        body: dict[str, Any] | None = None,
        *,
        timeout: float = QUERY_TIMEOUT_S,
        attachment: bytes | None = None,
    ) -> list[bytes]:
        """Ask a queryable; every reply's payload. ``attachment``: e.g. a lease's token."""
        replies = await self.query_replies(key, body, timeout=timeout, attachment=attachment)
        return [reply.payload for reply in replies]

    async def query_replies(
        self,
        key: str,
        body: dict[str, Any] | None = None,
        *,
        timeout: float = QUERY_TIMEOUT_S,
        attachment: bytes | None = None,
        every_queryable: bool = False,
    ) -> list[Received]:
        """Ask a queryable; every reply with its attachment. ``every_queryable``: ask all that serve
        ``key`` and keep every reply (not just the best match, nor one reply per key)."""
        replies, _ = await self._ask(key, body, timeout, attachment, every_queryable)
        return replies

    async def _ask(
        self,
        key: str,
        body: dict[str, Any] | None,
        timeout: float,
        attachment: bytes | None,
        every_queryable: bool = False,
    ) -> tuple[list[Received], list[bytes]]:
        """Every reply to a query on ``key``, and every error reply's payload."""
        payload = None if body is None else encode_body(body)
        options: dict[str, Any] = {}
        if every_queryable:
            options = {"target": zenoh.QueryTarget.ALL, "consolidation": zenoh.ConsolidationMode.NONE}

        def ask() -> tuple[list[Received], list[bytes]]:
            replies = list(
                self.session.get(key, payload=payload, timeout=timeout, attachment=attachment, **options)
            )
            errors = [bytes(r.err.payload.to_bytes()) for r in replies if r.ok is None and r.err is not None]
            return [_received(r.ok) for r in replies if r.ok is not None], errors

        try:
            return await self._loop.run_in_executor(None, ask)
        except zenoh.ZError as err:
            raise UrDaemonError(f"cannot ask {key!r} at {self.endpoint}: {zenoh_message(err)}") from err

    async def request(
        self,
        key: str,
        body: dict[str, Any] | None = None,
        *,
        timeout: float = QUERY_TIMEOUT_S,
        attachment: bytes | None = None,
    ) -> dict[str, Any]:
        """Ask a queryable that must answer once.

        Raises ``NoSuchService`` when the query ends at once without a reply (nobody serves ``key``),
        ``UrTimeoutError`` when nobody answers within ``timeout`` s.
        """
        start = self._loop.time()
        received, errors = await self._ask(key, body, timeout, attachment)
        replies = [reply.payload for reply in received]
        if not replies and errors:  # the daemon refused it as no answer can be (a wildcard, no such goal)
            raise UrDaemonError(f"{key}: {_error_text(errors[0])}")
        if not replies:
            if self._loop.time() - start < min(0.5 * timeout, 1.0):
                raise NoSuchService(
                    f"nothing at {self.endpoint} answers {key}: the daemon serves no such key, or the "
                    "cell's access control does not let this client ask it (docs/security.md, "
                    '"Access control")'
                )
            raise UrTimeoutError(
                f"no answer on {key} from {self.endpoint} within {timeout:g} s (a daemon that is "
                "there but busy, or access control that drops the query: docs/security.md)"
            )
        try:
            data = json.loads(replies[0])
        except ValueError as err:
            raise UrDaemonError(f"the answer on {key} is not JSON: {err}") from err
        if not isinstance(data, dict):
            raise UrDaemonError(f"the answer on {key} is not a JSON object")
        return data


def _error_text(payload: bytes) -> str:
    """What an error reply says: its ``reason`` (a JSON refusal), else its text."""
    try:
        data = json.loads(payload)
    except ValueError:
        return payload.decode(errors="replace")[:300]
    if isinstance(data, dict) and isinstance(data.get("reason"), str):
        return str(data["reason"])[:300]
    return payload.decode(errors="replace")[:300]


def _received(sample: Any) -> Received:
    attachment = sample.attachment
    return Received(
        str(sample.key_expr), sample.payload.to_bytes(), None if attachment is None else attachment.to_bytes()
    )
