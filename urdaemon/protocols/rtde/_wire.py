"""RTDE's numbers on the wire: the port, the package header and type byte, the limits, the versions.

Also the controller's output rates (``max_frequency``) and the two errors every part of the codec raises,
both named for the protocol. See the package docstring for the package layout.
"""

from __future__ import annotations

import enum
import struct
from typing import Final, TypeAlias

from urdaemon.errors import LocalProtocolError, RemoteProtocolError

__all__ = [
    "CB3_MAX_FREQUENCY_HZ",
    "E_SERIES_FIRST_MAJOR",
    "E_SERIES_MAX_FREQUENCY_HZ",
    "F64",
    "HEADER",
    "HEADER_BYTES",
    "KIND_DATA",
    "MAX_PACKAGE_BYTES",
    "MAX_RECIPE_NAMES_BYTES",
    "MAX_TEXT_FIELD_BYTES",
    "MAX_UNANSWERED_REQUESTS",
    "PROTOCOL",
    "RTDE_PORT",
    "SUPPORTED_PROTOCOL_VERSIONS",
    "U8",
    "U16",
    "VERSION4",
    "Buf",
    "PackageType",
    "local_error",
    "max_frequency",
    "remote_error",
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

HEADER: Final = struct.Struct(">HB")
U8: Final = struct.Struct(">B")
U16: Final = struct.Struct(">H")
F64: Final = struct.Struct(">d")
VERSION4: Final = struct.Struct(">IIII")
Buf: TypeAlias = bytes | bytearray | memoryview


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


KIND_DATA: Final = int(PackageType.DATA_PACKAGE)


def remote_error(message: str, offset: int | None = None) -> RemoteProtocolError:
    return RemoteProtocolError(f"{PROTOCOL}: {message}", protocol=PROTOCOL, offset=offset)


def local_error(message: str) -> LocalProtocolError:
    return LocalProtocolError(f"{PROTOCOL}: {message}", protocol=PROTOCOL)
