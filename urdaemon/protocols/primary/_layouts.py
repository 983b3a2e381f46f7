"""The byte layouts of ROBOT_STATE sub-packages (§2.2) and ROBOT_MESSAGE bodies (§2.3), both directions.

``SUB_DECODERS`` / ``SUB_ENCODERS`` map a sub-package's type byte to its decoder and its class to (type byte,
encoder); ``MESSAGE_DECODERS`` and ``encode_message`` do the same for robot messages. A decoder raises
``struct.error`` or ``Malformed`` on a body too short for its layout; the connection adds the offset.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Sequence
from dataclasses import fields
from typing import Any, Final, TypeAlias

from urdaemon.protocols.primary._events import (
    AdditionalInfo,
    CartesianInfo,
    ConfigurationData,
    ErrorCodeMessage,
    Euromap67,
    ForceModeData,
    JointData,
    KeyMessage,
    KinematicsInfo,
    MasterboardData,
    OtherRobotMessage,
    RobotMessage,
    RobotModeData,
    RuntimeExceptionMessage,
    SafetyModeMessage,
    TextMessage,
    ToolCommInfo,
    ToolData,
    ToolModeInfo,
    VersionMessage,
)
from urdaemon.protocols.primary._wire import JOINTS, Malformed, RobotMessageType, SubPackageType, local_error

__all__ = ["MESSAGE_DECODERS", "ROBOT_MESSAGE_CLASSES", "SUB_DECODERS", "SUB_ENCODERS", "encode_message"]


def _vec(values: Sequence[Any], name: str) -> Sequence[Any]:
    if len(values) != JOINTS:
        raise local_error(f"{name} needs {JOINTS} values, got {len(values)}")
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


_JOINT: Final = struct.Struct(">" + "3d4fB" * JOINTS)
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
    return _JOINT.pack(*[column[j] for j in range(JOINTS) for column in columns])


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
        raise local_error("CONFIGURATION_DATA has at most 2 reserved int16")
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
SUB_DECODERS: Final = {kind: decode for kind, (_, decode, _) in _SUB_CODECS.items()}
SUB_ENCODERS: Final = {cls: (kind, encode) for kind, (cls, _, encode) in _SUB_CODECS.items()}


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
        raise Malformed(f"VERSION project name length {n} < 0")
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
        raise Malformed(f"KEY title of {n} bytes runs past the message")
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


MESSAGE_DECODERS: Final[dict[int, Callable[[bytes, int, int], RobotMessage]]] = {
    RobotMessageType.TEXT: _decode_text,
    RobotMessageType.VERSION: _decode_version,
    RobotMessageType.SAFETY_MODE: _decode_safety_mode,
    RobotMessageType.ERROR_CODE: _decode_error_code,
    RobotMessageType.KEY: _decode_key,
    RobotMessageType.RUNTIME_EXCEPTION: _decode_runtime_exception,
}


def encode_message(m: RobotMessage) -> tuple[int, bytes]:
    """(robot message type, message body) of one robot message."""
    match m:
        case TextMessage():
            return RobotMessageType.TEXT, m.text.encode()
        case VersionMessage():
            name = m.project_name.encode()
            if len(name) > _INT8_MAX:  # int8 length prefix
                raise local_error(f"VERSION project name over {_INT8_MAX} bytes")
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
                raise local_error(f"KEY title over {_UINT8_MAX} bytes")
            head = _CODE_ARG.pack(m.code, m.argument, len(title))
            return RobotMessageType.KEY, head + title + m.text.encode()
        case RuntimeExceptionMessage():
            head = _RUNTIME_EXCEPTION.pack(m.line, m.column)
            return RobotMessageType.RUNTIME_EXCEPTION, head + m.text.encode()
        case OtherRobotMessage():
            if m.type in MESSAGE_DECODERS:
                raise local_error(f"robot message type {m.type} is modelled; send its class")
            return m.type, bytes(m.body)


ROBOT_MESSAGE_CLASSES: Final = (
    TextMessage,
    VersionMessage,
    SafetyModeMessage,
    ErrorCodeMessage,
    KeyMessage,
    RuntimeExceptionMessage,
    OtherRobotMessage,
)
