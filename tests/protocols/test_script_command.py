"""Script command codec (docs/protocols.md §4.5): frame layouts, validation, both sides, fuzz and a pair."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.protocols.feeding import feed_all_ways
from urdaemon.errors import LocalProtocolError, RemoteProtocolError
from urdaemon.protocols import Side
from urdaemon.protocols._fixed import INT32_MAX, INT32_MIN, MULT
from urdaemon.protocols.script_command import (
    FRAME_BYTES,
    EndForceMode,
    EndToolContact,
    FtRtdeInputEnable,
    ScriptCommand,
    ScriptCommandConnection,
    ScriptCommandId,
    SetFrictionCompensation,
    SetFrictionScales,
    SetGravity,
    SetPayload,
    SetTargetPayload,
    SetTcpOffset,
    SetToolVoltage,
    StartForceMode,
    StartToolContact,
    ToolContactResult,
    ToolContactResultCode,
    ToolContactResultMessage,
    UnknownScriptCommand,
    ZeroFtSensor,
    decode_script_command,
    encode_script_command,
)

FRAME_6 = (0.1, 0.2, 0.3, 0.0, 0.0, 1.57)


def _ints(values: tuple[float, ...]) -> list[int]:
    return [round(v * 1_000_000) for v in values]


def _frame(*ints: int) -> bytes:
    """An independent encoder for expected bytes: the given int32s, zero-filled to 28."""
    assert len(ints) <= 28
    padded = [*ints, *[0] * (28 - len(ints))]
    return b"".join(i.to_bytes(4, "big", signed=True) for i in padded)


def _robot() -> ScriptCommandConnection:
    return ScriptCommandConnection(Side.ROBOT)


def _daemon() -> ScriptCommandConnection:
    return ScriptCommandConnection(Side.DAEMON)


def _sent(command: ScriptCommand) -> bytes:
    conn = _daemon()
    conn.send(command)
    return conn.data_to_send()


# -- frame layouts (§4.5 table, built independently) ----------------------------------------------------

FORCE = StartForceMode(
    task_frame=FRAME_6,
    selection=(0, 0, 1, 0, 0, 0),
    wrench=(0.0, 0.0, -10.0, 0.0, 0.0, 0.0),
    force_type=2,
    limits=(0.1, 0.1, 0.1, 0.35, 0.35, 0.35),
    damping=0.025,
    gain_scaling=0.5,
)

LAYOUTS: list[tuple[ScriptCommand, bytes]] = [
    (ZeroFtSensor(), _frame(0)),
    (SetPayload(1.5, (0.0, 0.01, 0.05)), _frame(1, 1_500_000, 0, 10_000, 50_000)),
    (SetToolVoltage(24), _frame(2, 24_000_000)),
    (SetToolVoltage(0), _frame(2, 0)),
    (
        FORCE,
        _frame(
            3,
            *_ints(FRAME_6),
            0,
            0,
            MULT,
            0,
            0,
            0,
            0,
            0,
            -10_000_000,
            0,
            0,
            0,
            2_000_000,
            100_000,
            100_000,
            100_000,
            350_000,
            350_000,
            350_000,
            25_000,
            500_000,
        ),
    ),
    (EndForceMode(), _frame(4)),
    (StartToolContact(), _frame(5)),
    (EndToolContact(), _frame(6)),
    (SetFrictionCompensation(True), _frame(7, 1)),
    (SetFrictionCompensation(False), _frame(7, 0)),
    (
        FtRtdeInputEnable(True, 0.25, (0.0, 0.0, 0.03), (0.0, 0.0, 0.015)),
        _frame(8, 1, 250_000, 0, 0, 30_000, 0, 0, 15_000),
    ),
    (SetGravity((0.0, 0.0, 9.82)), _frame(9, 0, 0, 9_820_000)),
    (SetTcpOffset(FRAME_6), _frame(10, *_ints(FRAME_6))),
    (
        SetFrictionScales((0.9, 0.9, 0.8, 0.9, 0.9, 0.9), (0.8, 0.8, 0.7, 0.8, 0.8, 0.8)),
        _frame(11, *_ints((0.9, 0.9, 0.8, 0.9, 0.9, 0.9)), *_ints((0.8, 0.8, 0.7, 0.8, 0.8, 0.8))),
    ),
    (
        SetTargetPayload(2.0, (0.0, 0.0, 0.1), (0.01, 0.02, 0.03, 0.0, 0.0, -0.001), 0.5),
        _frame(12, 2_000_000, 0, 0, 100_000, 10_000, 20_000, 30_000, 0, 0, -1000, 500_000),
    ),
]


@pytest.mark.parametrize(("command", "wire"), LAYOUTS)
def test_commands_have_the_documented_layout(command: ScriptCommand, wire: bytes) -> None:
    assert len(wire) == FRAME_BYTES
    assert _sent(command) == wire
    assert encode_script_command(command) == wire


@pytest.mark.parametrize(("command", "wire"), LAYOUTS)
def test_commands_decode_every_way_on_the_robot_side(command: ScriptCommand, wire: bytes) -> None:
    assert feed_all_ways(_robot, wire) == [command]


def test_all_thirteen_commands_are_covered() -> None:
    assert [c.value for c in ScriptCommandId] == list(range(13))
    assert {encode_script_command(c)[3] for c, _ in LAYOUTS} == set(range(13))


def test_force_mode_defaults_are_urcls() -> None:
    command = StartForceMode(FRAME_6, (1,) * 6, (0.0,) * 6, 1, (0.1,) * 6)
    assert (command.damping, command.gain_scaling) == (0.025, 0.5)


# -- what the daemon side refuses to send --------------------------------------------------------------


@pytest.mark.parametrize(
    "command",
    [
        SetToolVoltage(5),
        SetToolVoltage(12.0),  # type: ignore[arg-type]
        SetToolVoltage(-12),
        StartForceMode(FRAME_6, (0, 0, 2, 0, 0, 0), (0.0,) * 6, 2, (0.1,) * 6),
        StartForceMode(FRAME_6, (0, 0, 0.5, 0, 0, 0), (0.0,) * 6, 2, (0.1,) * 6),  # type: ignore[arg-type]
        StartForceMode(FRAME_6, (0,) * 6, (0.0,) * 6, 4, (0.1,) * 6),
        StartForceMode(FRAME_6, (0,) * 6, (0.0,) * 6, 0, (0.1,) * 6),
        StartForceMode(FRAME_6, (0,) * 6, (0.0,) * 6, 1, (0.1,) * 6, damping=1.01),
        StartForceMode(FRAME_6, (0,) * 6, (0.0,) * 6, 1, (0.1,) * 6, damping=-0.1),
        StartForceMode(FRAME_6, (0,) * 6, (0.0,) * 6, 1, (0.1,) * 6, gain_scaling=2.5),
        StartForceMode(FRAME_6, (0,) * 6, (0.0,) * 6, 1, (0.1,) * 6, gain_scaling=math.nan),
        StartForceMode(FRAME_6, (0,) * 5, (0.0,) * 6, 1, (0.1,) * 6),
        StartForceMode(FRAME_6, (0,) * 6, (0.0,) * 6, 1, (0.1,) * 7),
        StartForceMode(FRAME_6, 7, (0.0,) * 6, 1, (0.1,) * 6),  # type: ignore[arg-type]
        SetFrictionScales((1.1,) + (0.5,) * 5, (0.5,) * 6),
        SetFrictionScales((0.5,) * 6, (-0.01,) + (0.5,) * 5),
        SetFrictionScales((0.5,) * 6, (0.5,) * 5),
        SetPayload(-1.0, (0.0, 0.0, 0.0)),
        SetPayload(math.inf, (0.0, 0.0, 0.0)),
        SetPayload(1.0, (0.0, 0.0)),
        SetPayload(1.0, (0.0, math.nan, 0.0)),
        SetTargetPayload(1.0, (0.0,) * 3, (0.0,) * 6, -0.5),
        SetTargetPayload(-1.0, (0.0,) * 3, (0.0,) * 6),
        SetTargetPayload(1.0, (0.0,) * 3, (0.0,) * 5),
        FtRtdeInputEnable(True, -0.1, (0.0,) * 3, (0.0,) * 3),
        SetGravity((0.0, 0.0, 3000.0)),
        SetTcpOffset((0.0,) * 3),
    ],
)
def test_invalid_commands_are_local_protocol_errors(command: ScriptCommand) -> None:
    conn = _daemon()
    with pytest.raises(LocalProtocolError) as info:
        conn.send(command)
    assert info.value.protocol == "script_command"
    assert conn.data_to_send() == b""


def test_each_side_sends_only_its_own_messages() -> None:
    with pytest.raises(LocalProtocolError):
        _daemon().send(ToolContactResultMessage(ToolContactResultCode.SUCCESS))
    with pytest.raises(LocalProtocolError):
        _robot().send(ZeroFtSensor())
    with pytest.raises(LocalProtocolError):
        _robot().send(ToolContactResultMessage(2))  # type: ignore[arg-type]
    with pytest.raises(LocalProtocolError):
        encode_script_command(UnknownScriptCommand(20, ()))  # type: ignore[arg-type]


# -- robot side decoding --------------------------------------------------------------------------------


@pytest.mark.parametrize("command_id", [13, 99, -1, INT32_MIN, INT32_MAX])
def test_unknown_ids_are_reported_with_their_raw_arguments(command_id: int) -> None:
    wire = _frame(command_id, 1, 2, 3)
    expected = UnknownScriptCommand(command_id, (1, 2, 3, *[0] * 24))
    assert feed_all_ways(_robot, wire) == [expected]


def test_values_are_reported_as_read_without_range_checks() -> None:
    assert decode_script_command(_frame(2, 5 * MULT)) == SetToolVoltage(5)
    assert decode_script_command(_frame(3, *[0] * 6, *[MULT * 3] * 6, *[0] * 6, 9 * MULT)) == StartForceMode(
        (0.0,) * 6, (3,) * 6, (0.0,) * 6, 9, (0.0,) * 6, 0.0, 0.0
    )
    assert decode_script_command(_frame(11, *[2 * MULT] * 12)) == SetFrictionScales((2.0,) * 6, (2.0,) * 6)


def test_raw_flags_are_true_when_non_zero_like_the_script() -> None:
    assert decode_script_command(_frame(7, 7)) == SetFrictionCompensation(True)
    assert decode_script_command(_frame(8, -1)) == FtRtdeInputEnable(True, 0.0, (0.0,) * 3, (0.0,) * 3)


def test_unused_slots_are_not_read() -> None:
    assert decode_script_command(_frame(4, 1, 2, 3, 4)) == EndForceMode()
    assert decode_script_command(_frame(2, 12 * MULT, 77)) == SetToolVoltage(12)


@pytest.mark.parametrize(
    "wire",
    [
        _frame(2, 12_500_000),  # 12.5 V
        _frame(3, *[0] * 6, 0, 0, 1, 0, 0, 0),  # selection 1e-6
        _frame(3, *[0] * 18, 1_500_000),  # force type 1.5
    ],
)
def test_a_fraction_where_a_whole_number_belongs_is_a_remote_protocol_error(wire: bytes) -> None:
    conn = _robot()
    with pytest.raises(RemoteProtocolError) as info:
        conn.receive_data(_frame(0) + wire)
    assert info.value.protocol == "script_command"
    assert info.value.offset == FRAME_BYTES
    with pytest.raises(RemoteProtocolError):
        conn.receive_data(_frame(0))


# -- daemon side: tool-contact results ------------------------------------------------------------------


@pytest.mark.parametrize("code", list(ToolContactResultCode))
def test_each_result_decodes_every_way(code: ToolContactResultCode) -> None:
    assert feed_all_ways(_daemon, code.to_bytes(4, "big")) == [ToolContactResult(code)]


def test_results_are_zero_contact_one_canceled() -> None:
    assert ToolContactResultCode.SUCCESS.value == 0
    assert ToolContactResultCode.CANCELED.value == 1


@pytest.mark.parametrize("value", [-1, 2, 256, INT32_MIN])
def test_an_unknown_result_is_a_remote_protocol_error(value: int) -> None:
    conn = _daemon()
    with pytest.raises(RemoteProtocolError) as info:
        conn.receive_data(value.to_bytes(4, "big", signed=True))
    assert info.value.offset == 0
    with pytest.raises(LocalProtocolError):
        conn.send(ZeroFtSensor())


def test_eof_in_the_middle_of_a_command_is_an_error() -> None:
    conn = _robot()
    conn.receive_data(_frame(5)[:100])
    with pytest.raises(RemoteProtocolError):
        conn.receive_eof()


# -- hypothesis: round trips and fuzz -------------------------------------------------------------------

scaled = st.integers(INT32_MIN, INT32_MAX).map(lambda i: i / MULT)
unit = st.integers(0, MULT).map(lambda i: i / MULT)
mass = st.integers(0, INT32_MAX).map(lambda i: i / MULT)


def vec(element: st.SearchStrategy[float], n: int) -> st.SearchStrategy[tuple[float, ...]]:
    return st.lists(element, min_size=n, max_size=n).map(tuple)


commands: st.SearchStrategy[ScriptCommand] = st.one_of(
    st.just(ZeroFtSensor()),
    st.builds(SetPayload, mass, vec(scaled, 3)),
    st.builds(SetToolVoltage, st.sampled_from([0, 12, 24])),
    st.builds(
        StartForceMode,
        vec(scaled, 6),
        st.lists(st.sampled_from([0, 1]), min_size=6, max_size=6).map(tuple),
        vec(scaled, 6),
        st.sampled_from([1, 2, 3]),
        vec(scaled, 6),
        unit,
        st.integers(0, 2 * MULT).map(lambda i: i / MULT),
    ),
    st.just(EndForceMode()),
    st.just(StartToolContact()),
    st.just(EndToolContact()),
    st.builds(SetFrictionCompensation, st.booleans()),
    st.builds(FtRtdeInputEnable, st.booleans(), mass, vec(scaled, 3), vec(scaled, 3)),
    st.builds(SetGravity, vec(scaled, 3)),
    st.builds(SetTcpOffset, vec(scaled, 6)),
    st.builds(SetFrictionScales, vec(unit, 6), vec(unit, 6)),
    st.builds(SetTargetPayload, mass, vec(scaled, 3), vec(scaled, 6), mass),
)


@given(st.lists(commands, min_size=1, max_size=5), st.data())
@settings(max_examples=300, deadline=None)
def test_every_command_round_trips_daemon_to_robot(
    messages: list[ScriptCommand], data: st.DataObject
) -> None:
    daemon, robot = _daemon(), _robot()
    for message in messages:
        daemon.send(message)
    wire = daemon.data_to_send()
    assert len(wire) == FRAME_BYTES * len(messages)
    cuts = sorted(data.draw(st.lists(st.integers(0, len(wire)), max_size=5)))
    events = []
    for start, end in zip([0, *cuts], [*cuts, len(wire)], strict=True):
        events += robot.receive_data(wire[start:end])
    assert events == messages


@given(st.lists(st.sampled_from(ToolContactResultCode), max_size=6))
@settings(max_examples=50, deadline=None)
def test_every_result_round_trips_robot_to_daemon(codes: list[ToolContactResultCode]) -> None:
    robot, daemon = _robot(), _daemon()
    for code in codes:
        robot.send(ToolContactResultMessage(code))
    assert daemon.receive_data(robot.data_to_send()) == [ToolContactResult(c) for c in codes]


@given(st.binary(max_size=600), st.lists(st.integers(0, 600), max_size=6))
@settings(max_examples=300, deadline=None)
def test_any_bytes_give_events_or_a_remote_protocol_error(blob: bytes, cuts: list[int]) -> None:
    for side in (Side.ROBOT, Side.DAEMON):
        conn = ScriptCommandConnection(side)
        failure: RemoteProtocolError | None = None
        count = 0
        try:
            for start, end in zip([0, *sorted(cuts)], [*sorted(cuts), len(blob)], strict=True):
                count += len(conn.receive_data(blob[start:end]))
            conn.receive_eof()
        except RemoteProtocolError as err:
            failure = err
        assert failure is None or failure.protocol == "script_command"
        size = FRAME_BYTES if side is Side.ROBOT else 4
        assert count <= len(blob) // size


slot = st.one_of(
    st.integers(INT32_MIN, INT32_MAX), st.sampled_from([0, 1, MULT, 2 * MULT, 12 * MULT, 24 * MULT])
)


@given(st.integers(-1, 14), st.lists(slot, min_size=27, max_size=27))
@settings(max_examples=300, deadline=None)
def test_decode_encode_decode_is_a_fixed_point(command_id: int, arguments: list[int]) -> None:
    frame = _frame(command_id, *arguments)
    try:
        command = decode_script_command(frame)
    except RemoteProtocolError:
        return
    if isinstance(command, UnknownScriptCommand):
        assert command.command_id == int.from_bytes(frame[:4], "big", signed=True)
        return
    try:
        wire = encode_script_command(command)
    except LocalProtocolError:
        return  # read as-is, but outside what the daemon may send
    assert wire[:4] == frame[:4]
    assert decode_script_command(wire) == command


# -- tool contact, both parties in memory ---------------------------------------------------------------


def test_pair_configuration_then_two_tool_contacts() -> None:
    daemon, robot = _daemon(), _robot()
    setup: list[ScriptCommand] = [
        SetPayload(1.2, (0.0, 0.0, 0.05)),
        SetTcpOffset((0.0, 0.0, 0.15, 0.0, 0.0, 0.0)),
        SetToolVoltage(24),
        ZeroFtSensor(),
        StartToolContact(),
    ]
    for command in setup:
        daemon.send(command)
    assert robot.receive_data(daemon.data_to_send()) == setup

    # contact detected: the robot sends 0
    robot.send(ToolContactResultMessage(ToolContactResultCode.SUCCESS))
    assert daemon.receive_data(robot.data_to_send()) == [ToolContactResult(ToolContactResultCode.SUCCESS)]
    daemon.send(EndToolContact())
    assert robot.receive_data(daemon.data_to_send()) == [EndToolContact()]

    # armed again, ended before contact: the robot sends 1
    daemon.send(StartToolContact())
    daemon.send(EndToolContact())
    assert robot.receive_data(daemon.data_to_send()) == [StartToolContact(), EndToolContact()]
    robot.send(ToolContactResultMessage(ToolContactResultCode.CANCELED))
    assert daemon.receive_data(robot.data_to_send()) == [ToolContactResult(ToolContactResultCode.CANCELED)]
    assert daemon.receive_eof() == []
    assert robot.receive_eof() == []
