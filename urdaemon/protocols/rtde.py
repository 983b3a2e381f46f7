"""RTDE, the Real-Time Data Exchange on port 30004, as a sans-IO codec for both parties (reference §1).

Every package, both directions (§1.1), big-endian::

    offset 0        2        3
           +--------+--------+------------------------------+
           | size   | type   | payload: size - 3 bytes      |
           +--------+--------+------------------------------+
             uint16   uint8    size counts the 3-byte header
                      ASCII letter, see PackageType

Payloads (§1.3; "v1"/"v2" is the protocol version in force, §1.4)::

    type  daemon -> robot (request)           robot -> daemon (reply)
    V     uint16 version                      uint8 accepted
    v     (empty)                             uint32 major, minor, bugfix, build
    O     v2: double Hz, then names           v2: uint8 output recipe id, then types
          v1: names                           v1: types
    I     names                               uint8 input recipe id, then types
    S     (empty)                             uint8 accepted
    P     (empty)                             uint8 accepted
    U     uint8 input recipe id, values       v2: uint8 output recipe id, values;  v1: values
    M     text (either direction)             v2: uint8 n, n bytes message, uint8 m, m bytes
                                              source, uint8 level;  v1: uint8 level, text to the end

``names`` / ``types`` are ASCII joined by ``,`` with no terminator; names at most 2048 bytes (UR's
RTDE guide). ``values`` are the recipe's fields packed back to back in recipe order (§1.5).

The version in force is the one the robot accepted in reply to REQUEST_PROTOCOL_VERSION; until
then it is the ``protocol_version`` the connection was built with.
"""

from __future__ import annotations

import enum
import math
import operator
import struct
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, Final, TypeAlias

from urdaemon.errors import LocalProtocolError, RemoteProtocolError
from urdaemon.protocols._buffer import Side
from urdaemon.protocols._codec import Codec, CodecState
from urdaemon.protocols.rtde_variables import (
    BOOL,
    DOUBLE,
    IN_USE,
    INT32,
    NOT_FOUND,
    RTDE_TYPES,
    UINT8,
    UINT32,
    UINT64,
    VECTOR3D,
    VECTOR6D,
    VECTOR6INT32,
    VECTOR6UINT32,
)

__all__ = [
    "CB3_MAX_FREQUENCY_HZ",
    "E_SERIES_FIRST_MAJOR",
    "E_SERIES_MAX_FREQUENCY_HZ",
    "HEADER_BYTES",
    "MAX_PACKAGE_BYTES",
    "MAX_RECIPE_NAMES_BYTES",
    "MAX_UNANSWERED_REQUESTS",
    "PROTOCOL",
    "RTDE_PORT",
    "SUPPORTED_PROTOCOL_VERSIONS",
    "ControllerVersion",
    "ControllerVersionReply",
    "ControllerVersionRequested",
    "DaemonEvent",
    "DaemonMessage",
    "DataPackage",
    "Event",
    "GetControllerVersion",
    "InputData",
    "InputDataReceived",
    "InputsConfigured",
    "InputsSetup",
    "Message",
    "MessageLevel",
    "OutputData",
    "OutputsConfigured",
    "OutputsSetup",
    "PackageType",
    "Pause",
    "PauseAccept",
    "PauseReply",
    "PauseRequested",
    "ProtocolVersionAccept",
    "ProtocolVersionReply",
    "ProtocolVersionRequested",
    "Recipe",
    "RequestProtocolVersion",
    "RobotEvent",
    "RobotMessage",
    "RtdeConnection",
    "RtdeState",
    "RtdeValue",
    "SendText",
    "SetupInputs",
    "SetupInputsRequested",
    "SetupOutputs",
    "SetupOutputsRequested",
    "Start",
    "StartAccept",
    "StartReply",
    "StartRequested",
    "Text",
    "TextMessage",
    "TextReceived",
    "max_frequency",
]

PROTOCOL: Final = "rtde"
RTDE_PORT: Final = 30004
"""TCP port of the RTDE interface on the robot (§0)."""
HEADER_BYTES: Final = 3
MAX_PACKAGE_BYTES: Final = 0xFFFF
"""Largest package, header included: the size field is a uint16 (§1.1); also the receive-buffer cap."""
MAX_RECIPE_NAMES_BYTES: Final = 2048
"""Longest comma-joined name list in SETUP_OUTPUTS / SETUP_INPUTS, in bytes (UR's RTDE guide, §1.3)."""
MAX_TEXT_FIELD_BYTES: Final = 0xFF
"""Longest message or source of a v2 TEXT_MESSAGE: each has a uint8 length prefix (§1.3)."""
MAX_UNANSWERED_REQUESTS: Final = 64
"""Requests a client may pipeline before the robot side calls it a flood; real clients wait for each reply."""
SUPPORTED_PROTOCOL_VERSIONS: Final = (1, 2)
"""Framings this codec speaks; urcl and UR's client ask for 2 and fall back to 1 (§1.4)."""
CB3_MAX_FREQUENCY_HZ: Final = 125.0
"""Highest output rate of a CB3 controller, Hz (§1.6 step 4)."""
E_SERIES_MAX_FREQUENCY_HZ: Final = 500.0
"""Highest output rate of e-Series, UR-series and PolyScope X controllers, Hz (§1.6 step 4)."""
E_SERIES_FIRST_MAJOR: Final = 5
"""First controller major version with the 500 Hz loop (urcl: major < 5 means CB3)."""

_HEADER: Final = struct.Struct(">HB")
_U8: Final = struct.Struct(">B")
_U16: Final = struct.Struct(">H")
_F64: Final = struct.Struct(">d")
_VERSION4: Final = struct.Struct(">IIII")

_STRUCT_CODES: Final[Mapping[str, str]] = MappingProxyType(
    {
        BOOL: "?",
        UINT8: "B",
        UINT32: "I",
        UINT64: "Q",
        INT32: "i",
        DOUBLE: "d",
        VECTOR3D: "3d",
        VECTOR6D: "6d",
        VECTOR6INT32: "6i",
        VECTOR6UINT32: "6I",
    }
)
_VECTOR_LENGTHS: Final[Mapping[str, int]] = MappingProxyType(
    {VECTOR3D: 3, VECTOR6D: 6, VECTOR6INT32: 6, VECTOR6UINT32: 6}
)
_OUTPUT_ANSWERS: Final = RTDE_TYPES | {NOT_FOUND}
_INPUT_ANSWERS: Final = RTDE_TYPES | {NOT_FOUND, IN_USE}

RtdeValue: TypeAlias = bool | int | float | tuple[float, ...] | tuple[int, ...]
"""One decoded field: a scalar, or a tuple for the VECTOR types."""
_Buf: TypeAlias = bytes | bytearray | memoryview


def max_frequency(controller_major: int) -> float:
    """Highest output frequency [Hz] a controller of this major version streams at (§1.6 step 4)."""
    return CB3_MAX_FREQUENCY_HZ if controller_major < E_SERIES_FIRST_MAJOR else E_SERIES_MAX_FREQUENCY_HZ


class PackageType(enum.IntEnum):
    """The package type byte (§1.2): the same code for a request and its reply."""

    REQUEST_PROTOCOL_VERSION = ord("V")
    GET_URCONTROL_VERSION = ord("v")
    TEXT_MESSAGE = ord("M")
    DATA_PACKAGE = ord("U")
    CONTROL_PACKAGE_SETUP_OUTPUTS = ord("O")
    CONTROL_PACKAGE_SETUP_INPUTS = ord("I")
    CONTROL_PACKAGE_START = ord("S")
    CONTROL_PACKAGE_PAUSE = ord("P")
    # READ_PROPERTIES ('R') exists only with protocol v3 in UR's newest client (§1.12): not spoken here.


_KIND_DATA: Final = int(PackageType.DATA_PACKAGE)


class MessageLevel(enum.IntEnum):
    """TEXT_MESSAGE severity levels as UR's RTDE client names them (§1.3); other values pass through."""

    EXCEPTION = 0
    ERROR = 1
    WARNING = 2
    INFO = 3


class Recipe:
    """RTDE fields compiled once into a ``struct.Struct``: encodes and decodes DATA_PACKAGE bodies."""

    __slots__ = ("_lengths", "_regroup", "_struct", "names", "size", "types")

    def __init__(self, names: Sequence[str], types: Sequence[str]) -> None:
        if len(names) != len(types):
            raise ValueError(f"{len(names)} names but {len(types)} types")
        if not types:
            raise ValueError("a recipe needs at least one field")
        for name, rtde_type in zip(names, types, strict=True):
            if rtde_type not in RTDE_TYPES:
                # NOT_FOUND / IN_USE are answers to a setup request: reported, never decoded.
                raise ValueError(f"{name!r} has no RTDE value type: {rtde_type!r}")
        self.names: tuple[str, ...] = tuple(names)
        self.types: tuple[str, ...] = tuple(types)
        self._struct = struct.Struct(">" + "".join(_STRUCT_CODES[t] for t in types))
        self.size: int = self._struct.size
        """Bytes of the packed values (without header or recipe id)."""
        # struct returns vectors as loose items; an itemgetter of one key per field (an index, or a
        # slice for a vector) regroups them in C, ~3x faster than a Python-level map over the keys
        keys: list[int | slice] = []
        at = 0
        for t in types:
            n = _VECTOR_LENGTHS.get(t, 0)
            keys.append(slice(at, at + n) if n else at)
            at += n or 1
        self._regroup: Callable[[tuple[Any, ...]], tuple[RtdeValue, ...]] | None = None
        if at != len(types):
            # itemgetter of one key returns the item itself; a one-field recipe is wrapped again
            getter = operator.itemgetter(*keys)
            self._regroup = getter if len(keys) > 1 else lambda flat: (getter(flat),)
        self._lengths = tuple(_VECTOR_LENGTHS.get(t, 0) for t in types)

    def __repr__(self) -> str:
        return f"Recipe({len(self.names)} fields, {self.size} bytes)"

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Recipe) and (self.names, self.types) == (other.names, other.types)

    def __hash__(self) -> int:
        return hash((self.names, self.types))

    def index(self, name: str) -> int:
        """Position of ``name`` in the recipe (and so in every decoded tuple); ValueError if absent."""
        return self.names.index(name)

    def decode(self, payload: _Buf, offset: int = 0) -> tuple[RtdeValue, ...]:
        """The values at ``payload[offset:]`` in recipe order; the caller checked ``size`` bytes are there."""
        regroup = self._regroup
        if regroup is None:
            return self._struct.unpack_from(payload, offset)
        return regroup(self._struct.unpack_from(payload, offset))

    def encode(self, values: Sequence[Any]) -> bytes:
        """``values`` in recipe order packed for the wire; ValueError if they do not fit the types."""
        if len(values) != len(self._lengths):
            raise ValueError(f"recipe has {len(self._lengths)} fields, got {len(values)} values")
        try:
            if self._regroup is None:
                return self._struct.pack(*values)
            flat: list[Any] = []
            for value, n in zip(values, self._lengths, strict=True):
                if n:
                    if len(value) != n:
                        raise ValueError(f"a {n}-vector field got {len(value)} values")
                    flat.extend(value)
                else:
                    flat.append(value)
            return self._struct.pack(*flat)
        except (struct.error, TypeError) as err:
            raise ValueError(f"values do not fit the recipe types: {err}") from err


# -- messages the DAEMON sends ------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class RequestProtocolVersion:
    """Ask the robot to switch to protocol ``version`` (V); answered by ProtocolVersionReply."""

    version: int


@dataclass(frozen=True, slots=True)
class GetControllerVersion:
    """Ask for the controller software version (v); answered by ControllerVersion."""


@dataclass(frozen=True, slots=True)
class SetupOutputs:
    """Ask for the output recipe ``names`` at ``frequency`` Hz (O); v1 has no frequency: pass None."""

    frequency: float | None
    names: tuple[str, ...]


@dataclass(frozen=True, slots=True)
class SetupInputs:
    """Ask for an input recipe of ``names`` (I); answered by InputsConfigured."""

    names: tuple[str, ...]


@dataclass(frozen=True, slots=True)
class Start:
    """Ask the robot to start streaming outputs (S); answered by StartReply."""


@dataclass(frozen=True, slots=True)
class Pause:
    """Ask the robot to stop streaming outputs (P); answered by PauseReply."""


@dataclass(frozen=True, slots=True)
class InputData:
    """Input values in recipe order (U), for the input recipe ``recipe_id`` (None: the latest configured)."""

    values: tuple[RtdeValue, ...]
    recipe_id: int | None = None


@dataclass(frozen=True, slots=True)
class SendText:
    """A text message to the controller (M)."""

    level: int
    message: str
    source: str
    """Must be empty under protocol v1, whose layout has no source."""


# -- events the DAEMON receives -----------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class ProtocolVersionReply:
    """The robot's answer to RequestProtocolVersion; if accepted, that version is in force from now on."""

    accepted: bool


@dataclass(frozen=True, slots=True)
class ControllerVersion:
    """The controller software version, e.g. 5.12.2.1101534."""

    major: int
    minor: int
    bugfix: int
    build: int


@dataclass(frozen=True, slots=True)
class OutputsConfigured:
    """The robot's answer to SetupOutputs: a type per name; the recipe is usable iff nothing is not_found."""

    recipe_id: int | None
    """None under protocol v1, which carries no output recipe id."""
    types: tuple[str, ...]
    not_found: tuple[str, ...]
    """The requested names the robot answered NOT_FOUND, in request order."""


@dataclass(frozen=True, slots=True)
class InputsConfigured:
    """The robot's answer to SetupInputs; the recipe is usable iff ``not_found`` and ``in_use`` are empty."""

    recipe_id: int
    types: tuple[str, ...]
    not_found: tuple[str, ...]
    in_use: tuple[str, ...]
    """Names another client (or interface) already owns."""


@dataclass(frozen=True, slots=True)
class StartReply:
    """The robot's answer to Start."""

    accepted: bool


@dataclass(frozen=True, slots=True)
class PauseReply:
    """The robot's answer to Pause."""

    accepted: bool


@dataclass(frozen=True, slots=True)
class DataPackage:
    """One output sample: ``values`` in output-recipe order (vectors as tuples)."""

    recipe_id: int | None
    """None under protocol v1."""
    values: tuple[RtdeValue, ...]


@dataclass(frozen=True, slots=True)
class TextMessage:
    """A text message from the controller (``source`` is empty under protocol v1)."""

    level: int
    message: str
    source: str


# -- events the ROBOT receives ------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class ProtocolVersionRequested:
    """The client asks for protocol ``version``; answer with ProtocolVersionAccept."""

    version: int


@dataclass(frozen=True, slots=True)
class ControllerVersionRequested:
    """The client asks for the controller version; answer with ControllerVersionReply."""


@dataclass(frozen=True, slots=True)
class SetupOutputsRequested:
    """The client asks for an output recipe (``frequency`` is None under v1); answer with OutputsSetup."""

    frequency: float | None
    """As sent, unchecked: may be 0, negative, NaN or above the controller's rate."""
    names: tuple[str, ...]


@dataclass(frozen=True, slots=True)
class SetupInputsRequested:
    """The client asks for an input recipe; answer with InputsSetup."""

    names: tuple[str, ...]


@dataclass(frozen=True, slots=True)
class StartRequested:
    """The client asks to start streaming; answer with StartAccept."""


@dataclass(frozen=True, slots=True)
class PauseRequested:
    """The client asks to pause streaming; answer with PauseAccept."""


@dataclass(frozen=True, slots=True)
class InputDataReceived:
    """Input values for the configured input recipe ``recipe_id``, in its order."""

    recipe_id: int
    values: tuple[RtdeValue, ...]


@dataclass(frozen=True, slots=True)
class TextReceived:
    """A text message from the client."""

    level: int
    message: str
    source: str


# -- messages the ROBOT sends -------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class ProtocolVersionAccept:
    """Answer to ProtocolVersionRequested; accepting switches the framing right after this package."""

    accepted: bool


@dataclass(frozen=True, slots=True)
class ControllerVersionReply:
    """Answer to ControllerVersionRequested."""

    major: int
    minor: int
    bugfix: int
    build: int


@dataclass(frozen=True, slots=True)
class OutputsSetup:
    """Answer to SetupOutputsRequested: a type or NOT_FOUND per requested name; recipe_id None under v1."""

    recipe_id: int | None
    types: tuple[str, ...]


@dataclass(frozen=True, slots=True)
class InputsSetup:
    """Answer to SetupInputsRequested: a type, NOT_FOUND or IN_USE per requested name."""

    recipe_id: int
    types: tuple[str, ...]


@dataclass(frozen=True, slots=True)
class StartAccept:
    """Answer to StartRequested."""

    accepted: bool


@dataclass(frozen=True, slots=True)
class PauseAccept:
    """Answer to PauseRequested."""

    accepted: bool


@dataclass(frozen=True, slots=True)
class OutputData:
    """One output sample in output-recipe order; the codec adds the recipe id under v2."""

    values: tuple[RtdeValue, ...]


@dataclass(frozen=True, slots=True)
class Text:
    """A text message to the client (``source`` must be empty under protocol v1)."""

    level: int
    message: str
    source: str


DaemonMessage: TypeAlias = (
    RequestProtocolVersion
    | GetControllerVersion
    | SetupOutputs
    | SetupInputs
    | Start
    | Pause
    | InputData
    | SendText
)
DaemonEvent: TypeAlias = (
    ProtocolVersionReply
    | ControllerVersion
    | OutputsConfigured
    | InputsConfigured
    | StartReply
    | PauseReply
    | DataPackage
    | TextMessage
)
RobotEvent: TypeAlias = (
    ProtocolVersionRequested
    | ControllerVersionRequested
    | SetupOutputsRequested
    | SetupInputsRequested
    | StartRequested
    | PauseRequested
    | InputDataReceived
    | TextReceived
)
RobotMessage: TypeAlias = (
    ProtocolVersionAccept
    | ControllerVersionReply
    | OutputsSetup
    | InputsSetup
    | StartAccept
    | PauseAccept
    | OutputData
    | Text
)
Event: TypeAlias = DaemonEvent | RobotEvent
Message: TypeAlias = DaemonMessage | RobotMessage


# -- the conversation as a table ----------------------------------------------------------------


class RtdeState(enum.Enum):
    """Where the conversation stands; the same for both parties."""

    IDLE = "idle"  # no output recipe
    CONFIGURED = "configured"  # an output recipe, never started since it was set up
    STARTING = "starting"  # START sent, reply pending (daemon side only)
    RUNNING = "running"  # outputs streaming; inputs may be written
    PAUSING = "pausing"  # PAUSE sent, reply pending (daemon side only)
    PAUSED = "paused"
    ERROR = "error"  # the peer broke the protocol: every later call raises


class _Step(enum.Enum):
    """What moves the state: a request, the outcome of its reply, or a data package."""

    REQUEST_VERSION = enum.auto()
    VERSION_ACCEPTED = enum.auto()
    VERSION_REFUSED = enum.auto()
    REQUEST_OUTPUTS = enum.auto()
    OUTPUTS_CONFIGURED = enum.auto()
    OUTPUTS_NOT_FOUND = enum.auto()
    REQUEST_INPUTS = enum.auto()
    INPUTS_ANSWERED = enum.auto()
    REQUEST_START = enum.auto()
    START_ACCEPTED = enum.auto()
    START_REFUSED = enum.auto()
    REQUEST_PAUSE = enum.auto()
    PAUSE_ACCEPTED = enum.auto()
    PAUSE_REFUSED = enum.auto()
    OUTPUT_DATA = enum.auto()
    INPUT_DATA = enum.auto()


_S = RtdeState
_TRANSITIONS: Final[Mapping[tuple[RtdeState, _Step], RtdeState]] = MappingProxyType(
    {
        # the framing is fixed before anything is set up
        (_S.IDLE, _Step.REQUEST_VERSION): _S.IDLE,
        (_S.IDLE, _Step.VERSION_ACCEPTED): _S.IDLE,
        (_S.IDLE, _Step.VERSION_REFUSED): _S.IDLE,
        # recipes are set up while nothing streams; a failed output setup leaves no output recipe
        # (whether a controller keeps the previous one is unverified; assuming not is the safe side)
        (_S.IDLE, _Step.REQUEST_OUTPUTS): _S.IDLE,
        (_S.CONFIGURED, _Step.REQUEST_OUTPUTS): _S.CONFIGURED,
        (_S.PAUSED, _Step.REQUEST_OUTPUTS): _S.PAUSED,
        (_S.IDLE, _Step.OUTPUTS_CONFIGURED): _S.CONFIGURED,
        (_S.CONFIGURED, _Step.OUTPUTS_CONFIGURED): _S.CONFIGURED,
        (_S.PAUSED, _Step.OUTPUTS_CONFIGURED): _S.CONFIGURED,
        (_S.IDLE, _Step.OUTPUTS_NOT_FOUND): _S.IDLE,
        (_S.CONFIGURED, _Step.OUTPUTS_NOT_FOUND): _S.IDLE,
        (_S.PAUSED, _Step.OUTPUTS_NOT_FOUND): _S.IDLE,
        (_S.IDLE, _Step.REQUEST_INPUTS): _S.IDLE,
        (_S.CONFIGURED, _Step.REQUEST_INPUTS): _S.CONFIGURED,
        (_S.PAUSED, _Step.REQUEST_INPUTS): _S.PAUSED,
        (_S.IDLE, _Step.INPUTS_ANSWERED): _S.IDLE,
        (_S.CONFIGURED, _Step.INPUTS_ANSWERED): _S.CONFIGURED,
        (_S.PAUSED, _Step.INPUTS_ANSWERED): _S.PAUSED,
        # start / pause
        (_S.CONFIGURED, _Step.REQUEST_START): _S.STARTING,
        (_S.PAUSED, _Step.REQUEST_START): _S.STARTING,
        (_S.STARTING, _Step.START_ACCEPTED): _S.RUNNING,
        (_S.STARTING, _Step.START_REFUSED): _S.CONFIGURED,
        (_S.RUNNING, _Step.REQUEST_PAUSE): _S.PAUSING,
        (_S.PAUSING, _Step.PAUSE_ACCEPTED): _S.PAUSED,
        (_S.PAUSING, _Step.PAUSE_REFUSED): _S.RUNNING,
        # data: outputs flow while started; urcl takes one arriving before the START reply (§1.6 step 8)
        (_S.STARTING, _Step.OUTPUT_DATA): _S.STARTING,
        (_S.RUNNING, _Step.OUTPUT_DATA): _S.RUNNING,
        (_S.PAUSING, _Step.OUTPUT_DATA): _S.PAUSING,
        # a package the controller queued before it handled PAUSE may trail the reply (unverified):
        # it is still decodable with the recipe, so it is reported rather than called an error
        (_S.PAUSED, _Step.OUTPUT_DATA): _S.PAUSED,
        (_S.RUNNING, _Step.INPUT_DATA): _S.RUNNING,
    }
)
"""(state, step) -> next state. A pair missing here is out of order (see RtdeConnection)."""

_REQUEST_STEPS: Final[Mapping[PackageType, _Step | None]] = MappingProxyType(
    {
        PackageType.REQUEST_PROTOCOL_VERSION: _Step.REQUEST_VERSION,
        PackageType.GET_URCONTROL_VERSION: None,  # legal in every state, changes nothing
        PackageType.CONTROL_PACKAGE_SETUP_OUTPUTS: _Step.REQUEST_OUTPUTS,
        PackageType.CONTROL_PACKAGE_SETUP_INPUTS: _Step.REQUEST_INPUTS,
        PackageType.CONTROL_PACKAGE_START: _Step.REQUEST_START,
        PackageType.CONTROL_PACKAGE_PAUSE: _Step.REQUEST_PAUSE,
    }
)


@dataclass(slots=True)
class _Request:
    """A request sent (daemon side) or received (robot side) whose reply is still due."""

    kind: PackageType
    names: tuple[str, ...] = ()
    version: int = 0


def _remote(message: str, offset: int | None = None) -> RemoteProtocolError:
    return RemoteProtocolError(f"{PROTOCOL}: {message}", protocol=PROTOCOL, offset=offset)


def _local(message: str) -> LocalProtocolError:
    return LocalProtocolError(f"{PROTOCOL}: {message}", protocol=PROTOCOL)


class _RtdeCore(Codec[Message, Event]):
    """The job both parties share: state, framing, the feed loop, text messages; see RtdeConnection."""

    _handlers: dict[int, Callable[[_Buf, int, int], Event]]
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
        self._requests: deque[_Request] = deque()
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
        if recipe is None or len(self._buffer) or (self._state, _Step.OUTPUT_DATA) not in _TRANSITIONS:
            return None
        size = len(data)
        start = HEADER_BYTES if self._version == 1 else HEADER_BYTES + 1  # v2: the recipe id first
        if (
            size != start + recipe.size
            or _HEADER.unpack_from(data) != (size, _KIND_DATA)
            or (start > HEADER_BYTES and data[HEADER_BYTES] != self._output_recipe_id)
        ):
            return None
        self._consumed += size
        return recipe.decode(data, start)

    def receive_eof(self) -> list[Event]:
        """The peer closed; RemoteProtocolError if it closed in the middle of a package."""
        if self._stream is CodecState.ERROR:
            raise _remote("connection already failed", self._consumed)
        self._stream = CodecState.EOF
        if len(self._buffer):
            self._fail()
            raise _remote(f"connection closed {len(self._buffer)} bytes into a package", self._consumed)
        return []

    def _encode(self, message: Message) -> None:
        """Queue ``message``; LocalProtocolError if this side may not send it now (nothing is queued)."""
        sender = self._senders.get(type(message))
        if sender is None:
            raise _local(f"the {self.side.name} side does not send {type(message).__name__}")
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
        size, kind = _HEADER.unpack(header)
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
            size, kind = _HEADER.unpack_from(view, pos)
            if size < HEADER_BYTES:
                raise self._bad_size(size)
            end = pos + size
            if end > total:
                break
            events.append(self._dispatch(kind, view, pos + HEADER_BYTES, end))
            pos = end
        return pos

    def _dispatch(self, kind: int, buf: _Buf, start: int, end: int) -> Event:
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
            raise _local(f"{kind.name} of {size} bytes exceeds the {MAX_PACKAGE_BYTES}-byte package limit")
        self._out += _HEADER.pack(size, kind)
        self._out += payload

    def _next(self, step: _Step, *, local: bool) -> RtdeState:
        """The state after ``step``; out of order raises (Local for what we send, Remote for what we got)."""
        state = _TRANSITIONS.get((self._state, step))
        if state is None:
            what = f"{step.name} is out of order in state {self._state.name}"
            raise _local(what) if local else self._bad(what)
        return state

    def _bad(self, message: str) -> RemoteProtocolError:
        return _remote(message, self._package_offset)

    def _bad_size(self, size: int) -> RemoteProtocolError:
        self._package_offset = self._consumed
        return self._bad(f"package size {size} is smaller than the {HEADER_BYTES}-byte header")

    # -- payload pieces shared by both sides ----------------------------------------------------

    def _flag(self, buf: _Buf, start: int, end: int, kind: PackageType) -> bool:
        if end - start != 1:
            raise self._bad(f"{kind.name} reply has {end - start} payload bytes, expected 1")
        return buf[start] != 0  # bool on the wire: 0 false, anything else true (§0)

    def _empty(self, start: int, end: int, kind: PackageType) -> None:
        if end != start:
            raise self._bad(f"{kind.name} request has {end - start} payload bytes, expected none")

    def _parse_text(self, buf: _Buf, start: int, end: int) -> tuple[int, str, str]:
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
            raise _local(f"text level {level!r} is not a uint8")
        try:
            message_bytes = message.encode("utf-8")
            source_bytes = source.encode("utf-8")
        except (AttributeError, UnicodeEncodeError) as err:
            raise _local(f"text message and source must be encodable str: {err}") from err
        if self._version == 1:
            if source_bytes:
                raise _local("a protocol v1 TEXT_MESSAGE has no source field; leave source empty")
            return _U8.pack(level) + message_bytes
        if len(message_bytes) > MAX_TEXT_FIELD_BYTES or len(source_bytes) > MAX_TEXT_FIELD_BYTES:
            raise _local(f"text message and source are limited to {MAX_TEXT_FIELD_BYTES} bytes each")
        return (
            _U8.pack(len(message_bytes))
            + message_bytes
            + _U8.pack(len(source_bytes))
            + source_bytes
            + _U8.pack(level)
        )

    def _send_text(self, message: SendText | Text) -> None:
        pending = self._requests[0].kind if self._requests else None
        if self.side is Side.DAEMON and pending is PackageType.REQUEST_PROTOCOL_VERSION:
            # which framing the robot reads it in depends on when it answers: wait for the reply
            raise _local("no TEXT_MESSAGE while a protocol version change is pending")
        self._emit(
            PackageType.TEXT_MESSAGE, self._text_payload(message.level, message.message, message.source)
        )

    def _on_text_from_robot(self, buf: _Buf, start: int, end: int) -> TextMessage:
        return TextMessage(*self._parse_text(buf, start, end))

    def _on_text_from_client(self, buf: _Buf, start: int, end: int) -> TextReceived:
        return TextReceived(*self._parse_text(buf, start, end))

    def _types(self, buf: _Buf, start: int, end: int, names: int, allowed: frozenset[str]) -> tuple[str, ...]:
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


class _DaemonSide(_RtdeCore):
    """The daemon's job: send requests and input data, decode the replies and the output data."""

    def _daemon_tables(self) -> None:
        P = PackageType
        self._handlers = {
            P.REQUEST_PROTOCOL_VERSION: self._on_version_reply,
            P.GET_URCONTROL_VERSION: self._on_controller_version,
            P.CONTROL_PACKAGE_SETUP_OUTPUTS: self._on_outputs_reply,
            P.CONTROL_PACKAGE_SETUP_INPUTS: self._on_inputs_reply,
            P.CONTROL_PACKAGE_START: self._on_start_reply,
            P.CONTROL_PACKAGE_PAUSE: self._on_pause_reply,
            P.DATA_PACKAGE: self._on_output_data,
            P.TEXT_MESSAGE: self._on_text_from_robot,
        }
        self._senders = {
            RequestProtocolVersion: self._send_version_request,
            GetControllerVersion: self._send_controller_version_request,
            SetupOutputs: self._send_setup_outputs,
            SetupInputs: self._send_setup_inputs,
            Start: self._send_start,
            Pause: self._send_pause,
            InputData: self._send_input_data,
            SendText: self._send_text,
        }

    # -- DAEMON: requests ------------------------------------------------------------------------

    def _request(self, kind: PackageType, payload: bytes, request: _Request | None = None) -> None:
        if self._requests:
            due = self._requests[0].kind.name
            raise _local(f"{kind.name} while the {due} reply is still due (one request at a time)")
        step = _REQUEST_STEPS[kind]
        state = self._state if step is None else self._next(step, local=True)
        self._emit(kind, payload)
        self._state = state
        self._requests.append(request or _Request(kind))

    def _send_version_request(self, message: RequestProtocolVersion) -> None:
        version = message.version
        if version not in SUPPORTED_PROTOCOL_VERSIONS:
            raise _local(
                f"this codec speaks RTDE protocol versions {SUPPORTED_PROTOCOL_VERSIONS}, not {version!r}"
            )
        kind = PackageType.REQUEST_PROTOCOL_VERSION
        self._request(kind, _U16.pack(version), _Request(kind, version=version))

    def _send_controller_version_request(self, message: GetControllerVersion) -> None:
        self._request(PackageType.GET_URCONTROL_VERSION, b"")

    def _send_setup_outputs(self, message: SetupOutputs) -> None:
        names = _names_payload(message.names)
        frequency = message.frequency
        if self._version == 1:
            if frequency is not None:
                raise _local("protocol v1 SETUP_OUTPUTS has no frequency (the robot streams at its rate)")
            payload = names
        else:
            known = self._controller_version
            limit = max_frequency(known.major) if known else E_SERIES_MAX_FREQUENCY_HZ
            if not isinstance(frequency, int | float) or not (
                math.isfinite(frequency) and 0 < frequency <= limit
            ):
                raise _local(f"output frequency {frequency!r} Hz is not in (0, {limit}]")
            payload = _F64.pack(frequency) + names
        kind = PackageType.CONTROL_PACKAGE_SETUP_OUTPUTS
        self._request(kind, payload, _Request(kind, names=tuple(message.names)))

    def _send_setup_inputs(self, message: SetupInputs) -> None:
        kind = PackageType.CONTROL_PACKAGE_SETUP_INPUTS
        self._request(kind, _names_payload(message.names), _Request(kind, names=tuple(message.names)))

    def _send_start(self, message: Start) -> None:
        self._request(PackageType.CONTROL_PACKAGE_START, b"")

    def _send_pause(self, message: Pause) -> None:
        self._request(PackageType.CONTROL_PACKAGE_PAUSE, b"")

    def _send_input_data(self, message: InputData) -> None:
        recipe_id = self._input_recipe_id if message.recipe_id is None else message.recipe_id
        recipe = None if recipe_id is None else self._input_recipes.get(recipe_id)
        if recipe_id is None or recipe is None:
            raise _local(f"input data for input recipe {recipe_id}, which the robot never set up")
        state = self._next(_Step.INPUT_DATA, local=True)
        try:
            body = recipe.encode(message.values)
        except ValueError as err:
            raise _local(f"input data: {err}") from err
        self._emit(PackageType.DATA_PACKAGE, _U8.pack(recipe_id) + body)
        self._state = state

    # -- DAEMON: replies and data ----------------------------------------------------------------

    def _reply_to(self, kind: PackageType) -> _Request:
        """The request this reply answers; a reply nobody asked for is the robot's error."""
        if not self._requests or self._requests[0].kind is not kind:
            due = self._requests[0].kind.name if self._requests else "no reply"
            raise self._bad(f"{kind.name} reply while {due} is due")
        return self._requests.popleft()

    def _on_version_reply(self, buf: _Buf, start: int, end: int) -> ProtocolVersionReply:
        kind = PackageType.REQUEST_PROTOCOL_VERSION
        request = self._reply_to(kind)
        accepted = self._flag(buf, start, end, kind)
        self._state = self._next(_Step.VERSION_ACCEPTED if accepted else _Step.VERSION_REFUSED, local=False)
        if accepted:
            self._version = request.version
        return ProtocolVersionReply(accepted)

    def _on_controller_version(self, buf: _Buf, start: int, end: int) -> ControllerVersion:
        self._reply_to(PackageType.GET_URCONTROL_VERSION)
        if end - start != _VERSION4.size:
            raise self._bad(f"GET_URCONTROL_VERSION reply has {end - start} payload bytes, expected 16")
        self._controller_version = ControllerVersion(*_VERSION4.unpack_from(buf, start))
        return self._controller_version

    def _on_outputs_reply(self, buf: _Buf, start: int, end: int) -> OutputsConfigured:
        request = self._reply_to(PackageType.CONTROL_PACKAGE_SETUP_OUTPUTS)
        recipe_id: int | None = None
        if self._version >= 2:
            if end <= start:
                raise self._bad("SETUP_OUTPUTS reply without its recipe id")
            recipe_id = buf[start]
            start += 1
        types = self._types(buf, start, end, len(request.names), _OUTPUT_ANSWERS)
        not_found = tuple(name for name, t in zip(request.names, types, strict=True) if t == NOT_FOUND)
        if not_found:
            self._state = self._next(_Step.OUTPUTS_NOT_FOUND, local=False)
            self._output_recipe, self._output_recipe_id = None, None
        else:
            self._state = self._next(_Step.OUTPUTS_CONFIGURED, local=False)
            self._output_recipe, self._output_recipe_id = Recipe(request.names, types), recipe_id
        return OutputsConfigured(recipe_id, types, not_found)

    def _on_inputs_reply(self, buf: _Buf, start: int, end: int) -> InputsConfigured:
        request = self._reply_to(PackageType.CONTROL_PACKAGE_SETUP_INPUTS)
        if end <= start:
            raise self._bad("SETUP_INPUTS reply without its recipe id")
        recipe_id = buf[start]
        types = self._types(buf, start + 1, end, len(request.names), _INPUT_ANSWERS)
        pairs = tuple(zip(request.names, types, strict=True))
        not_found = tuple(name for name, t in pairs if t == NOT_FOUND)
        in_use = tuple(name for name, t in pairs if t == IN_USE)
        self._state = self._next(_Step.INPUTS_ANSWERED, local=False)
        if not not_found and not in_use:
            self._input_recipes[recipe_id] = Recipe(request.names, types)
            self._input_recipe_id = recipe_id
        return InputsConfigured(recipe_id, types, not_found, in_use)

    def _on_start_reply(self, buf: _Buf, start: int, end: int) -> StartReply:
        kind = PackageType.CONTROL_PACKAGE_START
        self._reply_to(kind)
        accepted = self._flag(buf, start, end, kind)
        self._state = self._next(_Step.START_ACCEPTED if accepted else _Step.START_REFUSED, local=False)
        return StartReply(accepted)

    def _on_pause_reply(self, buf: _Buf, start: int, end: int) -> PauseReply:
        kind = PackageType.CONTROL_PACKAGE_PAUSE
        self._reply_to(kind)
        accepted = self._flag(buf, start, end, kind)
        self._state = self._next(_Step.PAUSE_ACCEPTED if accepted else _Step.PAUSE_REFUSED, local=False)
        return PauseReply(accepted)

    def _on_output_data(self, buf: _Buf, start: int, end: int) -> DataPackage:
        # the 500 Hz path: one table lookup, one size check, one unpack_from
        recipe = self._output_recipe
        if (self._state, _Step.OUTPUT_DATA) not in _TRANSITIONS or recipe is None:
            raise self._bad(f"DATA_PACKAGE in state {self._state.name}, before outputs were started")
        if self._version == 1:
            if end - start != recipe.size:
                raise self._bad(
                    f"DATA_PACKAGE payload of {end - start} bytes, output recipe is {recipe.size}"
                )
            return DataPackage(None, recipe.decode(buf, start))
        if end - start != recipe.size + 1:
            raise self._bad(
                f"DATA_PACKAGE payload of {end - start} bytes, expected 1 (id) + {recipe.size} (recipe)"
            )
        recipe_id = buf[start]
        if recipe_id != self._output_recipe_id:
            raise self._bad(
                f"DATA_PACKAGE for output recipe {recipe_id}, configured is {self._output_recipe_id}"
            )
        return DataPackage(recipe_id, recipe.decode(buf, start + 1))


class _RobotSide(_RtdeCore):
    """The robot's job (the fake's side): decode requests and input data, send answers and outputs."""

    def _robot_tables(self) -> None:
        P = PackageType
        self._handlers = {
            P.REQUEST_PROTOCOL_VERSION: self._on_version_request,
            P.GET_URCONTROL_VERSION: self._on_controller_version_request,
            P.CONTROL_PACKAGE_SETUP_OUTPUTS: self._on_outputs_request,
            P.CONTROL_PACKAGE_SETUP_INPUTS: self._on_inputs_request,
            P.CONTROL_PACKAGE_START: self._on_start_request,
            P.CONTROL_PACKAGE_PAUSE: self._on_pause_request,
            P.DATA_PACKAGE: self._on_input_data,
            P.TEXT_MESSAGE: self._on_text_from_client,
        }
        self._senders = {
            ProtocolVersionAccept: self._send_version_answer,
            ControllerVersionReply: self._send_controller_version,
            OutputsSetup: self._send_outputs_answer,
            InputsSetup: self._send_inputs_answer,
            StartAccept: self._send_start_answer,
            PauseAccept: self._send_pause_answer,
            OutputData: self._send_output_data,
            Text: self._send_text,
        }

    # -- ROBOT: requests and data ----------------------------------------------------------------

    def _received(self, request: _Request) -> None:
        if len(self._requests) >= MAX_UNANSWERED_REQUESTS:
            raise self._bad(f"more than {MAX_UNANSWERED_REQUESTS} requests without waiting for replies")
        self._requests.append(request)

    def _names(self, buf: _Buf, start: int, end: int, kind: PackageType) -> tuple[str, ...]:
        if end <= start:
            raise self._bad(f"{kind.name} request without variable names")
        if end - start > MAX_RECIPE_NAMES_BYTES:
            raise self._bad(
                f"{kind.name} names take {end - start} bytes, the limit is {MAX_RECIPE_NAMES_BYTES}"
            )
        try:
            names = str(buf[start:end], "ascii").split(",")
        except UnicodeDecodeError:
            raise self._bad(f"{kind.name} names are not ASCII") from None
        # ur_rtde ends its list with a comma and works against real controllers: a trailing comma
        # adds no name there, so it adds none here either
        if len(names) > 1 and names[-1] == "":
            names.pop()
        return tuple(names)

    def _on_version_request(self, buf: _Buf, start: int, end: int) -> ProtocolVersionRequested:
        kind = PackageType.REQUEST_PROTOCOL_VERSION
        if end - start != _U16.size:
            raise self._bad(f"{kind.name} request has {end - start} payload bytes, expected 2")
        version: int = _U16.unpack_from(buf, start)[0]
        self._received(_Request(kind, version=version))
        return ProtocolVersionRequested(version)

    def _on_controller_version_request(self, buf: _Buf, start: int, end: int) -> ControllerVersionRequested:
        kind = PackageType.GET_URCONTROL_VERSION
        self._empty(start, end, kind)
        self._received(_Request(kind))
        return ControllerVersionRequested()

    def _on_outputs_request(self, buf: _Buf, start: int, end: int) -> SetupOutputsRequested:
        kind = PackageType.CONTROL_PACKAGE_SETUP_OUTPUTS
        frequency: float | None = None
        if self._version >= 2:
            if end - start < _F64.size:
                raise self._bad(f"{kind.name} request shorter than its frequency")
            frequency = _F64.unpack_from(buf, start)[0]
            start += _F64.size
        names = self._names(buf, start, end, kind)
        self._received(_Request(kind, names=names))
        return SetupOutputsRequested(frequency, names)

    def _on_inputs_request(self, buf: _Buf, start: int, end: int) -> SetupInputsRequested:
        kind = PackageType.CONTROL_PACKAGE_SETUP_INPUTS
        names = self._names(buf, start, end, kind)
        self._received(_Request(kind, names=names))
        return SetupInputsRequested(names)

    def _on_start_request(self, buf: _Buf, start: int, end: int) -> StartRequested:
        kind = PackageType.CONTROL_PACKAGE_START
        self._empty(start, end, kind)
        self._received(_Request(kind))
        return StartRequested()

    def _on_pause_request(self, buf: _Buf, start: int, end: int) -> PauseRequested:
        kind = PackageType.CONTROL_PACKAGE_PAUSE
        self._empty(start, end, kind)
        self._received(_Request(kind))
        return PauseRequested()

    def _on_input_data(self, buf: _Buf, start: int, end: int) -> InputDataReceived:
        # reported in any state: whether inputs count before START is the fake's call (unverified)
        if end <= start:
            raise self._bad("input DATA_PACKAGE without its recipe id")
        recipe_id = buf[start]
        recipe = self._input_recipes.get(recipe_id)
        if recipe is None:
            raise self._bad(f"input DATA_PACKAGE for input recipe {recipe_id}, which was never set up")
        if end - start - 1 != recipe.size:
            raise self._bad(f"input DATA_PACKAGE has {end - start - 1} value bytes, recipe is {recipe.size}")
        return InputDataReceived(recipe_id, recipe.decode(buf, start + 1))

    # -- ROBOT: answers and data -----------------------------------------------------------------

    def _answering(self, kind: PackageType) -> tuple[_Request, bool]:
        """The oldest unanswered request, which must be of ``kind``, and whether it is in order now."""
        if not self._requests:
            raise _local(f"{kind.name} reply, but no request is waiting for one")
        request = self._requests[0]
        if request.kind is not kind:
            raise _local(f"{kind.name} reply, but the oldest unanswered request is {request.kind.name}")
        step = _REQUEST_STEPS[kind]
        return request, step is None or (self._state, step) in _TRANSITIONS

    def _answer(self, kind: PackageType, payload: bytes, outcome: _Step | None, in_order: bool) -> None:
        """Queue the reply to the oldest request and walk request + outcome through the table if in order."""
        state = self._state
        step = _REQUEST_STEPS[kind]
        if in_order and step is not None and outcome is not None:
            state = _TRANSITIONS[(state, step)]
            after = _TRANSITIONS.get((state, outcome))
            if after is None:
                raise _local(f"{outcome.name} cannot follow {step.name} in state {self._state.name}")
            state = after
        self._emit(kind, payload)
        self._state = state
        self._requests.popleft()

    def _send_version_answer(self, message: ProtocolVersionAccept) -> None:
        kind = PackageType.REQUEST_PROTOCOL_VERSION
        request, in_order = self._answering(kind)
        accepted = bool(message.accepted)
        if accepted and not in_order:
            raise _local(f"accepting a protocol version in state {self._state.name}; answer accepted=False")
        if accepted and request.version not in SUPPORTED_PROTOCOL_VERSIONS:
            raise _local(f"this codec cannot speak protocol version {request.version}; answer accepted=False")
        outcome = _Step.VERSION_ACCEPTED if accepted else _Step.VERSION_REFUSED
        self._answer(kind, _U8.pack(accepted), outcome, in_order)
        if accepted:
            self._version = request.version

    def _send_controller_version(self, message: ControllerVersionReply) -> None:
        kind = PackageType.GET_URCONTROL_VERSION
        self._answering(kind)
        version = ControllerVersion(message.major, message.minor, message.bugfix, message.build)
        try:
            payload = _VERSION4.pack(version.major, version.minor, version.bugfix, version.build)
        except struct.error as err:
            raise _local(f"controller version fields must be uint32: {err}") from err
        self._answer(kind, payload, None, True)
        self._controller_version = version

    def _setup_answer(
        self, kind: PackageType, recipe_id: int | None, types: Sequence[str], allowed: frozenset[str]
    ) -> tuple[_Request, bool, tuple[str, ...], bytes]:
        """Checks shared by both setup answers: (request, in order, types, payload)."""
        request, in_order = self._answering(kind)
        answers = tuple(types)
        if len(answers) != len(request.names):
            raise _local(f"{kind.name} reply needs one type per requested name ({len(request.names)})")
        for rtde_type in answers:
            if rtde_type not in allowed:
                raise _local(f"{kind.name} reply cannot carry {rtde_type!r}")
        body = ",".join(answers).encode("ascii")
        if recipe_id is None:
            return request, in_order, answers, body
        if not isinstance(recipe_id, int) or not 0 <= recipe_id <= 0xFF:
            raise _local(f"recipe id {recipe_id!r} is not a uint8")
        return request, in_order, answers, _U8.pack(recipe_id) + body

    def _send_outputs_answer(self, message: OutputsSetup) -> None:
        kind = PackageType.CONTROL_PACKAGE_SETUP_OUTPUTS
        recipe_id = message.recipe_id
        if (recipe_id is None) != (self._version == 1):
            raise _local("an output recipe id goes with protocol v2 only (None under v1)")
        request, in_order, types, payload = self._setup_answer(
            kind, recipe_id, message.types, _OUTPUT_ANSWERS
        )
        found = NOT_FOUND not in types
        recipe = Recipe(request.names, types) if found else None
        outcome = _Step.OUTPUTS_CONFIGURED if found else _Step.OUTPUTS_NOT_FOUND
        self._answer(kind, payload, outcome, in_order)
        if in_order or found:  # an out-of-order failed setup keeps the recipe that streams now
            self._output_recipe, self._output_recipe_id = recipe, recipe_id if found else None

    def _send_inputs_answer(self, message: InputsSetup) -> None:
        kind = PackageType.CONTROL_PACKAGE_SETUP_INPUTS
        if message.recipe_id is None:
            raise _local("SETUP_INPUTS reply needs a recipe id (every protocol version)")
        request, in_order, types, payload = self._setup_answer(
            kind, message.recipe_id, message.types, _INPUT_ANSWERS
        )
        usable = NOT_FOUND not in types and IN_USE not in types
        self._answer(kind, payload, _Step.INPUTS_ANSWERED, in_order)
        if usable:
            self._input_recipes[message.recipe_id] = Recipe(request.names, types)
            self._input_recipe_id = message.recipe_id

    def _send_start_answer(self, message: StartAccept) -> None:
        kind = PackageType.CONTROL_PACKAGE_START
        _, in_order = self._answering(kind)
        accepted = bool(message.accepted)
        if accepted and self._output_recipe is None:
            raise _local("START accepted without an output recipe; a controller answers accepted=False")
        outcome = _Step.START_ACCEPTED if accepted else _Step.START_REFUSED
        self._answer(kind, _U8.pack(accepted), outcome, in_order)

    def _send_pause_answer(self, message: PauseAccept) -> None:
        kind = PackageType.CONTROL_PACKAGE_PAUSE
        _, in_order = self._answering(kind)
        accepted = bool(message.accepted)
        outcome = _Step.PAUSE_ACCEPTED if accepted else _Step.PAUSE_REFUSED
        self._answer(kind, _U8.pack(accepted), outcome, in_order)

    def _send_output_data(self, message: OutputData) -> None:
        state = self._next(_Step.OUTPUT_DATA, local=True)
        recipe = self._output_recipe
        if recipe is None:
            raise _local("output data without an output recipe")
        try:
            body = recipe.encode(message.values)
        except ValueError as err:
            raise _local(f"output data: {err}") from err
        if self._version >= 2:
            assert self._output_recipe_id is not None  # v2 setups always carry one
            body = _U8.pack(self._output_recipe_id) + body
        self._emit(PackageType.DATA_PACKAGE, body)
        self._state = state


class RtdeConnection(_DaemonSide, _RobotSide):
    """One RTDE connection for either party: ``receive_data`` → events, ``send`` → ``data_to_send``.

    State: ``_TRANSITIONS`` maps (state, step) to the next state; both parties walk the same table::

        IDLE, CONFIGURED, PAUSED  --setup outputs, all found-->  CONFIGURED
        IDLE, CONFIGURED, PAUSED  --setup outputs, NOT_FOUND-->  IDLE
        CONFIGURED, PAUSED        --START-->                     STARTING
        STARTING                  --accepted / refused-->        RUNNING / CONFIGURED
        RUNNING                   --PAUSE-->                     PAUSING
        PAUSING                   --accepted / refused-->        PAUSED / RUNNING
        (version changes only in IDLE; input setups in IDLE, CONFIGURED, PAUSED change nothing;
         output data in STARTING, RUNNING, PAUSING, PAUSED; input data in RUNNING)

    The daemon side passes through STARTING and PAUSING while its request is out; the robot side
    handles request and answer in one go and never rests there.

    Requests (§1.6): urcl and UR's client send one request and wait for its reply, so the DAEMON side
    allows one outstanding request. Sending a second first, or a request the table does not allow
    now (START before outputs are set up, input data before START, a version change after setup),
    raises LocalProtocolError and changes nothing. A reply nobody asked for is a RemoteProtocolError.

    The ROBOT side reports every well-formed request as an event, in order or not, and keeps the
    unanswered ones oldest first; the fake answers each exactly once, in that order. Order is judged
    when the answer is sent (a controller handles requests one by one). The answer to an
    out-of-order request leaves the state alone. Where the reply has an "accepted" byte, a
    controller answers 0 (START or PAUSE before setup); the codec lets the fake answer as it likes
    except where the answer would make no sense to the codec itself: accepting a version after
    setup or one it cannot speak, accepting START without an output recipe.

    Errors: bad bytes raise RemoteProtocolError (``offset`` = stream offset of the offending package)
    and leave the connection in ERROR, where every later call raises. A refused ``send`` raises
    LocalProtocolError and queues nothing.
    """

    def __init__(self, side: Side, *, protocol_version: int = 2) -> None:
        """``protocol_version`` is the framing in force until the robot accepts a REQUEST_PROTOCOL_VERSION."""
        super().__init__(side, protocol_version=protocol_version)
        if side is Side.DAEMON:
            self._daemon_tables()
        else:
            self._robot_tables()


def _names_payload(names: Sequence[str]) -> bytes:
    """A SETUP_* name list for the wire; LocalProtocolError if a controller could not read it."""
    if isinstance(names, str) or not names:
        raise _local("a recipe needs a non-empty sequence of variable names")
    for name in names:
        if not isinstance(name, str) or not name or not name.isascii() or "," in name:
            raise _local(f"RTDE variable names are non-empty ASCII without commas, not {name!r}")
    joined = ",".join(names).encode("ascii")
    if len(joined) > MAX_RECIPE_NAMES_BYTES:
        raise _local(f"name list of {len(joined)} bytes exceeds the {MAX_RECIPE_NAMES_BYTES}-byte limit")
    return joined
