"""Script sender (port 50002): the External Control URCap fetches the control script (docs/protocols.md §4.3).

Used in URCap mode only (§5.8). The URCap dials the daemon and the exchange is plain text::

    URCap  → daemon   request_program\\n                         (ASCII, exactly these 16 bytes)
    daemon → URCap    <the whole script text>\\n                 (UTF-8, one write, sent at once)

The URCap reads the first line blocking, then further lines only while data is already buffered,
then closes; so the daemon must send the whole text in one go as soon as the request arrives.

``ScriptSenderConnection(Side.DAEMON)`` yields ``ProgramRequested`` for each line that is exactly
``request_program`` and ``UnknownRequest(line)`` for any other line (urcl answers nothing to those);
lines longer than ``MAX_REQUEST_LINE_BYTES`` are a ``RemoteProtocolError``. ``send(Program(text))``
answers one pending request with the text plus one ``\\n`` (as urcl, even if the text already ends in
one); sending a program nobody asked for is a ``LocalProtocolError``. urcl matches the request against
one whole ``recv`` chunk; we match complete lines instead, which is the same for the real URCap and
does not depend on TCP segmentation.

``ScriptSenderConnection(Side.ROBOT)`` plays the URCap: ``send(RequestProgram())`` once, then feed the
answer to ``receive_data`` (it only accumulates, up to ``MAX_PROGRAM_BYTES``), and call
``receive_eof()`` when the daemon closes or ``close()`` when you stop reading (as the URCap does once
nothing more is buffered). Either returns the final event: ``ProgramReceived(text)`` (the text without
the sender's trailing ``\\n``) when what arrived ends with a newline, else ``ProgramIncomplete(data)``
(nothing, or cut off: the real URCap would block or show its "could not be established" popup).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final, TypeAlias

from urdaemon.protocols._buffer import Side
from urdaemon.protocols._codec import Codec, CodecState

__all__ = [
    "MAX_PROGRAM_BYTES",
    "MAX_REQUEST_LINE_BYTES",
    "PROTOCOL",
    "REQUEST_LINE",
    "SCRIPT_SENDER_PORT",
    "Program",
    "ProgramIncomplete",
    "ProgramReceived",
    "ProgramRequested",
    "RequestProgram",
    "ScriptSenderConnection",
    "ScriptSenderEvent",
    "ScriptSenderMessage",
    "UnknownRequest",
]

PROTOCOL: Final = "script_sender"
SCRIPT_SENDER_PORT: Final = 50002
"""The script sender's usual port, on the daemon's host (§0; the URCap is told which)."""

REQUEST_LINE: Final = b"request_program\n"
"""The URCap's request, byte for byte (§4.3 step 1)."""
MAX_REQUEST_LINE_BYTES: Final = 256
"""Longest request line the daemon side accepts, B without the newline; the only real request is 15."""
MAX_PROGRAM_BYTES: Final = 4 * 1024 * 1024
"""Largest script the robot side accepts, B: urcl's external_control.urscript is about 52 kB."""


# -- messages and events -------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class RequestProgram:
    """(ROBOT side sends) ask for the control script: ``request_program\\n``."""


@dataclass(frozen=True, slots=True)
class Program:
    """(DAEMON side sends) the whole control script; one ``\\n`` is appended on the wire."""

    text: str


@dataclass(frozen=True, slots=True)
class ProgramRequested:
    """(DAEMON side) the URCap asked for the script; answer with ``send(Program(text))``."""


@dataclass(frozen=True, slots=True)
class UnknownRequest:
    """(DAEMON side) a line other than ``request_program`` (without its newline); urcl ignores it."""

    line: bytes


@dataclass(frozen=True, slots=True)
class ProgramReceived:
    """(ROBOT side) the script as sent, without the one trailing newline the sender added."""

    text: str


@dataclass(frozen=True, slots=True)
class ProgramIncomplete:
    """(ROBOT side) the connection ended without a newline-terminated script; all bytes received."""

    data: bytes


ScriptSenderMessage: TypeAlias = RequestProgram | Program
"""A message either side may send (RequestProgram: ROBOT, Program: DAEMON)."""
ScriptSenderEvent: TypeAlias = ProgramRequested | UnknownRequest | ProgramReceived | ProgramIncomplete
"""An event of either side."""


class ScriptSenderConnection(Codec[ScriptSenderMessage, ScriptSenderEvent]):
    """One script-sender connection (§4.3), for either party (DAEMON = urcl's server, ROBOT = the URCap)."""

    __slots__ = ("_pending", "_requested")

    PROTOCOL = PROTOCOL

    def __init__(self, side: Side) -> None:
        limit = MAX_REQUEST_LINE_BYTES + 1 if side is Side.DAEMON else MAX_PROGRAM_BYTES
        super().__init__(side, limit)
        self._pending = 0  # DAEMON: requests not answered yet
        self._requested = False  # ROBOT: request sent

    # -- public API -----------------------------------------------------------------------------------

    def receive_eof(self) -> list[ScriptSenderEvent]:
        """The peer closed: the final events (see ``close``)."""
        return self.close()

    def close(self) -> list[ScriptSenderEvent]:
        """We stop reading. ROBOT: ``ProgramReceived`` or ``ProgramIncomplete``. DAEMON: a final
        unterminated line as ``UnknownRequest`` (urcl only answers a complete ``request_program\\n``)."""
        self._check_receiving()
        self._stream = CodecState.EOF
        data = self._buffer.take_all()
        if self.side is Side.DAEMON:
            return [UnknownRequest(data)] if data else []
        if not data.endswith(b"\n"):
            return [ProgramIncomplete(data)]
        try:
            return [ProgramReceived(data[:-1].decode("utf-8"))]
        except UnicodeDecodeError as err:
            self._fail()
            raise self._remote("the program is not UTF-8 text", err.start) from None

    # -- internals ------------------------------------------------------------------------------------

    def _parse(self, events: list[ScriptSenderEvent]) -> None:
        # DAEMON: one event per complete line. ROBOT: the program accumulates until close().
        if self.side is Side.ROBOT:
            if len(self._buffer) and not self._requested:
                raise self._remote("the daemon sent data before request_program", 0)
            return
        while (line := self._buffer.take_line(MAX_REQUEST_LINE_BYTES)) is not None:
            if line == REQUEST_LINE:
                self._pending += 1
                events.append(ProgramRequested())
            else:
                events.append(UnknownRequest(line[:-1]))

    def _encode(self, message: ScriptSenderMessage) -> None:
        if self._stream is CodecState.EOF:
            self._fail_local("connection is closed")
        if self.side is Side.DAEMON and type(message) is Program:
            self._send_program(message)
        elif self.side is Side.ROBOT and type(message) is RequestProgram:
            if self._requested:
                self._fail_local("the URCap requests the program once per connection")
            self._requested = True
            self._queue(REQUEST_LINE)
        else:
            self._fail_local(f"the {self.side.value} side does not send {type(message).__name__}")

    def _send_program(self, message: Program) -> None:
        if not isinstance(message.text, str) or not message.text:
            self._fail_local("the program must be a non-empty str")
        if self._pending == 0:
            self._fail_local("no request_program to answer (urcl only answers requests)")
        try:
            payload = message.text.encode("utf-8")
        except UnicodeEncodeError:
            self._fail_local("the program is not encodable as UTF-8")
        self._pending -= 1
        self._queue(payload + b"\n")
