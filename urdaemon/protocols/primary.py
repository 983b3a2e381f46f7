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
"""

from __future__ import annotations

import enum
import re
import struct
from collections.abc import Callable, Sequence
from dataclasses import KW_ONLY, dataclass, fields
from typing import Any, Final, Literal, TypeAlias, TypeVar

from urdaemon.errors import LocalProtocolError, RemoteProtocolError
from urdaemon.model import UR_JOINT_COUNT
from urdaemon.protocols._buffer import Side
from urdaemon.protocols._codec import Codec, CodecState
from urdaemon.protocols.kinematics_hash import kinematics_hash

__all__ = [
    "MAX_PACKAGE_BYTES",
    "MAX_SCRIPT_BYTES",
    "MAX_SCRIPT_NAME_LENGTH",
    "PRIMARY_PORT",
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
    "sec_program",
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

_HEADER_BYTES: Final = 5  # int32 length + uint8 type, §2.1; sub-packages use the same 5 (§2.2)
_HEADER: Final = struct.Struct(">iB")
_SUB_HEADER: Final = struct.Struct(">IB")
_MESSAGE_HEADER: Final = struct.Struct(">QbB")  # timestamp, source, robot message type; §2.3
_JOINTS: Final = UR_JOINT_COUNT

_NAME_PATTERN: Final = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")  # §2.4 step 5
# a top-level block opens with `def NAME():` / `sec NAME():` at column 0 and closes with `end` at column 0
_BLOCK_START: Final = re.compile(
    r"(def|sec)[ \t]+([A-Za-z_]\w*)[ \t]*\([ \t]*\)[ \t]*:[ \t]*(#.*)?", re.ASCII
)
_BLOCK_END: Final = re.compile(r"end[ \t]*(#.*)?")


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


class ControllerCommand(enum.StrEnum):
    """Single-line controller commands, sent like a script (GUI-internal, undocumented); §2.4 step 6."""

    POWER_ON = "power on"
    POWER_OFF = "power off"
    BRAKE_RELEASE = "set robotmode run"
    UNLOCK_PROTECTIVE_STOP = "set unlock protective stop"
    STOP_PROGRAM = "stop program"


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


_Vec6: TypeAlias = tuple[float, ...]
_ZERO6: Final[_Vec6] = (0.0,) * _JOINTS


# --- ROBOT_STATE sub-packages (§2.2) -------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class RobotModeData:
    """ROBOT_MODE_DATA (0): uint64 timestamp, 7 bools, int8 robot_mode (§6.1), uint8 control_mode, 3 doubles.

    e-Series controllers (URSim 5.8) append one reserved byte (47-byte sub-package); CB3 controllers do
    not (46 bytes). ``reserved`` is that byte, or None for the CB3 layout (sent and received as such).
    """

    timestamp: int = 0
    is_real_robot_connected: bool = False
    is_real_robot_enabled: bool = False
    is_robot_power_on: bool = False
    is_emergency_stopped: bool = False
    is_protective_stopped: bool = False
    is_program_running: bool = False
    is_program_paused: bool = False
    robot_mode: int = 0
    control_mode: int = 0
    target_speed_fraction: float = 0.0
    speed_scaling: float = 0.0
    target_speed_fraction_limit: float = 0.0
    reserved: int | None = 0


@dataclass(frozen=True, slots=True)
class JointData:
    """JOINT_DATA (1): per joint q_actual, q_target, qd_actual (double), I, V, T_motor, T_micro (float), mode.

    On the wire the eight values of joint 0 come first (41 bytes a joint, mode is a uint8); here each
    field is a 6-tuple.
    """

    q_actual: _Vec6 = _ZERO6
    q_target: _Vec6 = _ZERO6
    qd_actual: _Vec6 = _ZERO6
    i_actual: _Vec6 = _ZERO6
    v_actual: _Vec6 = _ZERO6
    t_motor: _Vec6 = _ZERO6
    t_micro: _Vec6 = _ZERO6
    joint_mode: tuple[int, ...] = (0,) * _JOINTS


@dataclass(frozen=True, slots=True)
class ToolData:
    """TOOL_DATA (2): uint8 ×2, double ×2, float, uint8, float ×2, uint8 tool_mode (253 = running)."""

    analog_input_range2: int = 0
    analog_input_range3: int = 0
    analog_input2: float = 0.0
    analog_input3: float = 0.0
    tool_voltage_48v: float = 0.0
    tool_output_voltage: int = 0
    tool_current: float = 0.0
    tool_temperature: float = 0.0
    tool_mode: int = 0


@dataclass(frozen=True, slots=True)
class Euromap67:
    """The conditional Euromap67 (IMMI) block of MASTERBOARD_DATA: uint32 ×2 bits, float 24 V, float A."""

    input_bits: int = 0
    output_bits: int = 0
    voltage_24v: float = 0.0
    current: float = 0.0


@dataclass(frozen=True, slots=True)
class MasterboardData:
    """MASTERBOARD_DATA (3); ``euromap67`` is None when the "installed" byte is 0 (then 16 bytes shorter)::

    uint32 ×2 digital bits | uint8 ×2 analog input ranges | double ×2 analog inputs | int8 ×2 output domains
    | double ×2 analog outputs | float ×4 temperature, 48 V, current, IO current | uint8 safety_mode
    | bool in_reduced_mode | bool euromap67 installed | [Euromap67: 16 bytes] | uint32 reserved_1
    | uint8 operational_mode_selector_input | bool three_position_enabling_device_input | uint8 reserved_2
    """

    digital_input_bits: int = 0
    digital_output_bits: int = 0
    analog_input_range0: int = 0
    analog_input_range1: int = 0
    analog_input0: float = 0.0
    analog_input1: float = 0.0
    analog_output_domain0: int = 0
    analog_output_domain1: int = 0
    analog_output0: float = 0.0
    analog_output1: float = 0.0
    masterboard_temperature: float = 0.0
    robot_voltage_48v: float = 0.0
    robot_current: float = 0.0
    master_io_current: float = 0.0
    safety_mode: int = 0
    in_reduced_mode: bool = False
    euromap67: Euromap67 | None = None
    reserved_1: int = 0
    operational_mode_selector_input: int = 0
    three_position_enabling_device_input: bool = False
    reserved_2: int = 0


@dataclass(frozen=True, slots=True)
class CartesianInfo:
    """CARTESIAN_INFO (4): 12 doubles, TCP pose X, Y, Z, Rx, Ry, Rz then the TCP offset in the same order."""

    tcp_pose: _Vec6 = _ZERO6
    tcp_offset: _Vec6 = _ZERO6


@dataclass(frozen=True, slots=True)
class KinematicsInfo:
    """KINEMATICS_INFO (5): uint32 checksum[6], double theta[6], a[6], d[6], alpha[6], uint32 calibration."""

    checksum: tuple[int, ...] = (0,) * _JOINTS
    dh_theta: _Vec6 = _ZERO6
    dh_a: _Vec6 = _ZERO6
    dh_d: _Vec6 = _ZERO6
    dh_alpha: _Vec6 = _ZERO6
    calibration_status: int = 0

    def kinematics_hash(self) -> str:
        """The ``calib_<digits>`` hash of these DH parameters (§2.6), to compare with the description's."""
        return kinematics_hash(self.dh_theta, self.dh_a, self.dh_d, self.dh_alpha)


@dataclass(frozen=True, slots=True)
class ConfigurationData:
    """CONFIGURATION_DATA (6), 440-byte body + 0–2 optional int16 ``reserved`` (newer software)::

    per joint (min, max) limit | per joint (max speed, max acceleration) | v_joint, a_joint, v_tool,
    a_tool defaults, eq_radius | dh_a[6], dh_d[6], dh_alpha[6], dh_theta[6] | int32 masterboard_version,
    controller_box_type, robot_type, robot_sub_type | [int16 reserved ...]
    """

    joint_min_limit: _Vec6 = _ZERO6
    joint_max_limit: _Vec6 = _ZERO6
    joint_max_speed: _Vec6 = _ZERO6
    joint_max_acceleration: _Vec6 = _ZERO6
    v_joint_default: float = 0.0
    a_joint_default: float = 0.0
    v_tool_default: float = 0.0
    a_tool_default: float = 0.0
    eq_radius: float = 0.0
    dh_a: _Vec6 = _ZERO6
    dh_d: _Vec6 = _ZERO6
    dh_alpha: _Vec6 = _ZERO6
    dh_theta: _Vec6 = _ZERO6
    masterboard_version: int = 0
    controller_box_type: int = 0
    robot_type: int = 0
    robot_sub_type: int = 0
    reserved: tuple[int, ...] = ()


@dataclass(frozen=True, slots=True)
class ForceModeData:
    """FORCE_MODE_DATA (7): 7 doubles, wrench Fx, Fy, Fz, Frx, Fry, Frz and robot dexterity."""

    wrench: _Vec6 = _ZERO6
    robot_dexterity: float = 0.0


@dataclass(frozen=True, slots=True)
class AdditionalInfo:
    """ADDITIONAL_INFO (8): uint8 freedrive button state, bool button enabled, bool IO freedrive, uint8."""

    freedrive_button_pressed: int = 0
    freedrive_button_enabled: bool = False
    io_enabled_freedrive: bool = False
    reserved: int = 0


@dataclass(frozen=True, slots=True)
class ToolCommInfo:
    """TOOL_COMM_INFO (11): bool enabled, int32 baud rate, parity, stop bits, float rx/tx idle chars."""

    enabled: bool = False
    baud_rate: int = 0
    parity: int = 0
    stop_bits: int = 0
    rx_idle_chars: float = 0.0
    tx_idle_chars: float = 0.0


@dataclass(frozen=True, slots=True)
class ToolModeInfo:
    """TOOL_MODE_INFO (12): uint8 output mode, uint8 digital output 0 mode, uint8 digital output 1 mode."""

    output_mode: int = 0
    digital_output_mode0: int = 0
    digital_output_mode1: int = 0


@dataclass(frozen=True, slots=True)
class UnknownSubPackage:
    """A sub-package this codec does not model (9, 10 or a newer type): its type byte and raw body."""

    type: int
    body: bytes


SubPackage: TypeAlias = (
    RobotModeData
    | JointData
    | ToolData
    | MasterboardData
    | CartesianInfo
    | KinematicsInfo
    | ConfigurationData
    | ForceModeData
    | AdditionalInfo
    | ToolCommInfo
    | ToolModeInfo
    | UnknownSubPackage
)

_S = TypeVar("_S")


@dataclass(frozen=True, slots=True)
class RobotState:
    """One ROBOT_STATE package (16): its sub-packages in wire order. Sent by the robot ~10 Hz (§0)."""

    subpackages: tuple[SubPackage, ...]

    def get(self, kind: type[_S]) -> _S | None:
        """The first sub-package of class ``kind``, or None if this package has none."""
        for sub in self.subpackages:
            if isinstance(sub, kind):
                return sub
        return None


# --- ROBOT_MESSAGE (§2.3) -------------------------------------------------------------------------
# timestamp and source are keyword-only: they come first on the wire but rarely matter to a reader.
# Source values are those seen in captures (−2 on VERSION/KEY, −3 on RUNTIME_EXCEPTION/SAFETY_MODE);
# what they mean is not documented in our sources.


@dataclass(frozen=True, slots=True)
class TextMessage:
    """TEXT (0): text to the end of the package."""

    text: str
    _: KW_ONLY
    timestamp: int = 0
    source: int = -2


@dataclass(frozen=True, slots=True)
class VersionMessage:
    """VERSION (3): int8 N, N bytes project name, uint8 major, minor, int32 bugfix, int32 build, date text.

    Sent right after connecting; e.g. ``URControl`` 5.24, bugfix 0, build 0, ``04-10-2025, 00:25:33``.
    """

    project_name: str
    major_version: int
    minor_version: int
    bugfix_version: int
    build_number: int
    build_date: str
    _: KW_ONLY
    timestamp: int = 0
    source: int = -2


@dataclass(frozen=True, slots=True)
class SafetyModeMessage:
    """SAFETY_MODE (5): int32 code, int32 argument, uint8 safety mode, uint32 data type, 4-byte report data.

    ``report_data`` is an int32 if ``report_data_type`` is 2, a float32 if it is 3, else a uint32.
    """

    code: int
    argument: int
    safety_mode: int
    report_data_type: int
    report_data: int | float
    _: KW_ONLY
    timestamp: int = 0
    source: int = -3


@dataclass(frozen=True, slots=True)
class ErrorCodeMessage:
    """ERROR_CODE (6): int32 code, int32 argument, int32 report level, uint32 data type, uint32 data, text.

    Code 210 means the interface is read-only (local mode, §2.4 step 7).
    """

    code: int
    argument: int
    report_level: int
    data_type: int
    data: int
    text: str
    _: KW_ONLY
    timestamp: int = 0
    source: int = -3


@dataclass(frozen=True, slots=True)
class KeyMessage:
    """KEY (7): int32 code, int32 argument, uint8 N, N bytes title, text (PROGRAM_XXX_STARTED etc., §2.5)."""

    code: int
    argument: int
    title: str
    text: str
    _: KW_ONLY
    timestamp: int = 0
    source: int = -2


@dataclass(frozen=True, slots=True)
class RuntimeExceptionMessage:
    """RUNTIME_EXCEPTION (10): uint32 line, uint32 column (into the sent script), text."""

    line: int
    column: int
    text: str
    _: KW_ONLY
    timestamp: int = 0
    source: int = -3


@dataclass(frozen=True, slots=True)
class OtherRobotMessage:
    """A ROBOT_MESSAGE of a type not modelled here (PROGRAM_LABEL, POPUP, REQUEST_VALUE, ...): raw body."""

    type: int
    body: bytes
    _: KW_ONLY
    timestamp: int = 0
    source: int = -2


_POPUP: Final = struct.Struct(">II???B")
_POPUP_TITLE_MAX: Final = 255


def popup_message(
    text: str, title: str = "Popup", *, warning: bool = False, error: bool = False, blocking: bool = False
) -> OtherRobotMessage:
    """A POPUP (2) robot message, as URScript's ``popup`` makes one: uint32 request id, uint32 requested
    type, bool warning, bool error, bool blocking, uint8 N, N bytes title, text to the end (the layout a
    PolyScope URCap reads off a controller's primary interface)."""
    head = title.encode()[:_POPUP_TITLE_MAX]
    body = _POPUP.pack(0, 0, warning, error, blocking, len(head)) + head + text.encode()
    return OtherRobotMessage(RobotMessageType.POPUP, body)


RobotMessage: TypeAlias = (
    TextMessage
    | VersionMessage
    | SafetyModeMessage
    | ErrorCodeMessage
    | KeyMessage
    | RuntimeExceptionMessage
    | OtherRobotMessage
)


@dataclass(frozen=True, slots=True)
class OtherPackage:
    """A package of a type other than ROBOT_STATE and ROBOT_MESSAGE (22, 5, 23, 24, 25, ...): raw body."""

    type: int
    body: bytes


# --- daemon → robot (§2.4) ------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Script:
    """URScript text for the controller (a program, a ``sec`` block or a command); sent newline-terminated."""

    text: str


@dataclass(frozen=True, slots=True)
class ProgramReceived:
    """Robot side: a top-level ``def``/``sec`` block closed by ``end`` at column 0; ``text`` is all of it."""

    kind: Literal["def", "sec"]
    name: str
    text: str


@dataclass(frozen=True, slots=True)
class CommandReceived:
    """Robot side: one top-level line outside a block (``power on``, ``stop program``, ...), stripped."""

    line: str


PrimaryMessage: TypeAlias = Script | RobotState | RobotMessage | OtherPackage
PrimaryEvent: TypeAlias = RobotState | RobotMessage | OtherPackage | ProgramReceived | CommandReceived


# --- script helpers (§2.4, §5.8) ------------------------------------------------------------------


def _check_name(name: str) -> None:
    if not _NAME_PATTERN.fullmatch(name) or len(name) > MAX_SCRIPT_NAME_LENGTH:
        raise LocalProtocolError(
            f"primary: program name {name!r} is not [A-Za-z_][A-Za-z0-9_]* of at most "
            f"{MAX_SCRIPT_NAME_LENGTH} characters",
            protocol=PROTOCOL,
        )


def _indented(body: str, indent: str) -> str:
    lines = body.removesuffix("\n").split("\n") if body else []
    return "".join(f"{indent}{line}\n" for line in lines)


def def_program(name: str, body: str, indent: str = "  ") -> str:
    """``def NAME():``, the body indented, ``end``: a program replacing the running one (§2.4 step 2)."""
    _check_name(name)
    return f"def {name}():\n{_indented(body, indent)}end\n"


def sec_program(name: str, body: str, indent: str = "  ") -> str:
    """``sec NAME():``, the body indented, ``end``: a secondary program, no motion (§2.4 step 3)."""
    _check_name(name)
    return f"sec {name}():\n{_indented(body, indent)}end\n"


def headless_program(script: str, name: str = "externalControl") -> str:
    """Headless wrapping of the External Control script (§5.8): ``stop program``, ``def`` tab-indented."""
    return f"{ControllerCommand.STOP_PROGRAM}\n" + def_program(name, script, indent="\t")


# --- sub-package codecs ---------------------------------------------------------------------------


def _local(message: str) -> LocalProtocolError:
    return LocalProtocolError(f"{PROTOCOL}: {message}", protocol=PROTOCOL)


class _Malformed(Exception):
    """A body that does not fit its layout; turned into RemoteProtocolError with the offset."""


def _vec(values: Sequence[Any], name: str) -> Sequence[Any]:
    if len(values) != _JOINTS:
        raise _local(f"{name} needs {_JOINTS} values, got {len(values)}")
    return values


def _flat_codec(cls: type[Any], layout: str) -> tuple[Callable[[bytes], Any], Callable[[Any], bytes]]:
    """Decoder and encoder for a sub-package whose fields are exactly ``layout``'s values, in order."""
    packer = struct.Struct(layout)
    names = tuple(f.name for f in fields(cls))

    def decode(body: bytes) -> Any:
        return cls(*packer.unpack_from(body))

    def encode(sub: Any) -> bytes:
        return packer.pack(*[getattr(sub, name) for name in names])

    return decode, encode


_JOINT: Final = struct.Struct(">" + "3d4fB" * _JOINTS)
_MB_HEAD: Final = struct.Struct(">IIBBddbbddffffB??")
_MB_EUROMAP: Final = struct.Struct(">IIff")
_MB_TAIL: Final = struct.Struct(">IB?B")
_CARTESIAN: Final = struct.Struct(">12d")
_KINEMATICS: Final = struct.Struct(">6I24dI")
_CONFIGURATION: Final = struct.Struct(">24d5d24d4i")
_CONFIG_RESERVED: Final = struct.Struct(">h")
_CONFIG_RESERVED_MAX: Final = 2  # urcl reads at most two optional int16 (§2.2)
_FORCE: Final = struct.Struct(">7d")


def _decode_joint_data(body: bytes) -> JointData:
    v = _JOINT.unpack_from(body)
    return JointData(*(tuple(v[k::8]) for k in range(8)))


def _encode_joint_data(sub: JointData) -> bytes:
    columns = [
        _vec(sub.q_actual, "q_actual"),
        _vec(sub.q_target, "q_target"),
        _vec(sub.qd_actual, "qd_actual"),
        _vec(sub.i_actual, "i_actual"),
        _vec(sub.v_actual, "v_actual"),
        _vec(sub.t_motor, "t_motor"),
        _vec(sub.t_micro, "t_micro"),
        _vec(sub.joint_mode, "joint_mode"),
    ]
    return _JOINT.pack(*[column[j] for j in range(_JOINTS) for column in columns])


def _decode_masterboard(body: bytes) -> MasterboardData:
    head = _MB_HEAD.unpack_from(body)
    offset = _MB_HEAD.size
    euromap = None
    if head[-1]:
        euromap = Euromap67(*_MB_EUROMAP.unpack_from(body, offset))
        offset += _MB_EUROMAP.size
    return MasterboardData(*(*head[:-1], euromap, *_MB_TAIL.unpack_from(body, offset)))


def _encode_masterboard(sub: MasterboardData) -> bytes:
    m, e = sub, sub.euromap67
    out = _MB_HEAD.pack(
        m.digital_input_bits, m.digital_output_bits, m.analog_input_range0, m.analog_input_range1,
        m.analog_input0, m.analog_input1, m.analog_output_domain0, m.analog_output_domain1,
        m.analog_output0, m.analog_output1, m.masterboard_temperature, m.robot_voltage_48v,
        m.robot_current, m.master_io_current, m.safety_mode, m.in_reduced_mode, e is not None,
    )  # fmt: skip
    if e is not None:
        out += _MB_EUROMAP.pack(e.input_bits, e.output_bits, e.voltage_24v, e.current)
    return out + _MB_TAIL.pack(
        m.reserved_1, m.operational_mode_selector_input, m.three_position_enabling_device_input, m.reserved_2
    )


def _decode_cartesian(body: bytes) -> CartesianInfo:
    v = _CARTESIAN.unpack_from(body)
    return CartesianInfo(v[:6], v[6:])


def _encode_cartesian(sub: CartesianInfo) -> bytes:
    return _CARTESIAN.pack(*_vec(sub.tcp_pose, "tcp_pose"), *_vec(sub.tcp_offset, "tcp_offset"))


def _decode_kinematics(body: bytes) -> KinematicsInfo:
    v = _KINEMATICS.unpack_from(body)
    return KinematicsInfo(v[0:6], v[6:12], v[12:18], v[18:24], v[24:30], v[30])


def _encode_kinematics(sub: KinematicsInfo) -> bytes:
    return _KINEMATICS.pack(
        *_vec(sub.checksum, "checksum"),
        *_vec(sub.dh_theta, "dh_theta"),
        *_vec(sub.dh_a, "dh_a"),
        *_vec(sub.dh_d, "dh_d"),
        *_vec(sub.dh_alpha, "dh_alpha"),
        sub.calibration_status,
    )


def _decode_configuration(body: bytes) -> ConfigurationData:
    v = _CONFIGURATION.unpack_from(body)
    reserved: list[int] = []
    offset = _CONFIGURATION.size
    # newer software appends int16s; urcl reads each one only if its 2 bytes are there (§2.2)
    while len(reserved) < _CONFIG_RESERVED_MAX and offset + _CONFIG_RESERVED.size <= len(body):
        reserved.append(_CONFIG_RESERVED.unpack_from(body, offset)[0])
        offset += _CONFIG_RESERVED.size
    # wire: (min, max) per joint, (speed, acc) per joint, 5 defaults, dh a/d/alpha/theta, 4 int32
    vectors = (v[0:12:2], v[1:12:2], v[12:24:2], v[13:24:2])
    dh = (v[29:35], v[35:41], v[41:47], v[47:53])
    return ConfigurationData(*(*vectors, *v[24:29], *dh, *v[53:57], tuple(reserved)))


def _encode_configuration(sub: ConfigurationData) -> bytes:
    c = sub
    if len(c.reserved) > _CONFIG_RESERVED_MAX:
        raise _local("CONFIGURATION_DATA has at most 2 reserved int16")
    limits = zip(
        _vec(c.joint_min_limit, "joint_min_limit"), _vec(c.joint_max_limit, "max_limit"), strict=True
    )
    motion = zip(_vec(c.joint_max_speed, "max_speed"), _vec(c.joint_max_acceleration, "max_acc"), strict=True)
    out = _CONFIGURATION.pack(
        *[x for pair in limits for x in pair],
        *[x for pair in motion for x in pair],
        c.v_joint_default, c.a_joint_default, c.v_tool_default, c.a_tool_default, c.eq_radius,
        *_vec(c.dh_a, "dh_a"), *_vec(c.dh_d, "dh_d"), *_vec(c.dh_alpha, "dh_alpha"),
        *_vec(c.dh_theta, "dh_theta"),
        c.masterboard_version, c.controller_box_type, c.robot_type, c.robot_sub_type,
    )  # fmt: skip
    return out + b"".join(_CONFIG_RESERVED.pack(r) for r in c.reserved)


def _decode_force(body: bytes) -> ForceModeData:
    v = _FORCE.unpack_from(body)
    return ForceModeData(v[:6], v[6])


def _encode_force(sub: ForceModeData) -> bytes:
    return _FORCE.pack(*_vec(sub.wrench, "wrench"), sub.robot_dexterity)


_Decoder: TypeAlias = Callable[[bytes], Any]
_Encoder: TypeAlias = Callable[[Any], bytes]

_ROBOT_MODE: Final = struct.Struct(">Q7?bB3d")
_ROBOT_MODE_RESERVED: Final = struct.Struct(">B")


def _decode_robot_mode(body: bytes) -> RobotModeData:
    values = _ROBOT_MODE.unpack_from(body)
    reserved = body[_ROBOT_MODE.size] if len(body) > _ROBOT_MODE.size else None
    return RobotModeData(**dict(zip(_ROBOT_MODE_FIELDS, values, strict=True)), reserved=reserved)


def _encode_robot_mode(sub: RobotModeData) -> bytes:
    body = _ROBOT_MODE.pack(*[getattr(sub, name) for name in _ROBOT_MODE_FIELDS])
    return body if sub.reserved is None else body + _ROBOT_MODE_RESERVED.pack(sub.reserved)


_ROBOT_MODE_FIELDS: Final = tuple(f.name for f in fields(RobotModeData))[:-1]
_tool_codec = _flat_codec(ToolData, ">BBddfBffB")
_additional_codec = _flat_codec(AdditionalInfo, ">B??B")
_tool_comm_codec = _flat_codec(ToolCommInfo, ">?iiiff")
_tool_mode_codec = _flat_codec(ToolModeInfo, ">BBB")

# type byte -> (class, decoder, encoder): the dispatch table both directions use
_SUB_CODECS: Final[dict[int, tuple[type[Any], _Decoder, _Encoder]]] = {
    SubPackageType.ROBOT_MODE_DATA: (RobotModeData, _decode_robot_mode, _encode_robot_mode),
    SubPackageType.JOINT_DATA: (JointData, _decode_joint_data, _encode_joint_data),
    SubPackageType.TOOL_DATA: (ToolData, *_tool_codec),
    SubPackageType.MASTERBOARD_DATA: (MasterboardData, _decode_masterboard, _encode_masterboard),
    SubPackageType.CARTESIAN_INFO: (CartesianInfo, _decode_cartesian, _encode_cartesian),
    SubPackageType.KINEMATICS_INFO: (KinematicsInfo, _decode_kinematics, _encode_kinematics),
    SubPackageType.CONFIGURATION_DATA: (ConfigurationData, _decode_configuration, _encode_configuration),
    SubPackageType.FORCE_MODE_DATA: (ForceModeData, _decode_force, _encode_force),
    SubPackageType.ADDITIONAL_INFO: (AdditionalInfo, *_additional_codec),
    SubPackageType.TOOL_COMM_INFO: (ToolCommInfo, *_tool_comm_codec),
    SubPackageType.TOOL_MODE_INFO: (ToolModeInfo, *_tool_mode_codec),
}
_SUB_DECODERS: Final = {kind: decode for kind, (_, decode, _) in _SUB_CODECS.items()}
_SUB_ENCODERS: Final = {cls: (kind, encode) for kind, (cls, _, encode) in _SUB_CODECS.items()}


# --- robot-message codecs -------------------------------------------------------------------------

_INT8: Final = struct.Struct(">b")
_INT8_MAX: Final = 127
_UINT8_MAX: Final = 255
_VERSION_NUMBERS: Final = struct.Struct(">BBii")
_SAFETY_MODE: Final = struct.Struct(">iiBI")
_REPORT_DATA: Final = {2: struct.Struct(">i"), 3: struct.Struct(">f")}
_REPORT_DATA_DEFAULT: Final = struct.Struct(">I")
_CODE_ARG: Final = struct.Struct(">iiB")  # KEY: code, argument, title length
_ERROR_CODE: Final = struct.Struct(">iiiII")
_RUNTIME_EXCEPTION: Final = struct.Struct(">II")


def _text(data: bytes) -> str:
    # the controller's text encoding is not documented; UTF-8 is ASCII-compatible, and an undecodable
    # byte in a log text must not cost the connection
    return data.decode("utf-8", errors="replace")


def _decode_version(p: bytes, ts: int, src: int) -> VersionMessage:
    n = _INT8.unpack_from(p)[0]
    if n < 0:
        raise _Malformed(f"VERSION project name length {n} < 0")
    numbers = _VERSION_NUMBERS.unpack_from(p, 1 + n)
    end = 1 + n + _VERSION_NUMBERS.size
    major, minor, bugfix, build = numbers
    return VersionMessage(
        _text(p[1 : 1 + n]), major, minor, bugfix, build, _text(p[end:]), timestamp=ts, source=src
    )


def _decode_safety_mode(p: bytes, ts: int, src: int) -> SafetyModeMessage:
    code, argument, mode, data_type = _SAFETY_MODE.unpack_from(p)
    data = _REPORT_DATA.get(data_type, _REPORT_DATA_DEFAULT).unpack_from(p, _SAFETY_MODE.size)[0]
    return SafetyModeMessage(code, argument, mode, data_type, data, timestamp=ts, source=src)


def _decode_error_code(p: bytes, ts: int, src: int) -> ErrorCodeMessage:
    code, argument, level, data_type, data = _ERROR_CODE.unpack_from(p)
    text = _text(p[_ERROR_CODE.size :])
    return ErrorCodeMessage(code, argument, level, data_type, data, text, timestamp=ts, source=src)


def _decode_key(p: bytes, ts: int, src: int) -> KeyMessage:
    code, argument, n = _CODE_ARG.unpack_from(p)
    start = _CODE_ARG.size
    if len(p) < start + n:
        raise _Malformed(f"KEY title of {n} bytes runs past the message")
    return KeyMessage(
        code, argument, _text(p[start : start + n]), _text(p[start + n :]), timestamp=ts, source=src
    )


def _decode_runtime_exception(p: bytes, ts: int, src: int) -> RuntimeExceptionMessage:
    line, column = _RUNTIME_EXCEPTION.unpack_from(p)
    return RuntimeExceptionMessage(
        line, column, _text(p[_RUNTIME_EXCEPTION.size :]), timestamp=ts, source=src
    )


def _decode_text(p: bytes, ts: int, src: int) -> TextMessage:
    return TextMessage(_text(p), timestamp=ts, source=src)


_MESSAGE_DECODERS: Final[dict[int, Callable[[bytes, int, int], RobotMessage]]] = {
    RobotMessageType.TEXT: _decode_text,
    RobotMessageType.VERSION: _decode_version,
    RobotMessageType.SAFETY_MODE: _decode_safety_mode,
    RobotMessageType.ERROR_CODE: _decode_error_code,
    RobotMessageType.KEY: _decode_key,
    RobotMessageType.RUNTIME_EXCEPTION: _decode_runtime_exception,
}


def _encode_message(m: RobotMessage) -> tuple[int, bytes]:
    """(robot message type, message body) of one robot message."""
    match m:
        case TextMessage():
            return RobotMessageType.TEXT, m.text.encode()
        case VersionMessage():
            name = m.project_name.encode()
            if len(name) > _INT8_MAX:  # int8 length prefix
                raise _local(f"VERSION project name over {_INT8_MAX} bytes")
            head = _INT8.pack(len(name)) + name
            numbers = _VERSION_NUMBERS.pack(
                m.major_version, m.minor_version, m.bugfix_version, m.build_number
            )
            return RobotMessageType.VERSION, head + numbers + m.build_date.encode()
        case SafetyModeMessage():
            data = _REPORT_DATA.get(m.report_data_type, _REPORT_DATA_DEFAULT).pack(m.report_data)
            head = _SAFETY_MODE.pack(m.code, m.argument, m.safety_mode, m.report_data_type)
            return RobotMessageType.SAFETY_MODE, head + data
        case ErrorCodeMessage():
            head = _ERROR_CODE.pack(m.code, m.argument, m.report_level, m.data_type, m.data)
            return RobotMessageType.ERROR_CODE, head + m.text.encode()
        case KeyMessage():
            title = m.title.encode()
            if len(title) > _UINT8_MAX:  # uint8 length prefix
                raise _local(f"KEY title over {_UINT8_MAX} bytes")
            head = _CODE_ARG.pack(m.code, m.argument, len(title))
            return RobotMessageType.KEY, head + title + m.text.encode()
        case RuntimeExceptionMessage():
            head = _RUNTIME_EXCEPTION.pack(m.line, m.column)
            return RobotMessageType.RUNTIME_EXCEPTION, head + m.text.encode()
        case OtherRobotMessage():
            if m.type in _MESSAGE_DECODERS:
                raise _local(f"robot message type {m.type} is modelled; send its class")
            return m.type, bytes(m.body)


_ROBOT_MESSAGE_CLASSES: Final = (
    TextMessage,
    VersionMessage,
    SafetyModeMessage,
    ErrorCodeMessage,
    KeyMessage,
    RuntimeExceptionMessage,
    OtherRobotMessage,
)


# --- the connection -------------------------------------------------------------------------------


class PrimaryConnection(Codec["PrimaryMessage", "PrimaryEvent"]):
    """One primary/secondary-interface TCP connection, for either party; see the module docstring."""

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
                raise _local(f"the daemon sends only Script, not {message!r}")
            self._queue(_encode_script(message.text))
            return
        if isinstance(message, Script):
            raise _local("the robot side does not send Script")
        try:
            self._queue(_encode_package(message))
        except (struct.error, OverflowError, TypeError) as err:
            raise _local(f"cannot encode {message!r}: {err}") from err

    # --- daemon side: packages ---

    def _error(self, message: str, offset: int) -> RemoteProtocolError:
        return RemoteProtocolError(f"primary: {message}", protocol=PROTOCOL, offset=self._consumed + offset)

    def _parse_packages(self, events: list[PrimaryEvent]) -> None:
        while (header := self._buffer.peek(_HEADER_BYTES)) is not None:
            length, kind = _HEADER.unpack(header)
            if not _HEADER_BYTES <= length <= MAX_PACKAGE_BYTES:
                raise self._error(
                    f"package length {length} outside [{_HEADER_BYTES}, {MAX_PACKAGE_BYTES}]", 0
                )
            package = self._buffer.take(length)
            if package is None:
                return
            if kind == PackageType.ROBOT_STATE:
                events.append(self._decode_robot_state(package))
            elif kind == PackageType.ROBOT_MESSAGE:
                events.append(self._decode_robot_message(package))
            else:
                events.append(OtherPackage(kind, package[_HEADER_BYTES:]))
            self._consumed += length

    def _decode_robot_state(self, package: bytes) -> RobotState:
        subs: list[SubPackage] = []
        pos = _HEADER_BYTES
        while pos < len(package):
            if len(package) - pos < _HEADER_BYTES:
                raise self._error("ROBOT_STATE ends inside a sub-package header", pos)
            length, kind = _SUB_HEADER.unpack_from(package, pos)
            end = pos + length
            if length < _HEADER_BYTES or end > len(package):
                raise self._error(f"sub-package {kind} length {length} does not fit the package", pos)
            body = package[pos + _HEADER_BYTES : end]
            decode = _SUB_DECODERS.get(kind)
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
        if len(package) < _HEADER_BYTES + _MESSAGE_HEADER.size:
            raise self._error(f"ROBOT_MESSAGE of {len(package)} bytes has no message header", 0)
        timestamp, source, kind = _MESSAGE_HEADER.unpack_from(package, _HEADER_BYTES)
        payload = package[_HEADER_BYTES + _MESSAGE_HEADER.size :]
        decode = _MESSAGE_DECODERS.get(kind)
        if decode is None:
            return OtherRobotMessage(kind, payload, timestamp=timestamp, source=source)
        try:
            return decode(payload, timestamp, source)
        except (struct.error, _Malformed) as err:
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
            start = _BLOCK_START.fullmatch(line)
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
        if _BLOCK_END.fullmatch(line) is None:
            return None
        event = ProgramReceived(self._block_kind, self._block_name, "\n".join(self._block_lines) + "\n")
        self._block_kind, self._block_lines, self._block_bytes = None, [], 0
        return event


def _encode_script(text: str) -> bytes:
    if not text.endswith("\n"):
        text += "\n"  # §2.4 step 1: the controller runs only newline-terminated text
    try:
        data = text.encode("ascii")
    except UnicodeEncodeError as err:
        raise _local(f"script is not ASCII at {err.start} (§2.4)") from err
    if len(data) > MAX_SCRIPT_BYTES:
        raise _local(f"script of {len(data)} bytes > {MAX_SCRIPT_BYTES}")
    return data


def _frame(kind: int, body: bytes) -> bytes:
    length = _HEADER_BYTES + len(body)
    if length > MAX_PACKAGE_BYTES:
        raise _local(f"package of {length} bytes > {MAX_PACKAGE_BYTES}")
    return _HEADER.pack(length, kind) + body


def _encode_subpackage(sub: SubPackage) -> bytes:
    if isinstance(sub, UnknownSubPackage):
        if sub.type in _SUB_DECODERS:
            raise _local(f"sub-package {sub.type} is modelled; send its class")
        kind, body = sub.type, bytes(sub.body)
    else:
        entry = _SUB_ENCODERS.get(type(sub))
        if entry is None:
            raise _local(f"{sub!r} is not a sub-package")
        kind, body = entry[0], entry[1](sub)
    return _SUB_HEADER.pack(_HEADER_BYTES + len(body), kind) + body


def _encode_package(message: PrimaryMessage) -> bytes:
    if isinstance(message, RobotState):
        return _frame(PackageType.ROBOT_STATE, b"".join(_encode_subpackage(s) for s in message.subpackages))
    if isinstance(message, _ROBOT_MESSAGE_CLASSES):
        kind, body = _encode_message(message)
        return _frame(
            PackageType.ROBOT_MESSAGE, _MESSAGE_HEADER.pack(message.timestamp, message.source, kind) + body
        )
    if isinstance(message, OtherPackage):
        if message.type in (PackageType.ROBOT_STATE, PackageType.ROBOT_MESSAGE):
            raise _local(f"package type {message.type} is modelled")
        return _frame(message.type, bytes(message.body))
    raise _local(f"cannot send {message!r}")
