"""The primary interface's numbers on the wire: ports, limits, headers, the type bytes; and its errors."""

from __future__ import annotations

import enum
import struct
from typing import Final

from urdaemon.errors import LocalProtocolError
from urdaemon.model import UR_JOINT_COUNT

__all__ = [
    "HEADER",
    "HEADER_BYTES",
    "JOINTS",
    "MAX_PACKAGE_BYTES",
    "MAX_SCRIPT_BYTES",
    "MAX_SCRIPT_NAME_LENGTH",
    "MESSAGE_HEADER",
    "PRIMARY_PORT",
    "PROTOCOL",
    "SECONDARY_PORT",
    "SUB_HEADER",
    "Malformed",
    "PackageType",
    "ReportLevel",
    "RobotMessageType",
    "SubPackageType",
    "local_error",
]

PROTOCOL: Final = "primary"
PRIMARY_PORT: Final = 30001
"""TCP port of the primary interface on the robot (§0)."""
SECONDARY_PORT: Final = 30002
"""TCP port of the secondary interface on the robot (§0)."""

MAX_PACKAGE_BYTES: Final = 64 * 1024
"""Largest package accepted or sent [bytes]. The largest one observed is the first ROBOT_STATE of
URSim 5.8 at 1,386 bytes (§2.2); 64 KiB leaves ~47x room for fields appended by newer firmware and
for long message texts, while a garbage length cannot make us buffer megabytes."""

MAX_SCRIPT_BYTES: Final = 1024 * 1024
"""Largest script text sent, and largest program or line received on the robot side [bytes]. Our own
choice: urcl 2.14's External Control script is ~52 KB before templating (§5), so 1 MiB leaves ~20x room."""

MAX_SCRIPT_NAME_LENGTH: Final = 31
"""Longest program name [characters]; urcl truncates to 31 (§2.4 step 5), we refuse instead so the
name in PROGRAM_XXX_STARTED key messages (§2.5) is the one we chose."""

HEADER_BYTES: Final = 5  # int32 length + uint8 type, §2.1; sub-packages use the same 5 (§2.2)
HEADER: Final = struct.Struct(">iB")
SUB_HEADER: Final = struct.Struct(">IB")
MESSAGE_HEADER: Final = struct.Struct(">QbB")  # timestamp, source, robot message type; §2.3
JOINTS: Final = UR_JOINT_COUNT


class PackageType(enum.IntEnum):
    """Package type byte of the primary interface; §2.1."""

    MODBUS_INFO_MESSAGE = 5
    ROBOT_STATE = 16
    ROBOT_MESSAGE = 20
    HMC_MESSAGE = 22
    SAFETY_SETUP_BROADCAST_MESSAGE = 23
    SAFETY_COMPLIANCE_TOLERANCES_MESSAGE = 24
    PROGRAM_STATE_MESSAGE = 25


class SubPackageType(enum.IntEnum):
    """ROBOT_STATE sub-package type byte; §2.2."""

    ROBOT_MODE_DATA = 0
    JOINT_DATA = 1
    TOOL_DATA = 2
    MASTERBOARD_DATA = 3
    CARTESIAN_INFO = 4
    KINEMATICS_INFO = 5
    CONFIGURATION_DATA = 6
    FORCE_MODE_DATA = 7
    ADDITIONAL_INFO = 8
    CALIBRATION_DATA = 9
    SAFETY_DATA = 10
    TOOL_COMM_INFO = 11
    TOOL_MODE_INFO = 12


class RobotMessageType(enum.IntEnum):
    """ROBOT_MESSAGE type byte; §2.3."""

    TEXT = 0
    PROGRAM_LABEL = 1
    POPUP = 2
    VERSION = 3
    SAFETY_MODE = 5
    ERROR_CODE = 6
    KEY = 7
    REQUEST_VALUE = 9
    RUNTIME_EXCEPTION = 10


class ReportLevel(enum.IntEnum):
    """ERROR_CODE report level; §2.3 (VIOLATION and worse fail a script, §2.5)."""

    DEBUG = 0
    INFO = 1
    WARNING = 2
    VIOLATION = 3
    FAULT = 4
    CRITICAL_FAULT = 5
    DEVL_DEBUG = 128
    DEVL_INFO = 129
    DEVL_WARNING = 130
    DEVL_VIOLATION = 131
    DEVL_FAULT = 132
    DEVL_CRITICAL_FAULT = 133


def local_error(message: str) -> LocalProtocolError:
    return LocalProtocolError(f"{PROTOCOL}: {message}", protocol=PROTOCOL)


class Malformed(Exception):
    """A body that does not fit its layout; turned into RemoteProtocolError with the offset."""
