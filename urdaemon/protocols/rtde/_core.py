"""What both RTDE parties share: the conversation's state, the package framing and feed loop, text messages.

``RtdeCore`` is the base of each side (``_daemon.DaemonSide``, ``_robot.RobotSide``); a side fills the two
tables, ``_handlers`` (package type -> decoder) and ``_senders`` (message type -> encoder).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Mapping
from types import MappingProxyType
from typing import Any

from urdaemon.errors import RemoteProtocolError
from urdaemon.protocols._buffer import Side
from urdaemon.protocols._codec import Codec, CodecState
from urdaemon.protocols.rtde._events import (
    ControllerVersion,
    Event,
    Message,
    SendText,
    Text,
    TextMessage,
    TextReceived,
)
from urdaemon.protocols.rtde._recipe import Recipe, RtdeValue
from urdaemon.protocols.rtde._state import TRANSITIONS, Request, RtdeState, Step
from urdaemon.protocols.rtde._wire import (
    HEADER,
    HEADER_BYTES,
    KIND_DATA,
    MAX_PACKAGE_BYTES,
    MAX_TEXT_FIELD_BYTES,
    PROTOCOL,
    SUPPORTED_PROTOCOL_VERSIONS,
    U8,
    Buf,
    PackageType,
    local_error,
    remote_error,
)

__all__ = ["RtdeCore"]


class RtdeCore(Codec[Message, Event]):
    """The job both parties share: state, framing, the feed loop, text messages; see RtdeConnection."""

    PROTOCOL = PROTOCOL
    """Names RTDE in the base codec's own errors (a failed connection, data after EOF), as in ours."""

    _handlers: dict[int, Callable[[Buf, int, int], Event]]
    """Package type -> decoder of a received package, for this side."""
    _senders: dict[type, Callable[[Any], None]]
    """Message type -> encoder of a message this side sends."""

    def __init__(self, side: Side, *, protocol_version: int = 2) -> None:
        """``protocol_version`` is the framing in force until the robot accepts a REQUEST_PROTOCOL_VERSION."""
        if not isinstance(side, Side):
            raise TypeError(f"side must be a Side, not {side!r}")
        if protocol_version not in SUPPORTED_PROTOCOL_VERSIONS:
            raise ValueError(
                f"RTDE protocol version {protocol_version} is not one of {SUPPORTED_PROTOCOL_VERSIONS}"
            )
        super().__init__(side, MAX_PACKAGE_BYTES)
        self._version = protocol_version
        self._state = RtdeState.IDLE
        self._package_offset = 0  # stream offset of the package being decoded, for error reports
        self._requests: deque[Request] = deque()
        self._output_recipe: Recipe | None = None
        self._output_recipe_id: int | None = None
        self._input_recipes: dict[int, Recipe] = {}
        self._input_recipe_id: int | None = None
        self._controller_version: ControllerVersion | None = None

    # -- public API ------------------------------------------------------------------------------

    @property
    def state(self) -> RtdeState:
        """Where the conversation stands."""
        return self._state

    @property
    def protocol_version(self) -> int:
        """The framing in force (1 or 2)."""
        return self._version

    @property
    def output_recipe(self) -> Recipe | None:
        """The output recipe in force (None until a setup succeeded)."""
        return self._output_recipe

    @property
    def output_recipe_id(self) -> int | None:
        """The robot-assigned id of the output recipe (None under v1 or without a recipe)."""
        return self._output_recipe_id

    @property
    def input_recipes(self) -> Mapping[int, Recipe]:
        """Every usable input recipe by its robot-assigned id (a controller keeps several)."""
        return MappingProxyType(self._input_recipes)

    @property
    def input_recipe_id(self) -> int | None:
        """The id of the input recipe set up last; InputData without an id uses it."""
        return self._input_recipe_id

    @property
    def controller_version(self) -> ControllerVersion | None:
        """The controller version once it was exchanged (daemon side: bounds the output frequency)."""
        return self._controller_version

    @property
    def pending_requests(self) -> tuple[PackageType, ...]:
        """Requests still waiting for their reply, oldest first (at most one on the daemon side)."""
        return tuple(request.kind for request in self._requests)

    def receive_data(self, data: bytes | bytearray | memoryview) -> list[Event]:
        """Feed received bytes (any split); the events of every package they complete, in order.

        The base's feed loop, specialised for the 500 Hz stream: whole packages are decoded straight
        from ``data``; only a partial one is copied into the buffer (always under its limit).
        """
        if self._stream is not CodecState.OPEN:  # inline: a call costs ~3 % of a data package
            self._check_receiving()
        events: list[Event] = []
        view = memoryview(data)
        try:
            pos = self._finish_buffered(view, events) if len(self._buffer) else 0
            pos = self._decode_whole(view, pos, events)
            if pos < len(view):
                self._buffer.feed(view[pos:])  # less than one package: always under the cap
        except RemoteProtocolError:
            self._fail()
            raise
        return events

    def receive_output(self, data: bytes | bytearray | memoryview) -> tuple[RtdeValue, ...] | None:
        """The 500 Hz fast path: the values when ``data`` is exactly one whole DATA_PACKAGE of the
        output recipe and nothing is buffered; otherwise ``None`` with nothing consumed, and the
        caller feeds ``data`` to ``receive_data`` (which also reports anything wrong with it)."""
        recipe = self._output_recipe
        if recipe is None or len(self._buffer) or (self._state, Step.OUTPUT_DATA) not in TRANSITIONS:
            return None
        size = len(data)
        start = HEADER_BYTES if self._version == 1 else HEADER_BYTES + 1  # v2: the recipe id first
        if (
            size != start + recipe.size
            or HEADER.unpack_from(data) != (size, KIND_DATA)
            or (start > HEADER_BYTES and data[HEADER_BYTES] != self._output_recipe_id)
        ):
            return None
        self._consumed += size
        return recipe.decode(data, start)

    def receive_eof(self) -> list[Event]:
        """The peer closed; RemoteProtocolError if it closed in the middle of a package."""
        if self._stream is CodecState.ERROR:
            raise remote_error("connection already failed", self._consumed)
        self._stream = CodecState.EOF
        if len(self._buffer):
            self._fail()
            raise remote_error(f"connection closed {len(self._buffer)} bytes into a package", self._consumed)
        return []

    def _encode(self, message: Message) -> None:
        """Queue ``message``; LocalProtocolError if this side may not send it now (nothing is queued)."""
        sender = self._senders.get(type(message))
        if sender is None:
            raise local_error(f"the {self.side.name} side does not send {type(message).__name__}")
        sender(message)

    def _fail(self) -> None:
        super()._fail()
        self._state = RtdeState.ERROR

    # -- framing ---------------------------------------------------------------------------------

    def _finish_buffered(self, view: memoryview, events: list[Event]) -> int:
        """Complete the package begun in an earlier chunk from the front of ``view``; bytes used."""
        buffer = self._buffer
        used = 0
        if len(buffer) < HEADER_BYTES:
            used = min(HEADER_BYTES - len(buffer), len(view))
            buffer.feed(view[:used])
            if len(buffer) < HEADER_BYTES:
                return used
        header = buffer.peek(HEADER_BYTES)
        assert header is not None  # checked just above
        size: int
        kind: int
        size, kind = HEADER.unpack(header)
        if size < HEADER_BYTES:
            raise self._bad_size(size)
        more = min(size - len(buffer), len(view) - used)
        buffer.feed(view[used : used + more])
        used += more
        package = buffer.take(size)
        if package is not None:
            events.append(self._dispatch(kind, package, HEADER_BYTES, size))
        return used

    def _decode_whole(self, view: memoryview, pos: int, events: list[Event]) -> int:
        """Decode the complete packages in ``view[pos:]`` in place; where the first incomplete one starts."""
        total = len(view)
        size: int
        kind: int
        while total - pos >= HEADER_BYTES:
            size, kind = HEADER.unpack_from(view, pos)
            if size < HEADER_BYTES:
                raise self._bad_size(size)
            end = pos + size
            if end > total:
                break
            events.append(self._dispatch(kind, view, pos + HEADER_BYTES, end))
            pos = end
        return pos

    def _dispatch(self, kind: int, buf: Buf, start: int, end: int) -> Event:
        self._package_offset = self._consumed
        handler = self._handlers.get(kind)
        if handler is None:
            raise self._bad(f"unknown package type {kind} ({chr(kind)!r})")
        event = handler(buf, start, end)
        self._consumed += end - start + HEADER_BYTES
        return event

    def _emit(self, kind: PackageType, payload: bytes) -> None:
        size = HEADER_BYTES + len(payload)
        if size > MAX_PACKAGE_BYTES:
            raise local_error(
                f"{kind.name} of {size} bytes exceeds the {MAX_PACKAGE_BYTES}-byte package limit"
            )
        self._out += HEADER.pack(size, kind)
        self._out += payload

    def _next(self, step: Step, *, local: bool) -> RtdeState:
        """The state after ``step``; out of order raises (Local for what we send, Remote for what we got)."""
        state = TRANSITIONS.get((self._state, step))
        if state is None:
            what = f"{step.name} is out of order in state {self._state.name}"
            raise local_error(what) if local else self._bad(what)
        return state

    def _bad(self, message: str) -> RemoteProtocolError:
        return remote_error(message, self._package_offset)

    def _bad_size(self, size: int) -> RemoteProtocolError:
        self._package_offset = self._consumed
        return self._bad(f"package size {size} is smaller than the {HEADER_BYTES}-byte header")

    # -- payload pieces shared by both sides ----------------------------------------------------

    def _flag(self, buf: Buf, start: int, end: int, kind: PackageType) -> bool:
        if end - start != 1:
            raise self._bad(f"{kind.name} reply has {end - start} payload bytes, expected 1")
        return buf[start] != 0  # bool on the wire: 0 false, anything else true (§0)

    def _empty(self, start: int, end: int, kind: PackageType) -> None:
        if end != start:
            raise self._bad(f"{kind.name} request has {end - start} payload bytes, expected none")

    def _parse_text(self, buf: Buf, start: int, end: int) -> tuple[int, str, str]:
        """(level, message, source) of a TEXT_MESSAGE payload in the framing in force."""
        if self._version == 1:
            if end <= start:
                raise self._bad("TEXT_MESSAGE without its level byte")
            level: int = buf[start]
            return level, str(buf[start + 1 : end], "utf-8", "replace"), ""
        at = start
        fields: list[str] = []
        for what in ("message", "source"):
            if at >= end:
                raise self._bad(f"TEXT_MESSAGE ends before its {what} length")
            n = buf[at]
            if at + 1 + n > end:
                raise self._bad(f"TEXT_MESSAGE {what} of {n} bytes overruns the package")
            fields.append(str(buf[at + 1 : at + 1 + n], "utf-8", "replace"))
            at += 1 + n
        if end - at != 1:
            raise self._bad(f"TEXT_MESSAGE has {end - at} bytes after its source, expected the level byte")
        return buf[at], fields[0], fields[1]

    def _text_payload(self, level: int, message: str, source: str) -> bytes:
        if not isinstance(level, int) or not 0 <= level <= 0xFF:
            raise local_error(f"text level {level!r} is not a uint8")
        try:
            message_bytes = message.encode("utf-8")
            source_bytes = source.encode("utf-8")
        except (AttributeError, UnicodeEncodeError) as err:
            raise local_error(f"text message and source must be encodable str: {err}") from err
        if self._version == 1:
            if source_bytes:
                raise local_error("a protocol v1 TEXT_MESSAGE has no source field; leave source empty")
            return U8.pack(level) + message_bytes
        if len(message_bytes) > MAX_TEXT_FIELD_BYTES or len(source_bytes) > MAX_TEXT_FIELD_BYTES:
            raise local_error(f"text message and source are limited to {MAX_TEXT_FIELD_BYTES} bytes each")
        return (
            U8.pack(len(message_bytes))
            + message_bytes
            + U8.pack(len(source_bytes))
            + source_bytes
            + U8.pack(level)
        )

    def _send_text(self, message: SendText | Text) -> None:
        pending = self._requests[0].kind if self._requests else None
        if self.side is Side.DAEMON and pending is PackageType.REQUEST_PROTOCOL_VERSION:
            # which framing the robot reads it in depends on when it answers: wait for the reply
            raise local_error("no TEXT_MESSAGE while a protocol version change is pending")
        self._emit(
            PackageType.TEXT_MESSAGE, self._text_payload(message.level, message.message, message.source)
        )

    def _on_text_from_robot(self, buf: Buf, start: int, end: int) -> TextMessage:
        return TextMessage(*self._parse_text(buf, start, end))

    def _on_text_from_client(self, buf: Buf, start: int, end: int) -> TextReceived:
        return TextReceived(*self._parse_text(buf, start, end))

    def _types(self, buf: Buf, start: int, end: int, names: int, allowed: frozenset[str]) -> tuple[str, ...]:
        """The comma-joined type answers of a setup reply, one per requested name."""
        try:
            types = tuple(str(buf[start:end], "ascii").split(","))
        except UnicodeDecodeError:
            raise self._bad("setup reply types are not ASCII") from None
        if len(types) != names:
            raise self._bad(f"setup reply has {len(types)} types for {names} requested names")
        for rtde_type in types:
            if rtde_type not in allowed:
                raise self._bad(f"setup reply has an unknown type {rtde_type[:40]!r}")
        return types
