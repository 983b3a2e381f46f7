"""What each primary-interface party sends and receives: one frozen dataclass per package kind.

The robot sends ROBOT_STATE (``RobotState``, its sub-packages in wire order; §2.2), ROBOT_MESSAGE (one class
per modelled message type; §2.3) and any other package as ``OtherPackage``; the daemon sends ``Script``
text, which the robot side reads as ``ProgramReceived`` / ``CommandReceived`` (§2.4).
"""

from __future__ import annotations

import struct
from dataclasses import KW_ONLY, dataclass
from typing import Final, Literal, TypeAlias, TypeVar

from urdaemon.protocols.kinematics_hash import kinematics_hash
from urdaemon.protocols.primary._wire import JOINTS, RobotMessageType

__all__ = [
    "AdditionalInfo",
    "CartesianInfo",
    "CommandReceived",
    "ConfigurationData",
    "ErrorCodeMessage",
    "Euromap67",
    "ForceModeData",
    "JointData",
    "KeyMessage",
    "KinematicsInfo",
    "MasterboardData",
    "OtherPackage",
    "OtherRobotMessage",
    "PrimaryEvent",
    "PrimaryMessage",
    "ProgramReceived",
    "RobotMessage",
    "RobotModeData",
    "RobotState",
    "RuntimeExceptionMessage",
    "SafetyModeMessage",
    "Script",
    "SubPackage",
    "TextMessage",
    "ToolCommInfo",
    "ToolData",
    "ToolModeInfo",
    "UnknownSubPackage",
    "VersionMessage",
    "popup_message",
]

_Vec6: TypeAlias = tuple[float, ...]
_ZERO6: Final[_Vec6] = (0.0,) * JOINTS


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
    joint_mode: tuple[int, ...] = (0,) * JOINTS


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

    checksum: tuple[int, ...] = (0,) * JOINTS
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
