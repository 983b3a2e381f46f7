"""Shared pieces of the sans-IO codecs: which party we are, and a capped receive buffer."""

from __future__ import annotations

import enum

from urdaemon.errors import RemoteProtocolError

__all__ = ["ReceiveBuffer", "Side"]


class Side(enum.Enum):
    """Which party a codec speaks for: named by party, not by TCP role (on callback ports the robot dials)."""

    DAEMON = "daemon"
    ROBOT = "robot"


class ReceiveBuffer:
    """Bytes received and not yet decoded; refuses to grow past ``limit`` (a peer flooding garbage)."""

    __slots__ = ("_data", "_start", "limit", "protocol")

    def __init__(self, protocol: str, limit: int) -> None:
        self.protocol = protocol
        self.limit = limit
        self._data = bytearray()
        self._start = 0

    def __len__(self) -> int:
        return len(self._data) - self._start

    def feed(self, data: bytes | bytearray | memoryview) -> None:
        """Append received bytes; RemoteProtocolError if more than ``limit`` would wait undecoded."""
        if len(self) + len(data) > self.limit:
            raise RemoteProtocolError(
                f"{self.protocol}: more than {self.limit} bytes received without a complete message",
                protocol=self.protocol,
            )
        if self._start and self._start * 2 >= len(self._data):
            del self._data[: self._start]  # compact now and then: amortised O(n), never per message
            self._start = 0
        self._data += data

    def peek(self, n: int) -> bytes | None:
        """The next ``n`` bytes without consuming them, or None if fewer are buffered."""
        if len(self) < n:
            return None
        return bytes(self._data[self._start : self._start + n])

    def take(self, n: int) -> bytes | None:
        """Consume and return the next ``n`` bytes, or None if fewer are buffered."""
        if len(self) < n:
            return None
        out = bytes(self._data[self._start : self._start + n])
        self._start += n
        return out

    def take_line(self, max_length: int) -> bytes | None:
        """Consume one line up to and including ``\\n``; None if no full line yet.

        RemoteProtocolError if ``max_length`` bytes arrived without a newline.
        """
        end = self._data.find(b"\n", self._start)
        if end < 0:
            if len(self) > max_length:
                raise RemoteProtocolError(
                    f"{self.protocol}: line longer than {max_length} bytes", protocol=self.protocol
                )
            return None
        if end + 1 - self._start > max_length + 1:
            raise RemoteProtocolError(
                f"{self.protocol}: line longer than {max_length} bytes", protocol=self.protocol
            )
        return self.take(end + 1 - self._start)

    def take_all(self) -> bytes:
        """Consume everything buffered."""
        out = bytes(self._data[self._start :])
        self._data.clear()
        self._start = 0
        return out
