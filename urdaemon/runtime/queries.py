"""Answering a Zenoh query exactly once, and the request tasks a runtime cancels when it shuts down."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Coroutine
from typing import Any

from urdaemon.publish import envelope

__all__ = ["SHUTTING_DOWN", "Requests", "internal_error", "payload", "reply"]

SHUTTING_DOWN = "daemon shutting down"
"""The reason every request gets once the daemon started to shut down."""


def payload(query: Any) -> bytes | None:
    """The query's payload (None: it has none)."""
    data = query.payload
    return None if data is None else bytes(data.to_bytes())


def reply(query: Any, body: dict[str, Any]) -> None:
    """Answer ``query`` with ``body`` and end it; a querier that timed out and went is no error."""
    with contextlib.suppress(Exception):
        query.reply(query.key_expr, envelope.encode(body))
    with contextlib.suppress(Exception):
        query.drop()


def internal_error(err: Exception) -> str:
    """The reason a client hears when a bug, not its request, made the command fail."""
    return f"internal error: {type(err).__name__}: {err}"


class Requests:
    """The tasks that serve requests (services, trajectory goals): each answers its query once."""

    def __init__(self) -> None:
        self.tasks: set[asyncio.Task[None]] = set()

    def spawn(
        self, work: Coroutine[Any, Any, None], query: Any, cancelled: dict[str, Any]
    ) -> asyncio.Task[None]:
        """Run ``work`` (which answers ``query`` once); cancelled (shutting down), even before its first
        step, the query is answered ``cancelled`` here instead, once."""
        task = asyncio.get_running_loop().create_task(work)
        self.tasks.add(task)

        def done(task: asyncio.Task[None]) -> None:
            self.tasks.discard(task)
            if task.cancelled():
                reply(query, cancelled)

        task.add_done_callback(done)
        return task

    async def cancel_all(self) -> None:
        """Cancel every request still in progress (each is answered ``SHUTTING_DOWN``) and wait."""
        pending = list(self.tasks)
        for task in pending:
            task.cancel()
        if pending:
            await asyncio.gather(*pending, return_exceptions=True)
