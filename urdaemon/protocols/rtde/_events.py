"""What each RTDE party sends and receives: one frozen dataclass per package, named for what happened.

The daemon sends requests and input data (``DaemonMessage``) and receives replies, output data and text
(``DaemonEvent``); the robot side receives those requests (``RobotEvent``) and sends the answers
(``RobotMessage``). Payload layouts are drawn in the package docstring (§1.3).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import TypeAlias

from urdaemon.protocols.rtde._recipe import RtdeValue

__all__ = [
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
    "Pause",
    "PauseAccept",
    "PauseReply",
    "PauseRequested",
    "ProtocolVersionAccept",
    "ProtocolVersionReply",
    "ProtocolVersionRequested",
    "RequestProtocolVersion",
    "RobotEvent",
    "RobotMessage",
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
]


class MessageLevel(enum.IntEnum):
    """TEXT_MESSAGE severity levels as UR's RTDE client names them (§1.3); other values pass through."""

    EXCEPTION = 0
    ERROR = 1
    WARNING = 2
    INFO = 3


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
    """Input values for the configured input recipe ``recipe_id``, in its order.

    A package of another size than its recipe is reported, not refused (what a controller does with
    one is docs/fake-robot.md's "RTDE inputs, units and small fixes"): ``values`` then holds the
    recipe's leading fields that lie whole in the package, and ``size`` its value bytes."""

    recipe_id: int
    values: tuple[RtdeValue, ...]
    size: int | None = None
    """The package's value bytes when they are not the recipe's size (None when they are)."""


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
