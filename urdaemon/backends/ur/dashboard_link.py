"""The daemon's dashboard client (29999): one command at a time, typed replies."""

from __future__ import annotations

import asyncio
import contextlib
from typing import Any

from urdaemon.errors import ConnectionLostError, RemoteProtocolError, UrTimeoutError
from urdaemon.protocols import dashboard as dash
from urdaemon.protocols._buffer import Side

__all__ = ["DASHBOARD_PORT", "DashboardLink"]

DASHBOARD_PORT = 29999
BANNER_TIMEOUT_S = 10.0
"""urcl waits 10 s for the banner (ur-protocols.md §3.1)."""
REPLY_TIMEOUT_S = 5.0


class DashboardLink:
    """One dashboard connection; ``command`` sends a command and returns its typed reply."""

    def __init__(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self.reader = reader
        self.writer = writer
        self.conn = dash.DashboardConnection(Side.DAEMON)
        self._lock = asyncio.Lock()
        self._pending: list[Any] = []
        self.banner: dash.Banner | None = None

    @classmethod
    async def connect(cls, host: str, *, port: int = DASHBOARD_PORT, timeout: float = 5.0) -> DashboardLink:
        """Connect and read the banner."""
        try:
            reader, writer = await asyncio.wait_for(asyncio.open_connection(host, port), timeout)
        except TimeoutError as err:
            raise UrTimeoutError(f"dashboard: no connection to {host}:{port} within {timeout} s") from err
        except OSError as err:
            raise ConnectionLostError(
                f"dashboard: cannot connect to {host}:{port}: {err.strerror or err}"
            ) from err
        link = cls(reader, writer)
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
            self.writer.write(self.conn.data_to_send())
            return await self._next(timeout)

    async def _next(self, timeout: float) -> Any:
        while not self._pending:
            try:
                data = await asyncio.wait_for(self.reader.read(4096), timeout)
            except TimeoutError as err:
                raise UrTimeoutError(f"dashboard: no reply within {timeout} s") from err
            except (ConnectionError, OSError) as err:
                raise ConnectionLostError(f"dashboard: connection lost: {err}") from err
            if not data:
                raise ConnectionLostError("dashboard: connection closed by the robot")
            self._pending.extend(self.conn.receive_data(data))
        return self._pending.pop(0)

    def close(self) -> None:
        """Close the connection."""
        with contextlib.suppress(Exception):
            self.writer.close()
