"""Primary / secondary interface (ports 30001, 30002, 30011, 30012) as a sans-IO codec; docs/protocols.md §2.

Robot → daemon: length-prefixed binary packages (§2.1), every number big-endian (§0)::

    package         [ int32 length, incl. these 5 bytes ][ uint8 package type ][ body ........ ]
    ROBOT_STATE     body = sub-packages back to back (§2.2):
                    [ uint32 length, incl. these 5 bytes ][ uint8 sub-package type ][ sub body ] ...
    ROBOT_MESSAGE   body (§2.3):
                    [ uint64 timestamp ][ int8 source ][ uint8 message type ][ message body ... ]
    other types     22, 5, 23, 24, 25 (and any unknown type): skipped by length, reported as OtherPackage

Daemon → robot: URScript as ASCII text; the controller only runs text that ends with ``\\n`` (§2.4).

``PrimaryConnection(Side.DAEMON)`` sends :class:`Script` and receives one event per package:
:class:`RobotState` (all its sub-packages, in wire order; pick one with ``state.get(RobotModeData)``),
one of the robot-message classes, or :class:`OtherPackage`. ``PrimaryConnection(Side.ROBOT)`` (the fake
controller) sends those and receives :class:`ProgramReceived` / :class:`CommandReceived` from script text.

Unknown sub-packages, and the ones not modelled here (CALIBRATION_DATA 9, SAFETY_DATA 10), are reported
as :class:`UnknownSubPackage` rather than dropped, so the fake controller can replay a capture byte for
byte. Newer firmware appends fields (§2.1): bytes after a known layout are ignored; a body shorter than
the layout is a RemoteProtocolError.

The codec is cut by job: ``_wire`` (ports, limits, headers, type bytes), ``_events`` (one dataclass per
package, sub-package and robot message), ``_layouts`` (their byte layouts, both directions), ``_script``
(URScript text: programs, commands, blocks), ``_safety`` (the robot side's SAFETY_MODE and ERROR_CODE
reports of a safety mode's changes) and ``_connection`` (``PrimaryConnection``, either side).
This module states the public API.
"""

from __future__ import annotations

from urdaemon.protocols.primary._connection import (
    PrimaryConnection,
)
from urdaemon.protocols.primary._events import (
    AdditionalInfo,
    CartesianInfo,
    CommandReceived,
    ConfigurationData,
    ErrorCodeMessage,
    Euromap67,
    ForceModeData,
    JointData,
    KeyMessage,
    KinematicsInfo,
    MasterboardData,
    OtherPackage,
    OtherRobotMessage,
    PrimaryEvent,
    PrimaryMessage,
    ProgramReceived,
    RobotMessage,
    RobotModeData,
    RobotState,
    RuntimeExceptionMessage,
    SafetyModeMessage,
    Script,
    SubPackage,
    TextMessage,
    ToolCommInfo,
    ToolData,
    ToolModeInfo,
    UnknownSubPackage,
    VersionMessage,
    popup_message,
)
from urdaemon.protocols.primary._safety import (
    PROTECTIVE_STOP_TRIGGERED,
    SafetyReports,
    protective_stop_error,
)
from urdaemon.protocols.primary._script import (
    ControllerCommand,
    def_program,
    headless_program,
    sec_program,
)
from urdaemon.protocols.primary._wire import (
    MAX_PACKAGE_BYTES,
    MAX_SCRIPT_BYTES,
    MAX_SCRIPT_NAME_LENGTH,
    PRIMARY_PORT,
    PROTOCOL,
    SECONDARY_PORT,
    PackageType,
    ReportLevel,
    RobotMessageType,
    SubPackageType,
)

__all__ = [
    "MAX_PACKAGE_BYTES",
    "MAX_SCRIPT_BYTES",
    "MAX_SCRIPT_NAME_LENGTH",
    "PRIMARY_PORT",
    "PROTECTIVE_STOP_TRIGGERED",
    "PROTOCOL",
    "SECONDARY_PORT",
    "AdditionalInfo",
    "CartesianInfo",
    "CommandReceived",
    "ConfigurationData",
    "ControllerCommand",
    "ErrorCodeMessage",
    "Euromap67",
    "ForceModeData",
    "JointData",
    "KeyMessage",
    "KinematicsInfo",
    "MasterboardData",
    "OtherPackage",
    "OtherRobotMessage",
    "PackageType",
    "PrimaryConnection",
    "PrimaryEvent",
    "PrimaryMessage",
    "ProgramReceived",
    "ReportLevel",
    "RobotMessage",
    "RobotMessageType",
    "RobotModeData",
    "RobotState",
    "RuntimeExceptionMessage",
    "SafetyModeMessage",
    "SafetyReports",
    "Script",
    "SubPackage",
    "SubPackageType",
    "TextMessage",
    "ToolCommInfo",
    "ToolData",
    "ToolModeInfo",
    "UnknownSubPackage",
    "VersionMessage",
    "def_program",
    "headless_program",
    "popup_message",
    "protective_stop_error",
    "sec_program",
]
