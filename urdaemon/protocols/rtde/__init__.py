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

The codec is cut by job, as h11 does: ``_wire`` (port, header, type byte, limits), ``_recipe`` (variables
and their types, packed and unpacked), ``_events`` (one dataclass per package and direction), ``_state``
(the conversation as a table), ``_core`` (what both parties share: state, framing, text), ``_daemon`` and
``_robot`` (each side's requests and answers) and ``_connection`` (``RtdeConnection``, either side).
This module states the public API.
"""

from __future__ import annotations

from urdaemon.protocols.rtde._connection import (
    RtdeConnection,
)
from urdaemon.protocols.rtde._events import (
    ControllerVersion,
    ControllerVersionReply,
    ControllerVersionRequested,
    DaemonEvent,
    DaemonMessage,
    DataPackage,
    Event,
    GetControllerVersion,
    InputData,
    InputDataReceived,
    InputsConfigured,
    InputsSetup,
    Message,
    MessageLevel,
    OutputData,
    OutputsConfigured,
    OutputsSetup,
    Pause,
    PauseAccept,
    PauseReply,
    PauseRequested,
    ProtocolVersionAccept,
    ProtocolVersionReply,
    ProtocolVersionRequested,
    RequestProtocolVersion,
    RobotEvent,
    RobotMessage,
    SendText,
    SetupInputs,
    SetupInputsRequested,
    SetupOutputs,
    SetupOutputsRequested,
    Start,
    StartAccept,
    StartReply,
    StartRequested,
    Text,
    TextMessage,
    TextReceived,
)
from urdaemon.protocols.rtde._recipe import (
    Recipe,
    RtdeValue,
)
from urdaemon.protocols.rtde._state import (
    RtdeState,
)
from urdaemon.protocols.rtde._wire import (
    CB3_MAX_FREQUENCY_HZ,
    E_SERIES_FIRST_MAJOR,
    E_SERIES_MAX_FREQUENCY_HZ,
    HEADER_BYTES,
    MAX_PACKAGE_BYTES,
    MAX_RECIPE_NAMES_BYTES,
    MAX_UNANSWERED_REQUESTS,
    PROTOCOL,
    RTDE_PORT,
    SUPPORTED_PROTOCOL_VERSIONS,
    PackageType,
    max_frequency,
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
