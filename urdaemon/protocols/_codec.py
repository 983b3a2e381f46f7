"""The base every stream codec shares: its side, its error state, the receive buffer and the feed loop.

A codec subclasses ``Codec``, sets ``PROTOCOL`` and implements ``_parse(events)``: take every complete
unit (package, line, frame) out of ``self._buffer``, append one event per unit, leave a partial unit
buffered. ``receive_data`` is then the one feed loop of all codecs: it feeds at most what the buffer's
limit allows, parses, and repeats, so a large chunk of complete units is fine and one over-long
partial unit fails as soon as the limit fills. The first ``RemoteProtocolError`` moves the codec's
``_stream`` to ``CodecState.ERROR``, in which every later ``receive_data``, ``receive_eof`` and
``send`` raises.

``send`` checks the state and calls the codec's ``_encode(message)``, which appends to the one
outgoing buffer through ``_queue``; ``data_to_send`` returns and clears it. ``_remote`` and
``_local`` build the two errors with the protocol name and, for remote ones, the stream offset.
"""

from __future__ import annotations

import enum
from typing import ClassVar, Generic, NoReturn, TypeVar

from urdaemon.errors import LocalProtocolError, RemoteProtocolError
from urdaemon.protocols._buffer import ReceiveBuffer, Side

__all__ = ["Codec", "CodecState"]

EventT = TypeVar("EventT")
MessageT = TypeVar("MessageT")


class CodecState(enum.Enum):
    """Where a codec's byte stream stands: OPEN, the peer closed (EOF), or broken (ERROR, final)."""

    OPEN = "open"
    EOF = "eof"
    ERROR = "error"


class Codec(Generic[MessageT, EventT]):
    """Side, state, receive buffer (capped at ``limit`` bytes), outgoing buffer and the feed loop."""

    __slots__ = ("_buffer", "_consumed", "_out", "_stream", "side")

    PROTOCOL: ClassVar[str] = "codec"

    def __init__(self, side: Side, limit: int) -> None:
        self.side = side
        self._buffer = ReceiveBuffer(self.PROTOCOL, limit)
        self._out = bytearray()
        self._stream = CodecState.OPEN
        self._consumed = 0  # stream bytes of complete units decoded so far, for error offsets

    # -- public API -----------------------------------------------------------------------------------

    def receive_data(self, data: bytes | bytearray | memoryview) -> list[EventT]:
        """Feed received bytes (any split); the events completed so far. RemoteProtocolError on bad bytes."""
        self._check_receiving()
        events: list[EventT] = []
        view = memoryview(data).cast("B")
        buffer = self._buffer
        try:
            while True:
                self._parse(events)
                if not view:
                    return events
                room = buffer.limit - len(buffer)
                if room <= 0:
                    message = f"more than {buffer.limit} bytes without a complete unit"
                    raise self._remote(message, self._consumed)
                buffer.feed(view[:room])
                view = view[room:]
        except RemoteProtocolError:
            self._fail()
            raise

    def send(self, message: MessageT) -> None:
        """Queue one message; LocalProtocolError if it is illegal, not ours to send, or the codec failed."""
        if self._stream is CodecState.ERROR:
            raise self._local("connection already failed")
        self._encode(message)

    def data_to_send(self) -> bytes:
        """Return and clear the queued bytes."""
        out = bytes(self._out)
        self._out.clear()
        return out

    # -- for subclasses -------------------------------------------------------------------------------

    def _parse(self, events: list[EventT]) -> None:
        """Move every complete unit in ``self._buffer`` to ``events``; RemoteProtocolError on bad bytes."""
        raise NotImplementedError

    def _encode(self, message: MessageT) -> None:
        """Append one message's bytes with ``_queue``; LocalProtocolError if it cannot be sent."""
        raise NotImplementedError

    def _fail(self) -> None:
        """Enter the final error state (a codec with its own state table marks it there too)."""
        self._stream = CodecState.ERROR

    def _queue(self, data: bytes | bytearray) -> None:
        self._out += data

    def _check_receiving(self) -> None:
        if self._stream is CodecState.ERROR:
            raise self._remote("connection already failed")
        if self._stream is CodecState.EOF:
            self._fail_local("data fed after receive_eof()")

    def _remote(self, message: str, offset: int | None = None) -> RemoteProtocolError:
        """A RemoteProtocolError; ``offset`` is the stream position of the bad unit, if known."""
        return RemoteProtocolError(f"{self.PROTOCOL}: {message}", protocol=self.PROTOCOL, offset=offset)

    def _local(self, message: str) -> LocalProtocolError:
        return LocalProtocolError(f"{self.PROTOCOL}: {message}", protocol=self.PROTOCOL)

    def _fail_local(self, message: str) -> NoReturn:
        raise self._local(message)
