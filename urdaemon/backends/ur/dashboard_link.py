"""The daemon's dashboard client (29999): one command at a time, typed replies."""

from __future__ import annotations

import asyncio
from collections import deque
from typing import Any

from urdaemon.errors import RemoteProtocolError, UrTimeoutError
from urdaemon.protocols import dashboard as dash
from urdaemon.protocols._buffer import Side
from urdaemon.shell import Shell, connect

__all__ = ["DASHBOARD_PORT", "DashboardLink"]

DASHBOARD_PORT = dash.DASHBOARD_PORT
BANNER_TIMEOUT_S = 10.0
"""urcl waits 10 s for the banner (docs/protocols.md §3.1)."""
REPLY_TIMEOUT_S = 5.0


class DashboardLink(Shell):
    """One dashboard connection (the shell around ``DashboardConnection``); ``command`` sends a command
    and returns its typed reply."""

    def __init__(self) -> None:
        super().__init__(dash.DashboardConnection(Side.DAEMON), "dashboard", self._arrived)
        self.conn: dash.DashboardConnection = self.codec
        self._lock = asyncio.Lock()
        self._pending: deque[Any] = deque()
        self._waiter: asyncio.Future[None] | None = None
        self.banner: dash.Banner | None = None

    @classmethod
    async def connect(cls, host: str, *, port: int = DASHBOARD_PORT, timeout: float = 5.0) -> DashboardLink:
        """Connect and read the banner."""
        link = await connect(cls, host, port, timeout=timeout, name="dashboard")
        try:
            banner = await link._next(BANNER_TIMEOUT_S)
            if not isinstance(banner, dash.Banner):
                raise RemoteProtocolError("dashboard: no banner", protocol="dashboard")
        except BaseException:
            link.close()
            raise
        link.banner = banner
        return link

    async def command(self, command: Any, *, timeout: float = REPLY_TIMEOUT_S) -> Any:
        """Send ``command`` and return its typed reply (refusals are replies with success False)."""
        async with self._lock:
            self.conn.send(command)
            self.flush()
            return await self._next(timeout)

    def end(self, reason: Exception) -> None:
        super().end(reason)
        self._wake()

    def _arrived(self, event: Any) -> None:
        self._pending.append(event)
        self._wake()

    def _wake(self) -> None:
        if self._waiter is not None and not self._waiter.done():
            self._waiter.set_result(None)

    async def _next(self, timeout: float) -> Any:
        """The next reply; UrTimeoutError after ``timeout``, the reason once the connection ended."""
        while not self._pending:
            if self.closed.done():
                raise self.closed.result()
            self._waiter = asyncio.get_running_loop().create_future()
            try:
                await asyncio.wait_for(self._waiter, timeout)
            except TimeoutError as err:
                raise UrTimeoutError(f"dashboard: no reply within {timeout} s") from err
            finally:
                self._waiter = None
        return self._pending.popleft()
