"""Primary / secondary interface codec (docs/protocols.md §2): captures, layouts, round trips, fuzz, pairs."""

from __future__ import annotations

import math
import struct
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.protocols.feeding import feed_all_ways
from urdaemon.errors import LocalProtocolError, RemoteProtocolError
from urdaemon.protocols import Side
from urdaemon.protocols.primary import (
    MAX_PACKAGE_BYTES,
    MAX_SCRIPT_BYTES,
    MAX_SCRIPT_NAME_LENGTH,
    AdditionalInfo,
    CartesianInfo,
    CommandReceived,
    ConfigurationData,
    ControllerCommand,
    ErrorCodeMessage,
    Euromap67,
    ForceModeData,
    JointData,
    KeyMessage,
    KinematicsInfo,
    MasterboardData,
    OtherPackage,
    OtherRobotMessage,
    PackageType,
    PrimaryConnection,
    PrimaryEvent,
    PrimaryMessage,
    ProgramReceived,
    ReportLevel,
    RobotModeData,
    RobotState,
    RuntimeExceptionMessage,
    SafetyModeMessage,
    Script,
    SubPackage,
    SubPackageType,
    TextMessage,
    ToolCommInfo,
    ToolData,
    ToolModeInfo,
    UnknownSubPackage,
    VersionMessage,
    def_program,
    headless_program,
    sec_program,
)

DATA = Path(__file__).resolve().parents[1] / "data" / "primary"
CAPTURED_STATE = (DATA / "ursim58_ur5e_first_robot_state.bin").read_bytes()
CAPTURED_VERSION = (DATA / "version_urcontrol_5_24.bin").read_bytes()
CAPTURED_KEY = (DATA / "key_program_started.bin").read_bytes()

# §2.2: full sub-package lengths observed from URSim 5.8
TABLE_LENGTHS = {
    0: 47,
    1: 251,
    2: 37,
    3: 75,
    4: 101,
    5: 225,
    6: 445,
    7: 61,
    8: 9,
    9: 53,
    10: 43,
    11: 26,
    12: 8,
}
CAPTURE_ORDER = [0, 1, 4, 5, 9, 3, 2, 6, 7, 8, 10, 11, 12]
UR5E_HASH = "calib_12788084448423163542"


def daemon() -> PrimaryConnection:
    return PrimaryConnection(Side.DAEMON)


def robot() -> PrimaryConnection:
    return PrimaryConnection(Side.ROBOT)


def encode(*messages: PrimaryMessage) -> bytes:
    """Bytes of ``messages`` as the robot side sends them."""
    conn = robot()
    for message in messages:
        conn.send(message)
    return conn.data_to_send()


def script_bytes(*texts: str) -> bytes:
    conn = daemon()
    for text in texts:
        conn.send(Script(text))
    return conn.data_to_send()


def feed_repeatedly(conn: PrimaryConnection, chunk: bytes, times: int) -> None:
    for _ in range(times):
        conn.receive_data(chunk)


def walk_subpackages(package: bytes) -> list[tuple[int, int]]:
    """(type, full length) of each sub-package, read with plain struct: independent of the codec."""
    assert struct.unpack_from(">iB", package) == (len(package), 16)
    out, pos = [], 5
    while pos < len(package):
        length, kind = struct.unpack_from(">IB", package, pos)
        out.append((kind, length))
        pos += length
    assert pos == len(package)
    return out


def frame(kind: int, body: bytes) -> bytes:
    return struct.pack(">iB", len(body) + 5, kind) + body


def sub(kind: int, body: bytes) -> bytes:
    return struct.pack(">IB", len(body) + 5, kind) + body


def message(kind: int, payload: bytes, timestamp: int = 0, source: int = -2) -> bytes:
    return frame(20, struct.pack(">QbB", timestamp, source, kind) + payload)


def captured_style_state() -> RobotState:
    """The first ROBOT_STATE of a UR5e built from the values §2.2 lists, in the captured order."""
    nominal = KinematicsInfo(
        checksum=(0xFFFFFFFF,) * 6,
        dh_theta=(0.0,) * 6,
        dh_a=(0.0, -0.425, -0.3922, 0.0, 0.0, 0.0),
        dh_d=(0.1625, 0.0, 0.0, 0.1333, 0.0997, 0.0996),
        dh_alpha=(1.570796327, 0.0, 0.0, 1.570796327, -1.570796327, 0.0),
    )
    configuration = ConfigurationData(
        joint_min_limit=(-6.3355,) * 6,
        joint_max_limit=(6.3355,) * 6,
        joint_max_speed=(3.3416,) * 6,
        joint_max_acceleration=(40.0,) * 6,
        v_joint_default=1.0472,
        a_joint_default=1.3963,
        v_tool_default=0.25,
        a_tool_default=1.2,
        eq_radius=0.25,
        dh_a=nominal.dh_a,
        dh_d=nominal.dh_d,
        dh_alpha=nominal.dh_alpha,
        dh_theta=nominal.dh_theta,
        masterboard_version=6,
        controller_box_type=4,
        robot_type=1,
        robot_sub_type=3,
    )
    return RobotState(
        (
            RobotModeData(is_robot_power_on=True, robot_mode=7, target_speed_fraction=0.97),
            JointData(joint_mode=(253,) * 6),
            CartesianInfo(),
            nominal,
            UnknownSubPackage(9, bytes(48)),
            MasterboardData(safety_mode=1),
            ToolData(tool_mode=253),
            configuration,
            ForceModeData(),
            AdditionalInfo(),
            UnknownSubPackage(10, bytes(38)),
            ToolCommInfo(False, 115200, 0, 1, 1.5, 3.5),
            ToolModeInfo(),
        )
    )


# --- golden: the URSim capture ---------------------------------------------------------------------


def test_captured_robot_state_has_the_sub_package_lengths_of_the_table() -> None:
    assert walk_subpackages(CAPTURED_STATE) == [(k, TABLE_LENGTHS[k]) for k in CAPTURE_ORDER]


def test_captured_robot_state_decodes_fed_whole_split_and_bytewise() -> None:
    [state] = feed_all_ways(daemon, CAPTURED_STATE)
    assert isinstance(state, RobotState)
    kinds = [type(s) for s in state.subpackages]
    assert kinds == [
        RobotModeData,
        JointData,
        CartesianInfo,
        KinematicsInfo,
        UnknownSubPackage,
        MasterboardData,
        ToolData,
        ConfigurationData,
        ForceModeData,
        AdditionalInfo,
        UnknownSubPackage,
        ToolCommInfo,
        ToolModeInfo,
    ]


def test_captured_robot_state_values_match_the_reference() -> None:
    [state] = daemon().receive_data(CAPTURED_STATE)
    assert isinstance(state, RobotState)
    mode = state.get(RobotModeData)
    assert mode is not None
    assert (mode.robot_mode, mode.is_robot_power_on, mode.is_real_robot_enabled) == (7, True, True)
    assert mode.target_speed_fraction == pytest.approx(0.97)
    joints = state.get(JointData)
    assert joints is not None
    assert joints.joint_mode == (253,) * 6
    assert joints.q_actual[0] == pytest.approx(-1.6007)
    tool = state.get(ToolData)
    assert tool is not None
    assert tool.tool_mode == 253
    board = state.get(MasterboardData)
    assert board is not None
    assert (board.safety_mode, board.euromap67) == (1, None)
    kinematics = state.get(KinematicsInfo)
    assert kinematics is not None
    assert kinematics.checksum == (0xFFFFFFFF,) * 6
    assert kinematics.calibration_status == 0
    assert kinematics.kinematics_hash() == UR5E_HASH
    config = state.get(ConfigurationData)
    assert config is not None
    assert config.joint_min_limit == pytest.approx((-6.3355,) * 6, abs=1e-4)
    assert config.joint_max_limit == pytest.approx((6.3355,) * 6, abs=1e-4)
    assert config.joint_max_speed == pytest.approx((3.3416,) * 6, abs=1e-4)
    assert config.joint_max_acceleration == pytest.approx((40.0,) * 6)
    defaults = (config.v_joint_default, config.a_joint_default, config.v_tool_default)
    assert defaults == pytest.approx((1.0472, 1.3963, 0.25), abs=1e-4)
    assert (config.a_tool_default, config.eq_radius) == pytest.approx((1.2, 0.25))
    ids = (config.masterboard_version, config.controller_box_type, config.robot_type, config.robot_sub_type)
    assert ids == (6, 4, 1, 3)
    assert config.reserved == ()
    assert (config.dh_a, config.dh_alpha) == (kinematics.dh_a, kinematics.dh_alpha)
    assert state.get(ToolCommInfo) == ToolCommInfo(False, 115200, 0, 1, 1.5, 3.5)
    unknown = [s for s in state.subpackages if isinstance(s, UnknownSubPackage)]
    assert [(u.type, len(u.body)) for u in unknown] == [(9, 48), (10, 38)]


def test_captured_robot_state_reencodes_byte_for_byte() -> None:
    [state] = daemon().receive_data(CAPTURED_STATE)
    assert isinstance(state, RobotState)
    assert encode(state) == CAPTURED_STATE


def test_captured_style_state_built_by_the_encoder_has_the_table_lengths() -> None:
    data = encode(captured_style_state())
    assert walk_subpackages(data) == [(k, TABLE_LENGTHS[k]) for k in CAPTURE_ORDER]
    assert len(data) == len(CAPTURED_STATE) == 1386
    assert daemon().receive_data(data) == [captured_style_state()]


def test_version_message_matches_the_reference_example() -> None:
    version = VersionMessage("URControl", 5, 24, 0, 0, "04-10-2025, 00:25:33", timestamp=0, source=-2)
    data = encode(version)
    assert len(data) == 55
    assert data == CAPTURED_VERSION
    assert feed_all_ways(daemon, CAPTURED_VERSION) == [version]


def test_version_message_layout_written_by_hand() -> None:
    payload = bytes([9]) + b"URControl" + bytes([5, 24]) + struct.pack(">ii", 0, 0) + b"04-10-2025, 00:25:33"
    assert message(3, payload) == CAPTURED_VERSION


def test_captured_key_message() -> None:
    [key] = feed_all_ways(daemon, CAPTURED_KEY)
    assert key == KeyMessage(0, 0, "PROGRAM_XXX_STARTED", "textmsg", timestamp=0, source=-2)
    assert encode(key) == CAPTURED_KEY


def test_captured_packages_back_to_back_in_one_stream() -> None:
    stream = CAPTURED_VERSION + CAPTURED_STATE + CAPTURED_KEY + CAPTURED_STATE
    events = feed_all_ways(daemon, stream)
    assert [type(e) for e in events] == [VersionMessage, RobotState, KeyMessage, RobotState]


# --- golden: message layouts written by hand from §2.3 ----------------------------------------------


def test_text_message() -> None:
    data = message(0, b"hello robot", timestamp=7, source=-3)
    assert feed_all_ways(daemon, data) == [TextMessage("hello robot", timestamp=7, source=-3)]


def test_runtime_exception_message() -> None:
    text = b"compile_error_name_not_found:txtmsg:"
    data = message(10, struct.pack(">II", 3, 1) + text, source=-3)
    assert len(data) == 5 + 10 + 8 + len(text)
    expected = RuntimeExceptionMessage(3, 1, "compile_error_name_not_found:txtmsg:", source=-3)
    assert feed_all_ways(daemon, data) == [expected]
    assert encode(expected) == data


def test_error_code_message() -> None:
    data = message(6, struct.pack(">iiiII", 210, 0, 4, 0, 0x80070605) + b"C210", source=-3)
    [event] = feed_all_ways(daemon, data)
    assert event == ErrorCodeMessage(210, 0, ReportLevel.FAULT, 0, 0x80070605, "C210", source=-3)
    assert encode(event) == data


@pytest.mark.parametrize(
    ("data_type", "raw", "value"),
    [
        (0, b"\x00\x00\x00\x01", 1),
        (0, b"\x80\x07\x06\x05", 0x80070605),
        (2, b"\xff\xff\xff\xfe", -2),
        (3, struct.pack(">f", 1.5), 1.5),
        (9, b"\xff\xff\xff\xff", 0xFFFFFFFF),
    ],
)
def test_safety_mode_message_report_data_follows_its_type(data_type: int, raw: bytes, value: float) -> None:
    data = message(5, struct.pack(">iiBI", 0, 0, 3, data_type) + raw, source=-3)
    assert len(data) == 32
    [event] = feed_all_ways(daemon, data)
    assert event == SafetyModeMessage(0, 0, 3, data_type, value, source=-3)
    assert encode(event) == data


@pytest.mark.parametrize("kind", [1, 2, 4, 9, 200])
def test_other_robot_messages_are_reported_raw(kind: int) -> None:
    data = message(kind, b"\x01\x02payload", timestamp=99)
    assert feed_all_ways(daemon, data) == [OtherRobotMessage(kind, b"\x01\x02payload", timestamp=99)]


@pytest.mark.parametrize("kind", [22, 5, 23, 24, 25, 0, 255])
def test_other_package_types_are_skipped_by_length_and_reported(kind: int) -> None:
    data = frame(kind, b"\xaa" * 30) + CAPTURED_KEY
    events = feed_all_ways(daemon, data)
    assert events[0] == OtherPackage(kind, b"\xaa" * 30)
    assert isinstance(events[1], KeyMessage)


def test_package_type_enum_covers_the_reference_table() -> None:
    assert {int(t) for t in PackageType} == {5, 16, 20, 22, 23, 24, 25}


# --- sub-package layouts ---------------------------------------------------------------------------


def test_masterboard_with_euromap_block_is_sixteen_bytes_longer() -> None:
    board = MasterboardData(safety_mode=1, euromap67=Euromap67(0x0F, 0xF0, 24.0, 0.5), reserved_1=7)
    data = encode(RobotState((board,)))
    assert walk_subpackages(data) == [(3, 75 + 16)]
    assert feed_all_ways(daemon, data) == [RobotState((board,))]


def test_masterboard_euromap_flag_alone_decides_the_layout() -> None:
    plain = encode(RobotState((MasterboardData(),)))
    body = bytearray(plain[10:])
    body[62] = 1  # "euromap67 installed" without the 16 bytes: too short now
    with pytest.raises(RemoteProtocolError):
        daemon().receive_data(frame(16, sub(3, bytes(body))))


@pytest.mark.parametrize("count", [0, 1, 2])
def test_configuration_data_with_optional_reserved_int16(count: int) -> None:
    config = ConfigurationData(robot_type=1, reserved=(-1, 300)[:count])
    data = encode(RobotState((config,)))
    assert walk_subpackages(data) == [(6, 445 + 2 * count)]
    assert feed_all_ways(daemon, data) == [RobotState((config,))]


def test_configuration_data_reads_at_most_two_reserved_and_ignores_an_odd_byte() -> None:
    body = encode(RobotState((ConfigurationData(),)))[10:] + struct.pack(">hhh", 1, 2, 3) + b"\x09"
    [state] = daemon().receive_data(frame(16, sub(6, body)))
    assert isinstance(state, RobotState)
    assert state.subpackages == (ConfigurationData(reserved=(1, 2)),)


def test_robot_mode_data_without_the_reserved_byte_decodes() -> None:
    # urcl's fake server sends ROBOT_MODE_DATA without the trailing byte (46-byte sub-package)
    body = struct.pack(">Q7?bB3d", 5, True, True, True, False, True, False, False, 5, 0, 1.0, 0.5, 1.0)
    [state] = daemon().receive_data(frame(16, sub(0, body)))
    assert isinstance(state, RobotState)
    expected = RobotModeData(5, True, True, True, False, True, False, False, 5, 0, 1.0, 0.5, 1.0, None)
    assert state.subpackages == (expected,)


def test_robot_mode_data_is_46_bytes_in_the_cb3_layout_and_47_with_the_reserved_byte() -> None:
    """A CB3 controller sends ROBOT_MODE_DATA without the e-Series' reserved byte (the fake used to
    send 47 bytes for every version)."""
    for reserved, length in ((None, 46), (0, 47), (9, 47)):
        data = encode(RobotState((RobotModeData(robot_mode=7, reserved=reserved),)))
        assert struct.unpack_from(">I", data, 5)[0] == length
        [state] = daemon().receive_data(data)
        assert isinstance(state, RobotState)
        assert state.subpackages == (RobotModeData(robot_mode=7, reserved=reserved),)


def test_joint_data_is_transposed_from_per_joint_records() -> None:
    body = b"".join(struct.pack(">3d4fB", j, 10 + j, 20 + j, 1, 2, 3, 4, 253) for j in range(6))
    [state] = daemon().receive_data(frame(16, sub(1, body)))
    assert isinstance(state, RobotState)
    joints = state.get(JointData)
    assert joints is not None
    assert joints.q_actual == (0.0, 1.0, 2.0, 3.0, 4.0, 5.0)
    assert joints.q_target == (10.0, 11.0, 12.0, 13.0, 14.0, 15.0)
    assert joints.t_motor == (3.0,) * 6
    assert joints.joint_mode == (253,) * 6


def test_kinematics_info_layout_written_by_hand() -> None:
    body = struct.pack(">6I24dI", *range(6), *[0.0] * 6, *[0.5] * 6, *[0.25] * 6, *[-1.0] * 6, 9)
    [state] = daemon().receive_data(frame(16, sub(5, body)))
    assert isinstance(state, RobotState)
    assert state.subpackages == (
        KinematicsInfo(tuple(range(6)), (0.0,) * 6, (0.5,) * 6, (0.25,) * 6, (-1.0,) * 6, 9),
    )


MODELLED = [
    t for t in SubPackageType if t not in (SubPackageType.CALIBRATION_DATA, SubPackageType.SAFETY_DATA)
]


def _captured_bodies() -> dict[int, bytes]:
    bodies, pos = {}, 5
    while pos < len(CAPTURED_STATE):
        length, kind = struct.unpack_from(">IB", CAPTURED_STATE, pos)
        bodies[kind] = CAPTURED_STATE[pos + 5 : pos + length]
        pos += length
    return bodies


@pytest.mark.parametrize("kind", MODELLED, ids=lambda t: t.name)
def test_extra_trailing_bytes_in_a_known_sub_package_are_ignored(kind: int) -> None:
    body = _captured_bodies()[kind]
    [plain] = daemon().receive_data(frame(16, sub(kind, body)))
    [longer] = daemon().receive_data(frame(16, sub(kind, body + b"\x01\x02\x03\x04\x05\x06\x07")))
    if kind == SubPackageType.CONFIGURATION_DATA:
        assert isinstance(longer, RobotState)
        assert isinstance(plain, RobotState)
        assert longer.subpackages[0] == ConfigurationData(
            **{**_fields(plain.subpackages[0]), "reserved": (258, 772)}
        )
    else:
        assert longer == plain


def _fields(obj: Any) -> dict[str, Any]:
    return {name: getattr(obj, name) for name in obj.__dataclass_fields__}


@pytest.mark.parametrize("kind", MODELLED, ids=lambda t: t.name)
def test_a_known_sub_package_one_byte_short_is_a_remote_error(kind: int) -> None:
    body = _captured_bodies()[kind]
    if kind == SubPackageType.ROBOT_MODE_DATA:
        body = body[:-1]  # the reserved byte is optional
    with pytest.raises(RemoteProtocolError) as info:
        daemon().receive_data(frame(16, sub(kind, body[:-1])))
    assert info.value.protocol == "primary"
    assert info.value.offset == 5


@pytest.mark.parametrize("kind", [9, 10, 13, 200])
def test_unknown_sub_packages_are_reported_with_their_body(kind: int) -> None:
    data = frame(16, sub(kind, b"xyz") + sub(8, bytes([1, 1, 0, 0])))
    assert feed_all_ways(daemon, data) == [
        RobotState((UnknownSubPackage(kind, b"xyz"), AdditionalInfo(1, True, False, 0)))
    ]


def test_empty_robot_state_is_an_empty_tuple() -> None:
    assert daemon().receive_data(frame(16, b"")) == [RobotState(())]


def test_robot_state_get_returns_the_first_of_a_kind_or_none() -> None:
    state = RobotState((ToolModeInfo(1), ToolModeInfo(2)))
    assert state.get(ToolModeInfo) == ToolModeInfo(1)
    assert state.get(RobotModeData) is None


# --- bad input from the robot ----------------------------------------------------------------------


@pytest.mark.parametrize("length", [-1, 0, 4, MAX_PACKAGE_BYTES + 1, 2**31 - 1])
def test_package_length_outside_the_limits_fails_on_the_header(length: int) -> None:
    conn = daemon()
    conn.receive_data(CAPTURED_KEY)
    with pytest.raises(RemoteProtocolError) as info:
        conn.receive_data(struct.pack(">iB", length, 16))  # nothing after the header is needed
    assert info.value.protocol == "primary"
    assert info.value.offset == len(CAPTURED_KEY)


def test_a_package_of_exactly_the_maximum_is_accepted() -> None:
    data = frame(22, bytes(MAX_PACKAGE_BYTES - 5))
    assert daemon().receive_data(data) == [OtherPackage(22, bytes(MAX_PACKAGE_BYTES - 5))]


def test_many_packages_in_one_chunk_larger_than_the_cap_are_fine() -> None:
    count = MAX_PACKAGE_BYTES // len(CAPTURED_STATE) + 10
    events = daemon().receive_data(CAPTURED_STATE * count)
    assert len(events) == count


@pytest.mark.parametrize(
    "body",
    [
        sub(0, bytes(42))[:4],  # ends inside a sub-package header
        struct.pack(">IB", 4, 0),  # sub-package length below its own header
        struct.pack(">IB", 0, 0),
        struct.pack(">IB", 100, 8) + bytes(4),  # runs past the package
        sub(8, bytes(4)) + struct.pack(">IB", 2**32 - 1, 8),
    ],
)
def test_sub_package_framing_errors(body: bytes) -> None:
    with pytest.raises(RemoteProtocolError) as info:
        daemon().receive_data(frame(16, body))
    assert info.value.protocol == "primary"


@pytest.mark.parametrize(
    "payload",
    [
        pytest.param(b"", id="no message header"),
        pytest.param(struct.pack(">Qb", 0, 0), id="header cut"),
    ],
)
def test_robot_message_without_its_header_is_a_remote_error(payload: bytes) -> None:
    with pytest.raises(RemoteProtocolError):
        daemon().receive_data(frame(20, payload))


@pytest.mark.parametrize(
    ("kind", "payload"),
    [
        pytest.param(3, bytes([0x80]) + bytes(20), id="version negative name length"),
        pytest.param(3, bytes([9]) + b"URControl" + bytes(9), id="version numbers cut"),
        pytest.param(3, b"", id="version empty"),
        pytest.param(7, struct.pack(">iiB", 0, 0, 20) + b"short", id="key title runs past"),
        pytest.param(7, struct.pack(">ii", 0, 0), id="key cut"),
        pytest.param(10, struct.pack(">I", 1), id="runtime exception cut"),
        pytest.param(6, struct.pack(">iiiI", 0, 0, 0, 0), id="error code cut"),
        pytest.param(5, struct.pack(">iiBI", 0, 0, 0, 0), id="safety mode without data"),
    ],
)
def test_robot_message_shorter_than_its_layout_is_a_remote_error(kind: int, payload: bytes) -> None:
    with pytest.raises(RemoteProtocolError) as info:
        daemon().receive_data(message(kind, payload))
    assert info.value.protocol == "primary"


def test_after_a_remote_error_every_call_raises() -> None:
    conn = daemon()
    with pytest.raises(RemoteProtocolError):
        conn.receive_data(struct.pack(">iB", 2, 16))
    with pytest.raises(RemoteProtocolError):
        conn.receive_data(CAPTURED_KEY)
    with pytest.raises(RemoteProtocolError):
        conn.receive_data(b"")
    with pytest.raises(LocalProtocolError):
        conn.send(Script("power on"))


def test_eof_between_packages_is_clean_and_inside_one_is_a_remote_error() -> None:
    conn = daemon()
    conn.receive_data(CAPTURED_KEY)
    assert conn.receive_eof() == []
    with pytest.raises(LocalProtocolError):
        conn.receive_data(CAPTURED_KEY)
    cut = daemon()
    cut.receive_data(CAPTURED_KEY + CAPTURED_STATE[:100])
    with pytest.raises(RemoteProtocolError) as info:
        cut.receive_eof()
    assert info.value.offset == len(CAPTURED_KEY)
    with pytest.raises(RemoteProtocolError):
        cut.receive_data(b"")


def test_robot_drops_an_unterminated_line_or_block_at_eof() -> None:
    conn = robot()
    assert conn.receive_data(b"power on\ndef p():\n  sync()\nend") == [CommandReceived("power on")]
    assert conn.receive_eof() == []


def test_undecodable_text_is_replaced_not_fatal() -> None:
    [event] = daemon().receive_data(message(0, b"caf\xe9 \xff"))
    assert isinstance(event, TextMessage)
    assert event.text.startswith("caf")


# --- what each side may send ------------------------------------------------------------------------


def test_daemon_sends_only_scripts_and_robot_never_does() -> None:
    with pytest.raises(LocalProtocolError):
        daemon().send(RobotState(()))
    with pytest.raises(LocalProtocolError):
        daemon().send(TextMessage("x"))
    with pytest.raises(LocalProtocolError):
        robot().send(Script("power on"))


def test_script_gets_exactly_one_trailing_newline() -> None:
    assert script_bytes("power on") == b"power on\n"
    assert script_bytes("power on\n") == b"power on\n"
    assert script_bytes("") == b"\n"
    assert script_bytes(ControllerCommand.BRAKE_RELEASE) == b"set robotmode run\n"


def test_data_to_send_is_cleared_after_reading() -> None:
    conn = daemon()
    conn.send(Script("power off"))
    assert conn.data_to_send() == b"power off\n"
    assert conn.data_to_send() == b""


@pytest.mark.parametrize(
    "bad",
    [
        pytest.param(Script('popup("é")'), id="non-ascii script"),
        pytest.param(Script("x" * MAX_SCRIPT_BYTES), id="script over the cap with its newline"),
    ],
)
def test_daemon_refuses_scripts_the_controller_would_not_take(bad: Script) -> None:
    conn = daemon()
    with pytest.raises(LocalProtocolError):
        conn.send(bad)
    conn.send(Script("power on"))  # a refused send leaves the connection usable
    assert conn.data_to_send() == b"power on\n"


@pytest.mark.parametrize(
    "bad",
    [
        pytest.param(RobotState((JointData(q_actual=(0.0,) * 5),)), id="joint vector of 5"),
        pytest.param(RobotState((RobotModeData(robot_mode=300),)), id="int8 out of range"),
        pytest.param(RobotState((ToolModeInfo(output_mode=-1),)), id="uint8 negative"),
        pytest.param(RobotState((KinematicsInfo(checksum=(0,) * 7),)), id="checksum of 7"),
        pytest.param(RobotState((ConfigurationData(reserved=(1, 2, 3)),)), id="three reserved"),
        pytest.param(RobotState((UnknownSubPackage(0, b""),)), id="unknown with a modelled type"),
        pytest.param(RobotState(("not a sub-package",)), id="not a sub-package"),  # type: ignore[arg-type]
        pytest.param(OtherPackage(16, b""), id="other package typed ROBOT_STATE"),
        pytest.param(OtherPackage(20, b""), id="other package typed ROBOT_MESSAGE"),
        pytest.param(OtherPackage(22, bytes(MAX_PACKAGE_BYTES)), id="package over the cap"),
        pytest.param(OtherRobotMessage(7, b""), id="other message typed KEY"),
        pytest.param(VersionMessage("x" * 128, 5, 24, 0, 0, ""), id="project name over int8"),
        pytest.param(KeyMessage(0, 0, "t" * 256, ""), id="key title over uint8"),
        pytest.param(SafetyModeMessage(0, 0, 3, 2, 2**31), id="int32 report data out of range"),
        pytest.param(TextMessage("t", timestamp=-1), id="negative timestamp"),
    ],
)
def test_robot_refuses_to_encode_what_the_wire_cannot_carry(bad: PrimaryMessage) -> None:
    conn = robot()
    with pytest.raises(LocalProtocolError) as info:
        conn.send(bad)
    assert info.value.protocol == "primary"
    assert conn.data_to_send() == b""
    conn.send(TextMessage("still fine"))
    assert daemon().receive_data(conn.data_to_send()) == [TextMessage("still fine")]


# --- script helpers and the robot-side script reader -----------------------------------------------


def test_def_and_sec_program_helpers() -> None:
    assert def_program("move_it", "movej(q)\nsync()\n") == "def move_it():\n  movej(q)\n  sync()\nend\n"
    assert sec_program("set_io", "set_standard_digital_out(0, True)") == (
        "sec set_io():\n  set_standard_digital_out(0, True)\nend\n"
    )


def test_headless_program_wraps_like_the_reference() -> None:
    script = "def helper():\n  return 1\nend\nhelper()\n"
    assert headless_program(script) == (
        "stop program\ndef externalControl():\n\tdef helper():\n\t  return 1\n\tend\n\thelper()\nend\n"
    )


@pytest.mark.parametrize(
    "name", ["", "1abc", "has space", "dash-name", "a" * (MAX_SCRIPT_NAME_LENGTH + 1), "é"]
)
def test_program_names_outside_the_rules_are_refused(name: str) -> None:
    with pytest.raises(LocalProtocolError):
        def_program(name, "sync()")
    with pytest.raises(LocalProtocolError):
        sec_program(name, "sync()")


def test_robot_reads_commands_and_programs_split_anywhere() -> None:
    program = headless_program('textmsg("hi")\nwhile True:\n  sync()\nend\n')
    data = script_bytes(
        ControllerCommand.POWER_ON,
        ControllerCommand.BRAKE_RELEASE,
        program,
        sec_program("io", "set_standard_digital_out(1, False)"),
        ControllerCommand.UNLOCK_PROTECTIVE_STOP,
    )
    assert feed_all_ways(robot, data) == [
        CommandReceived("power on"),
        CommandReceived("set robotmode run"),
        CommandReceived("stop program"),
        ProgramReceived("def", "externalControl", program.removeprefix("stop program\n")),
        ProgramReceived("sec", "io", "sec io():\n  set_standard_digital_out(1, False)\nend\n"),
        CommandReceived("set unlock protective stop"),
    ]


def test_headless_script_with_top_level_functions_and_threads_arrives_as_one_program() -> None:
    script = (
        "global speed = 1.0\n"
        "def helper(x):\n  return x\nend\n"
        "thread watchdog():\n  while True:\n    sync()\n  end\nend\n"
        "sec not_top_level():\n  sync()\nend\n"
        "helper(1)\n"
    )
    program = headless_program(script)
    assert robot().receive_data(script_bytes(program)) == [
        CommandReceived("stop program"),
        ProgramReceived("def", "externalControl", program.removeprefix("stop program\n")),
    ]


def test_only_an_end_at_column_zero_closes_a_block() -> None:
    text = "def p():  # main\n  if True:\n    sync()\n  end\nend  # closes\n"
    assert robot().receive_data(text.encode()) == [ProgramReceived("def", "p", text)]


def test_blank_and_comment_lines_outside_a_block_are_skipped_and_crlf_is_accepted() -> None:
    data = b"\n   \n# a comment\r\n  power off  \r\nsec s():\r\n  sync()\r\nend\r\n"
    assert robot().receive_data(data) == [
        CommandReceived("power off"),
        ProgramReceived("sec", "s", "sec s():\n  sync()\nend\n"),
    ]


def test_an_unterminated_line_or_block_waits_for_more() -> None:
    conn = robot()
    assert conn.receive_data(b"def p():\n  sync()\n") == []
    assert conn.receive_data(b"en") == []
    assert conn.receive_data(b"d\n") == [ProgramReceived("def", "p", "def p():\n  sync()\nend\n")]


def test_robot_passes_non_ascii_script_text_on_for_the_compiler_to_refuse() -> None:
    """A controller answers a non-ASCII character with a compile error naming its line and column;
    the robot side used to fail the connection instead (the client never learnt why)."""
    conn = robot()
    conn.receive_data(b"power on\n")
    assert conn.receive_data('textmsg("é")\n'.encode()) == [CommandReceived('textmsg("é")')]
    assert conn.receive_data(b"def p():\n  x = 1\xff\nend\n") == [
        ProgramReceived("def", "p", "def p():\n  x = 1\udcff\nend\n")
    ]


def test_robot_caps_a_line_without_newline() -> None:
    chunk = b"x" * 65536
    with pytest.raises(RemoteProtocolError):
        feed_repeatedly(robot(), chunk, MAX_SCRIPT_BYTES // len(chunk) + 2)


def test_robot_caps_the_size_of_a_program() -> None:
    conn = robot()
    conn.receive_data(b"def big():\n")
    line = b"  " + b"x" * 1000 + b"\n"
    with pytest.raises(RemoteProtocolError):
        feed_repeatedly(conn, line, MAX_SCRIPT_BYTES // len(line) + 2)


def test_robot_accepts_a_program_just_under_the_cap() -> None:
    body = "\n".join(["x" * 1000] * ((MAX_SCRIPT_BYTES - 100) // 1003))
    text = def_program("big", body)
    assert len(text) < MAX_SCRIPT_BYTES
    assert robot().receive_data(script_bytes(text)) == [ProgramReceived("def", "big", text)]


# --- hypothesis round trips ------------------------------------------------------------------------

u8 = st.integers(0, 2**8 - 1)
i8 = st.integers(-(2**7), 2**7 - 1)
i16 = st.integers(-(2**15), 2**15 - 1)
i32 = st.integers(-(2**31), 2**31 - 1)
u32 = st.integers(0, 2**32 - 1)
u64 = st.integers(0, 2**64 - 1)
f64 = st.floats(allow_nan=False)
f32 = st.floats(width=32, allow_nan=False)
flag = st.booleans()
text = st.text(max_size=40)


def vec(element: st.SearchStrategy[Any]) -> st.SearchStrategy[tuple[Any, ...]]:
    return st.tuples(*[element] * 6)


subpackages: st.SearchStrategy[SubPackage] = st.one_of(
    st.builds(RobotModeData, u64, flag, flag, flag, flag, flag, flag, flag, i8, u8, f64, f64, f64),
    st.builds(JointData, vec(f64), vec(f64), vec(f64), vec(f32), vec(f32), vec(f32), vec(f32), vec(u8)),
    st.builds(ToolData, u8, u8, f64, f64, f32, u8, f32, f32, u8),
    st.builds(
        MasterboardData,
        *(u32, u32, u8, u8, f64, f64, i8, i8, f64, f64, f32, f32, f32, f32, u8, flag),
        st.none() | st.builds(Euromap67, u32, u32, f32, f32),
        *(u32, u8, flag, u8),
    ),
    st.builds(CartesianInfo, vec(f64), vec(f64)),
    st.builds(KinematicsInfo, vec(u32), vec(f64), vec(f64), vec(f64), vec(f64), u32),
    st.builds(
        ConfigurationData,
        *[vec(f64)] * 4,
        *[f64] * 5,
        *[vec(f64)] * 4,
        *[i32] * 4,
        st.lists(i16, max_size=2).map(tuple),
    ),
    st.builds(ForceModeData, vec(f64), f64),
    st.builds(AdditionalInfo, u8, flag, flag, u8),
    st.builds(ToolCommInfo, flag, i32, i32, i32, f32, f32),
    st.builds(ToolModeInfo, u8, u8, u8),
    st.builds(UnknownSubPackage, st.sampled_from([9, 10, 13, 99, 255]), st.binary(max_size=60)),
)

_report_data = st.one_of(
    st.tuples(st.just(2), i32),
    st.tuples(st.just(3), f32),
    st.tuples(st.sampled_from([0, 1, 4, 2**32 - 1]), u32),
)
header = {"timestamp": u64, "source": i8}
robot_messages: st.SearchStrategy[PrimaryMessage] = st.one_of(
    st.builds(TextMessage, text, **header),
    st.builds(VersionMessage, st.text(max_size=30), u8, u8, i32, i32, text, **header),
    _report_data.flatmap(
        lambda d: st.builds(SafetyModeMessage, i32, i32, u8, st.just(d[0]), st.just(d[1]), **header)
    ),
    st.builds(ErrorCodeMessage, i32, i32, i32, u32, u32, text, **header),
    st.builds(KeyMessage, i32, i32, st.text(max_size=60), text, **header),
    st.builds(RuntimeExceptionMessage, u32, u32, text, **header),
    st.builds(OtherRobotMessage, st.sampled_from([1, 2, 4, 9, 11, 255]), st.binary(max_size=60), **header),
)
packages: st.SearchStrategy[PrimaryMessage] = st.one_of(
    st.builds(RobotState, st.lists(subpackages, max_size=14).map(tuple)),
    robot_messages,
    st.builds(OtherPackage, st.sampled_from([0, 5, 22, 23, 24, 25, 255]), st.binary(max_size=100)),
)


def feed_in_pieces(conn: PrimaryConnection, data: bytes, cuts: list[int]) -> list[PrimaryEvent]:
    events: list[PrimaryEvent] = []
    previous = 0
    for cut in [*sorted({min(c, len(data)) for c in cuts}), len(data)]:
        events += conn.receive_data(data[previous:cut])
        previous = cut
    return events


@given(st.lists(packages, min_size=1, max_size=4), st.lists(st.integers(0, 6000), max_size=8))
@settings(max_examples=300, suppress_health_check=[HealthCheck.too_slow])
def test_every_package_round_trips_robot_to_daemon(sent: list[PrimaryMessage], cuts: list[int]) -> None:
    data = encode(*sent)
    assert feed_in_pieces(daemon(), data, cuts) == sent


ascii_line = st.text(alphabet=st.characters(min_codepoint=32, max_codepoint=126), max_size=60)
names = st.from_regex(r"[A-Za-z_][A-Za-z0-9_]{0,30}", fullmatch=True)


@given(
    st.sampled_from(["def", "sec"]), names, st.lists(ascii_line, max_size=10), st.lists(st.integers(0, 800))
)
def test_every_program_round_trips_daemon_to_robot(
    kind: str, name: str, lines: list[str], cuts: list[int]
) -> None:
    build = def_program if kind == "def" else sec_program
    program = build(name, "\n".join(lines))
    events = feed_in_pieces(robot(), script_bytes(program), cuts)
    assert events == [ProgramReceived(kind, name, program)]  # type: ignore[arg-type]


commands = st.text(alphabet="abcdefghijklmnopqrstuvwxyz _0123456789", min_size=1, max_size=40).filter(
    lambda s: s.strip() != ""
)


@given(st.lists(commands, min_size=1, max_size=6), st.lists(st.integers(0, 300)))
def test_every_command_round_trips_daemon_to_robot(lines: list[str], cuts: list[int]) -> None:
    events = feed_in_pieces(robot(), script_bytes(*lines), cuts)
    assert events == [CommandReceived(line.strip()) for line in lines]


# --- fuzz: any bytes give events or RemoteProtocolError --------------------------------------------


def _events_or_remote_error(conn: PrimaryConnection, data: bytes, cuts: list[int]) -> None:
    try:
        feed_in_pieces(conn, data, cuts)
    except RemoteProtocolError as err:
        error = err
    else:
        return
    assert error.protocol == "primary"
    with pytest.raises(RemoteProtocolError):
        conn.receive_data(b"\x00")


@given(st.binary(max_size=3000), st.lists(st.integers(0, 3000), max_size=10))
@settings(max_examples=400)
def test_fuzz_daemon_side_random_bytes(data: bytes, cuts: list[int]) -> None:
    _events_or_remote_error(daemon(), data, cuts)


framed_garbage = st.one_of(
    st.builds(
        lambda subs: frame(16, b"".join(subs)),
        st.lists(st.builds(sub, st.integers(0, 14), st.binary(max_size=500)), max_size=6),
    ),
    st.builds(lambda k, p: message(k, p), st.integers(0, 12), st.binary(max_size=80)),
    st.builds(frame, st.integers(0, 255), st.binary(max_size=50)),
    st.binary(min_size=1, max_size=40),
)


@given(st.lists(framed_garbage, min_size=1, max_size=5), st.lists(st.integers(0, 2000), max_size=10))
@settings(max_examples=400)
def test_fuzz_daemon_side_well_framed_garbage(parts: list[bytes], cuts: list[int]) -> None:
    _events_or_remote_error(daemon(), b"".join(parts), cuts)


@given(st.binary(max_size=3000), st.lists(st.integers(0, 3000), max_size=10))
@settings(max_examples=300)
def test_fuzz_robot_side_random_bytes(data: bytes, cuts: list[int]) -> None:
    _events_or_remote_error(robot(), data, cuts)


script_garbage = st.lists(
    st.sampled_from(["def p():", "sec q():", "end", "  end", "power on", "", "#x", "\r", "def", "end #"])
    | ascii_line,
    max_size=20,
).map(lambda lines: "\n".join(lines).encode())


@given(script_garbage, st.lists(st.integers(0, 500), max_size=10))
@settings(max_examples=300)
def test_fuzz_robot_side_script_like_lines(data: bytes, cuts: list[int]) -> None:
    _events_or_remote_error(robot(), data, cuts)


# --- a full conversation through both sides ---------------------------------------------------------


class Pair:
    """A daemon-side and a robot-side connection joined in memory; bytes move in odd-sized pieces."""

    def __init__(self) -> None:
        self.daemon = daemon()
        self.robot = robot()

    def to_robot(self, *texts: str) -> list[PrimaryEvent]:
        for text in texts:
            self.daemon.send(Script(text))
        return self._move(self.daemon.data_to_send(), self.robot)

    def to_daemon(self, *messages: PrimaryMessage) -> list[PrimaryEvent]:
        for m in messages:
            self.robot.send(m)
        return self._move(self.robot.data_to_send(), self.daemon)

    @staticmethod
    def _move(data: bytes, conn: PrimaryConnection) -> list[PrimaryEvent]:
        events: list[PrimaryEvent] = []
        for start in range(0, len(data), 7):
            events += conn.receive_data(data[start : start + 7])
        return events


def _mode(mode: int, *, power: bool, running: bool = False) -> RobotState:
    return RobotState(
        (RobotModeData(is_robot_power_on=power, robot_mode=mode, is_program_running=running), ToolModeInfo())
    )


def test_conversation_power_on_brake_release_program_start_and_failure() -> None:
    pair = Pair()
    version = VersionMessage("URControl", 5, 24, 0, 0, "04-10-2025, 00:25:33")
    assert pair.to_daemon(version, captured_style_state()) == [version, captured_style_state()]

    assert pair.to_robot(ControllerCommand.POWER_ON) == [CommandReceived("power on")]
    [state] = pair.to_daemon(_mode(5, power=True))
    assert isinstance(state, RobotState)
    mode = state.get(RobotModeData)
    assert mode is not None
    assert mode.robot_mode == 5

    assert pair.to_robot(ControllerCommand.BRAKE_RELEASE) == [CommandReceived("set robotmode run")]
    program = headless_program("while True:\n  sync()\nend\n")
    received = pair.to_robot(program)
    assert received[0] == CommandReceived("stop program")
    assert received[1] == ProgramReceived("def", "externalControl", program.removeprefix("stop program\n"))

    started = KeyMessage(0, 0, "PROGRAM_XXX_STARTED", "externalControl")
    events = pair.to_daemon(started, _mode(7, power=True, running=True))
    assert events[0] == started
    assert isinstance(events[1], RobotState)

    assert pair.to_robot(sec_program("io", "set_standard_digital_out(0, True)"))[0].kind == "sec"  # type: ignore[union-attr]

    failure = RuntimeExceptionMessage(2, 3, "compile_error_name_not_found:txtmsg:")
    fault = ErrorCodeMessage(210, 0, ReportLevel.FAULT, 0, 0, "C210 read-only")
    stopped = KeyMessage(0, 0, "PROGRAM_XXX_STOPPED", "externalControl")
    assert pair.to_daemon(failure, fault, stopped, OtherPackage(25, b"\x00\x01")) == [
        failure,
        fault,
        stopped,
        OtherPackage(25, b"\x00\x01"),
    ]
    assert pair.to_robot(ControllerCommand.STOP_PROGRAM, ControllerCommand.POWER_OFF) == [
        CommandReceived("stop program"),
        CommandReceived("power off"),
    ]
    assert pair.daemon.data_to_send() == pair.robot.data_to_send() == b""


def test_float32_fields_survive_only_to_float32_precision() -> None:
    # documents the wire: a double stored in a float field comes back rounded
    [state] = daemon().receive_data(encode(RobotState((ToolCommInfo(rx_idle_chars=0.1),))))
    assert isinstance(state, RobotState)
    tool = state.get(ToolCommInfo)
    assert tool is not None
    assert tool.rx_idle_chars != 0.1
    assert math.isclose(tool.rx_idle_chars, 0.1, rel_tol=1e-7)
