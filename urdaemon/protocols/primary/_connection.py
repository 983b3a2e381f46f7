"""``PrimaryConnection``: one primary/secondary connection, for either party, and the packages it writes."""

from __future__ import annotations

import struct
from typing import Literal

from urdaemon.errors import RemoteProtocolError
from urdaemon.protocols._buffer import Side
from urdaemon.protocols._codec import Codec, CodecState
from urdaemon.protocols.primary._events import (
    CommandReceived,
    OtherPackage,
    OtherRobotMessage,
    PrimaryEvent,
    PrimaryMessage,
    ProgramReceived,
    RobotMessage,
    RobotState,
    Script,
    SubPackage,
    UnknownSubPackage,
)
from urdaemon.protocols.primary._layouts import (
    MESSAGE_DECODERS,
    ROBOT_MESSAGE_CLASSES,
    SUB_DECODERS,
    SUB_ENCODERS,
    encode_message,
)
from urdaemon.protocols.primary._script import BLOCK_END, BLOCK_START, encode_script
from urdaemon.protocols.primary._wire import (
    HEADER,
    HEADER_BYTES,
    MAX_PACKAGE_BYTES,
    MAX_SCRIPT_BYTES,
    MESSAGE_HEADER,
    PROTOCOL,
    SUB_HEADER,
    Malformed,
    PackageType,
    local_error,
)

__all__ = ["PrimaryConnection"]


class PrimaryConnection(Codec["PrimaryMessage", "PrimaryEvent"]):
    """One primary/secondary-interface TCP connection, for either party; see the package docstring."""

    __slots__ = ("_block_bytes", "_block_kind", "_block_lines", "_block_name", "_parse_step")

    PROTOCOL = PROTOCOL

    def __init__(self, side: Side) -> None:
        super().__init__(side, MAX_PACKAGE_BYTES if side is Side.DAEMON else MAX_SCRIPT_BYTES)
        # robot side: the open top-level block, if any
        self._block_kind: Literal["def", "sec"] | None = None
        self._block_name = ""
        self._block_lines: list[str] = []
        self._block_bytes = 0
        self._parse_step = self._parse_packages if side is Side.DAEMON else self._parse_lines

    def receive_eof(self) -> list[PrimaryEvent]:
        """The peer closed; RemoteProtocolError if it closed inside a package (daemon side).

        On the robot side an unterminated line or unclosed block is dropped: the controller runs only
        newline-terminated text (§2.4 step 1).
        """
        if self._stream is CodecState.ERROR:
            raise self._remote("connection already failed")
        self._stream = CodecState.EOF
        if self.side is Side.DAEMON and len(self._buffer):
            self._fail()
            raise self._error(f"connection closed {len(self._buffer)} bytes into a package", 0)
        return []

    def _parse(self, events: list[PrimaryEvent]) -> None:
        self._parse_step(events)

    def _encode(self, message: PrimaryMessage) -> None:
        """Script from the daemon, packages from the robot; else LocalProtocolError."""
        if self.side is Side.DAEMON:
            if not isinstance(message, Script):
                raise local_error(f"the daemon sends only Script, not {message!r}")
            self._queue(encode_script(message.text))
            return
        if isinstance(message, Script):
            raise local_error("the robot side does not send Script")
        try:
            self._queue(_encode_package(message))
        except (struct.error, OverflowError, TypeError) as err:
            raise local_error(f"cannot encode {message!r}: {err}") from err

    # --- daemon side: packages ---

    def _error(self, message: str, offset: int) -> RemoteProtocolError:
        return RemoteProtocolError(f"primary: {message}", protocol=PROTOCOL, offset=self._consumed + offset)

    def _parse_packages(self, events: list[PrimaryEvent]) -> None:
        while (header := self._buffer.peek(HEADER_BYTES)) is not None:
            length, kind = HEADER.unpack(header)
            if not HEADER_BYTES <= length <= MAX_PACKAGE_BYTES:
                raise self._error(f"package length {length} outside [{HEADER_BYTES}, {MAX_PACKAGE_BYTES}]", 0)
            package = self._buffer.take(length)
            if package is None:
                return
            if kind == PackageType.ROBOT_STATE:
                events.append(self._decode_robot_state(package))
            elif kind == PackageType.ROBOT_MESSAGE:
                events.append(self._decode_robot_message(package))
            else:
                events.append(OtherPackage(kind, package[HEADER_BYTES:]))
            self._consumed += length

    def _decode_robot_state(self, package: bytes) -> RobotState:
        subs: list[SubPackage] = []
        pos = HEADER_BYTES
        while pos < len(package):
            if len(package) - pos < HEADER_BYTES:
                raise self._error("ROBOT_STATE ends inside a sub-package header", pos)
            length, kind = SUB_HEADER.unpack_from(package, pos)
            end = pos + length
            if length < HEADER_BYTES or end > len(package):
                raise self._error(f"sub-package {kind} length {length} does not fit the package", pos)
            body = package[pos + HEADER_BYTES : end]
            decode = SUB_DECODERS.get(kind)
            if decode is None:
                subs.append(UnknownSubPackage(kind, body))
            else:
                try:
                    subs.append(decode(body))
                except struct.error as err:
                    raise self._error(f"sub-package {kind} body of {len(body)} bytes too short", pos) from err
            pos = end
        return RobotState(tuple(subs))

    def _decode_robot_message(self, package: bytes) -> RobotMessage:
        if len(package) < HEADER_BYTES + MESSAGE_HEADER.size:
            raise self._error(f"ROBOT_MESSAGE of {len(package)} bytes has no message header", 0)
        timestamp, source, kind = MESSAGE_HEADER.unpack_from(package, HEADER_BYTES)
        payload = package[HEADER_BYTES + MESSAGE_HEADER.size :]
        decode = MESSAGE_DECODERS.get(kind)
        if decode is None:
            return OtherRobotMessage(kind, payload, timestamp=timestamp, source=source)
        try:
            return decode(payload, timestamp, source)
        except (struct.error, Malformed) as err:
            raise self._error(f"robot message {kind} of {len(payload)} bytes is malformed: {err}", 0) from err

    # --- robot side: script lines ---

    def _parse_lines(self, events: list[PrimaryEvent]) -> None:
        while (raw := self._buffer.take_line(MAX_SCRIPT_BYTES)) is not None:
            # Non-ASCII text is the controller's compiler's to refuse (with its line and column), not a
            # reason to drop the connection: it is passed on as read (UTF-8; other bytes kept as
            # surrogate escapes), one character per character sent.
            line = raw.decode("utf-8", "surrogateescape").removesuffix("\n").removesuffix("\r")
            event = self._on_line(line)
            if event is not None:
                events.append(event)
            self._consumed += len(raw)

    def _on_line(self, line: str) -> PrimaryEvent | None:
        if self._block_kind is None:
            start = BLOCK_START.fullmatch(line)
            if start is not None:
                self._block_kind = "def" if start[1] == "def" else "sec"
                self._block_name = start[2]
                self._block_lines = [line]
                self._block_bytes = len(line) + 1
                return None
            stripped = line.strip()
            if not stripped or stripped.startswith("#"):
                return None
            return CommandReceived(stripped)
        self._block_lines.append(line)
        self._block_bytes += len(line) + 1
        if self._block_bytes > MAX_SCRIPT_BYTES:
            raise self._error(f"program {self._block_name} longer than {MAX_SCRIPT_BYTES} bytes", 0)
        if BLOCK_END.fullmatch(line) is None:
            return None
        event = ProgramReceived(self._block_kind, self._block_name, "\n".join(self._block_lines) + "\n")
        self._block_kind, self._block_lines, self._block_bytes = None, [], 0
        return event


def _frame(kind: int, body: bytes) -> bytes:
    length = HEADER_BYTES + len(body)
    if length > MAX_PACKAGE_BYTES:
        raise local_error(f"package of {length} bytes > {MAX_PACKAGE_BYTES}")
    return HEADER.pack(length, kind) + body


def _encode_subpackage(sub: SubPackage) -> bytes:
    if isinstance(sub, UnknownSubPackage):
        if sub.type in SUB_DECODERS:
            raise local_error(f"sub-package {sub.type} is modelled; send its class")
        kind, body = sub.type, bytes(sub.body)
    else:
        entry = SUB_ENCODERS.get(type(sub))
        if entry is None:
            raise local_error(f"{sub!r} is not a sub-package")
        kind, body = entry[0], entry[1](sub)
    return SUB_HEADER.pack(HEADER_BYTES + len(body), kind) + body


def _encode_package(message: PrimaryMessage) -> bytes:
    if isinstance(message, RobotState):
        return _frame(PackageType.ROBOT_STATE, b"".join(_encode_subpackage(s) for s in message.subpackages))
    if isinstance(message, ROBOT_MESSAGE_CLASSES):
        kind, body = encode_message(message)
        return _frame(
            PackageType.ROBOT_MESSAGE, MESSAGE_HEADER.pack(message.timestamp, message.source, kind) + body
        )
    if isinstance(message, OtherPackage):
        if message.type in (PackageType.ROBOT_STATE, PackageType.ROBOT_MESSAGE):
            raise local_error(f"package type {message.type} is modelled")
        return _frame(message.type, bytes(message.body))
    raise local_error(f"cannot send {message!r}")
