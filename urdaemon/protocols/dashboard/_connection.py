"""``DashboardConnection``: one dashboard connection, for either party: lines in, typed events out."""

from __future__ import annotations

from collections import deque

from urdaemon.errors import LocalProtocolError, RemoteProtocolError
from urdaemon.protocols._buffer import Side
from urdaemon.protocols._codec import Codec
from urdaemon.protocols.dashboard._actions import Quit
from urdaemon.protocols.dashboard._events import (
    Banner,
    Command,
    CommandReceived,
    Event,
    ReplyLine,
    UnknownCommand,
)
from urdaemon.protocols.dashboard._parsing import parse_command
from urdaemon.protocols.dashboard._queries import Raw
from urdaemon.protocols.dashboard._wire import (
    MAX_LINE_BYTES,
    PROTOCOL,
    TRAILING_WHITESPACE,
    TRAILING_WHITESPACE_BYTES,
)

__all__ = ["DashboardConnection"]


def _encode_line(text: str, *, allow_empty: bool) -> bytes:
    """``text`` as one wire line; LocalProtocolError if the receiver could not read it back as sent."""
    if not text and not allow_empty:
        raise LocalProtocolError(f"{PROTOCOL}: an empty line is not a command", protocol=PROTOCOL)
    if "\n" in text or "\r" in text:
        raise LocalProtocolError(f"{PROTOCOL}: line break inside {text!r}", protocol=PROTOCOL)
    if text != text.rstrip(TRAILING_WHITESPACE):
        raise LocalProtocolError(
            f"{PROTOCOL}: {text!r} ends in whitespace, which the receiver strips (§3.1)", protocol=PROTOCOL
        )
    try:
        data = text.encode("utf-8")
    except UnicodeEncodeError as err:
        raise LocalProtocolError(f"{PROTOCOL}: {text!r} is not encodable: {err}", protocol=PROTOCOL) from err
    if len(data) > MAX_LINE_BYTES:
        raise LocalProtocolError(
            f"{PROTOCOL}: line of {len(data)} bytes exceeds {MAX_LINE_BYTES}", protocol=PROTOCOL
        )
    return data + b"\n"


class DashboardConnection(Codec["Command | Banner | ReplyLine", "Event"]):
    """One dashboard connection (§3), for either party: lines in, typed events out.

    Daemon side: ``send(Command)``; events ``Banner`` (first line) then one ``Reply`` per command, in
    order. Robot side: ``send(Banner())`` first, then one ``send(ReplyLine(text))`` per received
    command; events ``CommandReceived`` or ``UnknownCommand``.
    """

    PROTOCOL = PROTOCOL

    def __init__(self, side: Side) -> None:
        # One line plus its newline is the most that may wait undecoded.
        super().__init__(side, MAX_LINE_BYTES + 1)
        self._pending: deque[Command] = deque()  # daemon: sent, not yet answered
        self._owed = 0  # robot: received, not yet answered
        self._banner_done = False  # daemon: banner received; robot: banner sent
        self._quit_sent = False

    @property
    def pending(self) -> tuple[Command, ...]:
        """Daemon side: the commands sent and not yet answered, oldest first."""
        return tuple(self._pending)

    @property
    def replies_owed(self) -> int:
        """Robot side: how many received lines still wait for a reply."""
        return self._owed

    def _encode(self, message: Command | Banner | ReplyLine) -> None:
        """Queue a command (daemon side) or a banner/reply (robot side); LocalProtocolError if not allowed."""
        if self.side is Side.DAEMON:
            if isinstance(message, Banner | ReplyLine):
                raise LocalProtocolError(
                    f"{PROTOCOL}: the daemon side sends commands only", protocol=PROTOCOL
                )
            self._send_command(message)
        elif isinstance(message, Banner):
            self._send_banner(message)
        elif isinstance(message, ReplyLine):
            self._send_reply(message)
        else:
            raise LocalProtocolError(f"{PROTOCOL}: the robot side sends replies only", protocol=PROTOCOL)

    def _send_command(self, command: Command) -> None:
        if self._quit_sent:
            raise LocalProtocolError(f"{PROTOCOL}: quit was sent; the server closes", protocol=PROTOCOL)
        data = _encode_line(command.line, allow_empty=False)
        if not isinstance(command, Raw) and parse_command(command.line) != command:
            raise LocalProtocolError(
                f"{PROTOCOL}: the server would not read {command.line!r} as {command!r}", protocol=PROTOCOL
            )
        self._out += data
        self._pending.append(command)
        self._quit_sent = isinstance(command, Quit)

    def _send_banner(self, banner: Banner) -> None:
        if self._banner_done:
            raise LocalProtocolError(f"{PROTOCOL}: the banner was already sent", protocol=PROTOCOL)
        self._out += _encode_line(banner.text, allow_empty=True)
        self._banner_done = True

    def _send_reply(self, reply: ReplyLine) -> None:
        if not self._banner_done:
            raise LocalProtocolError(f"{PROTOCOL}: send the Banner before any reply", protocol=PROTOCOL)
        if not self._owed:
            raise LocalProtocolError(f"{PROTOCOL}: no command is waiting for a reply", protocol=PROTOCOL)
        self._out += _encode_line(reply.text, allow_empty=True)
        self._owed -= 1

    def _parse(self, events: list[Event]) -> None:
        while (raw := self._buffer.take_line(MAX_LINE_BYTES)) is not None:
            text = raw.rstrip(TRAILING_WHITESPACE_BYTES).decode("utf-8", errors="replace")
            events.append(self._on_line(text))
            self._consumed += len(raw)

    def _on_line(self, text: str) -> Event:
        if self.side is Side.ROBOT:
            self._owed += 1
            command = parse_command(text)
            return UnknownCommand(text) if command is None else CommandReceived(command, text)
        if not self._banner_done:
            self._banner_done = True
            return Banner(text)
        if not self._pending:
            raise RemoteProtocolError(
                f"{PROTOCOL}: reply {text[:80]!r} with no command waiting for one",
                protocol=PROTOCOL,
                offset=self._consumed,
            )
        return self._pending.popleft().decode_reply(text)
