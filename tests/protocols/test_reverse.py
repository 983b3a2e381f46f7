"""Reverse interface codec (docs/protocols.md §4.2): golden frames, timeouts, both sides, fuzz and a pair."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.protocols.feeding import feed_all_ways
from urdaemon.errors import LocalProtocolError, RemoteProtocolError
from urdaemon.protocols import Side
from urdaemon.protocols._fixed import INT32_MAX, INT32_MIN, MULT, MULT_JOINTSTATE, MULT_TIME
from urdaemon.protocols.reverse import (
    FRAME_BYTES,
    MAX_IGNORED_BYTES,
    ControlMode,
    FreedriveAction,
    FreedriveControl,
    Idle,
    Pose,
    ReverseCommand,
    ReverseConnection,
    ServoJ,
    SpeedJ,
    SpeedL,
    Stopped,
    Torque,
    TrajectoryAction,
    TrajectoryControl,
    UnknownReverseCommand,
    clamp_timeout,
    decode_reverse_command,
    encode_reverse_command,
    encode_servoj,
    step_time_for_frequency,
)

ZEROS = (0.0,) * 6


def _frame(*ints: int) -> bytes:
    """An independent encoder for expected bytes: eight big-endian int32."""
    assert len(ints) == 8
    return b"".join(i.to_bytes(4, "big", signed=True) for i in ints)


def _robot() -> ReverseConnection:
    return ReverseConnection(Side.ROBOT)


def _sent(message: ReverseCommand) -> bytes:
    conn = ReverseConnection(Side.DAEMON)
    conn.send(message)
    return conn.data_to_send()


# -- golden vectors (§4.2 examples) --------------------------------------------------------------------


GOLDEN = [
    # SERVOJ to all-zero joints, 40 ms
    (ServoJ(ZEROS, 0.04), bytes.fromhex("00000028") + bytes(24) + bytes.fromhex("00000001")),
    # IDLE keepalive, 1000 ms
    (Idle(1.0), bytes.fromhex("000003E8") + bytes(24) + bytes.fromhex("00000000")),
    # trajectory START of 10 points, 200 ms
    (
        TrajectoryControl(TrajectoryAction.START, 10, 0.2),
        bytes.fromhex("000000C8 00000001 0000000A") + bytes(16) + bytes.fromhex("00000003"),
    ),
]


@pytest.mark.parametrize(("message", "wire"), GOLDEN)
def test_reference_examples_encode_byte_for_byte(message: ReverseCommand, wire: bytes) -> None:
    assert _sent(message) == wire
    assert encode_reverse_command(message) == wire


@pytest.mark.parametrize(("message", "wire"), GOLDEN)
def test_reference_examples_decode_every_way_on_the_robot_side(message: ReverseCommand, wire: bytes) -> None:
    assert feed_all_ways(_robot, wire) == [message]


def test_the_scaling_constants_are_one_million() -> None:
    assert MULT == MULT_JOINTSTATE == MULT_TIME == 1_000_000


def test_servoj_values_are_scaled_rounded_and_twos_complement() -> None:
    wire = _sent(ServoJ((0.1, -0.2, 1.0000004, -1.0000006, 2147.483647, -2147.483648), 0.002))
    assert wire == _frame(2, 100_000, -200_000, 1_000_000, -1_000_001, INT32_MAX, INT32_MIN, 1)
    assert wire[8:12] == bytes.fromhex("FFFCF2C0")


@pytest.mark.parametrize(
    ("message", "expected"),
    [
        (SpeedJ((1.0, 0, 0, 0, 0, -1.0), 0.04), _frame(40, MULT, 0, 0, 0, 0, -MULT, 2)),
        (SpeedL((0.5, 0, 0, 0, 0, 0), 0.008), _frame(8, MULT // 2, 0, 0, 0, 0, 0, 4)),
        (Pose((0.3, 0.2, 0.1, 0, 3.14, 0), 0.02), _frame(20, 300_000, 200_000, 100_000, 0, 3_140_000, 0, 5)),
        (Torque((0, 0, 0, 0, 0, 1.5), 0.04), _frame(40, 0, 0, 0, 0, 0, 1_500_000, 8)),
        (Stopped(), _frame(100, 0, 0, 0, 0, 0, 0, -2)),
        (FreedriveControl(FreedriveAction.START, 0.2), _frame(200, 1, 0, 0, 0, 0, 0, 6)),
        (FreedriveControl(FreedriveAction.STOP), _frame(200, -1, 0, 0, 0, 0, 0, 6)),
        (TrajectoryControl(TrajectoryAction.NOOP, timeout=0.01), _frame(10, 0, 0, 0, 0, 0, 0, 3)),
        (TrajectoryControl(TrajectoryAction.CANCEL, 7), _frame(200, -1, 7, 0, 0, 0, 0, 3)),
        (TrajectoryControl(TrajectoryAction.STREAM_START), _frame(200, 2, 0, 0, 0, 0, 0, 3)),
        (TrajectoryControl(TrajectoryAction.STREAM_END, 123), _frame(200, 3, 123, 0, 0, 0, 0, 3)),
        (Idle(0.0), _frame(0, 0, 0, 0, 0, 0, 0, 0)),
        (Idle(-1.0), _frame(-1000, 0, 0, 0, 0, 0, 0, 0)),
    ],
)
def test_every_mode_has_its_documented_layout(message: ReverseCommand, expected: bytes) -> None:
    assert _sent(message) == expected
    assert len(expected) == FRAME_BYTES
    assert feed_all_ways(_robot, expected) == [message]


def test_defaults_are_urcls() -> None:
    assert ServoJ(ZEROS).timeout == 0.02
    assert Idle().timeout == 1.0
    assert TrajectoryControl(TrajectoryAction.NOOP).timeout == 0.2
    assert FreedriveControl(FreedriveAction.NOOP).timeout == 0.2


def test_control_modes_have_the_reference_values() -> None:
    assert {m.name: m.value for m in ControlMode} == {
        "STOPPED": -2,
        "UNINITIALIZED": -1,
        "IDLE": 0,
        "SERVOJ": 1,
        "SPEEDJ": 2,
        "FORWARD": 3,
        "SPEEDL": 4,
        "POSE": 5,
        "FREEDRIVE": 6,
        "TOOL_IN_CONTACT": 7,
        "TORQUE": 8,
    }
    assert [a.value for a in TrajectoryAction] == [-1, 0, 1, 2, 3]
    assert [a.value for a in FreedriveAction] == [-1, 0, 1]


# -- what the daemon side refuses to send --------------------------------------------------------------


@pytest.mark.parametrize(
    "message",
    [
        ServoJ((math.nan, 0, 0, 0, 0, 0)),
        ServoJ((math.inf, 0, 0, 0, 0, 0)),
        ServoJ((0, 0, 0, 0, 0, -math.inf)),
        ServoJ((2147.4836475, 0, 0, 0, 0, 0)),  # one step past int32 after rounding
        SpeedJ((0, 0, 0, 0, 0, -2147.4836486)),
        ServoJ((0, 0, 0, 0, 0)),
        ServoJ((0, 0, 0, 0, 0, 0, 0)),
        ServoJ(ZEROS, math.nan),
        ServoJ(ZEROS, 3e6),  # 3e9 ms does not fit an int32
        Idle(math.inf),
        Torque(("1", 0, 0, 0, 0, 0)),  # type: ignore[arg-type]
        TrajectoryControl(TrajectoryAction.START, -1),
        TrajectoryControl(TrajectoryAction.START, 2**31),
        TrajectoryControl(TrajectoryAction.NOOP, 3),
        TrajectoryControl(TrajectoryAction.STREAM_START, 1),
        TrajectoryControl(TrajectoryAction.START, 1.0),  # type: ignore[arg-type]
        TrajectoryControl(7, 0),  # type: ignore[arg-type]
        FreedriveControl(2),  # type: ignore[arg-type]
        FreedriveControl(FreedriveAction.START, math.nan),
    ],
)
def test_unrepresentable_commands_are_local_protocol_errors(message: ReverseCommand) -> None:
    conn = ReverseConnection(Side.DAEMON)
    with pytest.raises(LocalProtocolError) as info:
        conn.send(message)
    assert info.value.protocol == "reverse"
    assert conn.data_to_send() == b""
    conn.send(Idle())  # a refused message does not break the connection
    assert len(conn.data_to_send()) == FRAME_BYTES


def test_plain_ints_are_accepted_for_enum_fields() -> None:
    assert _sent(TrajectoryControl(1, 4)) == _sent(TrajectoryControl(TrajectoryAction.START, 4))  # type: ignore[arg-type]


def test_the_robot_side_sends_nothing_and_the_daemon_only_commands() -> None:
    with pytest.raises(LocalProtocolError):
        ReverseConnection(Side.ROBOT).send(Idle())
    with pytest.raises(LocalProtocolError):
        ReverseConnection(Side.DAEMON).send(UnknownReverseCommand(0.0, 9, (0,) * 6))  # type: ignore[arg-type]
    with pytest.raises(LocalProtocolError):
        encode_reverse_command("SERVOJ")  # type: ignore[arg-type]


# -- robot side decoding --------------------------------------------------------------------------------


@pytest.mark.parametrize("mode", [-3, -1, 7, 9, 100, INT32_MIN, INT32_MAX])
def test_modes_the_daemon_never_sends_are_reported_not_refused(mode: int) -> None:
    wire = _frame(40, 1, 2, 3, 4, 5, 6, mode)
    assert feed_all_ways(_robot, wire) == [UnknownReverseCommand(0.04, mode, (1, 2, 3, 4, 5, 6))]


def test_unknown_trajectory_and_freedrive_actions_are_reported() -> None:
    assert decode_reverse_command(_frame(200, 4, 9, 0, 0, 0, 0, 3)) == UnknownReverseCommand(
        0.2, 3, (4, 9, 0, 0, 0, 0)
    )
    assert decode_reverse_command(_frame(200, 2, 0, 0, 0, 0, 0, 6)) == UnknownReverseCommand(
        0.2, 6, (2, 0, 0, 0, 0, 0)
    )


def test_fields_the_script_ignores_are_ignored_on_the_robot_side() -> None:
    # urcl's keepalive carries uninitialised bytes 4–27 (§6.8); the script ignores them.
    assert decode_reverse_command(_frame(1000, -7, 99, 5, 5, 5, 5, 0)) == Idle(1.0)
    assert decode_reverse_command(_frame(12345, 1, 2, 3, 4, 5, 6, -2)) == Stopped()
    assert decode_reverse_command(_frame(200, 0, 55, 1, 1, 1, 1, 3)) == TrajectoryControl(
        TrajectoryAction.NOOP
    )
    assert decode_reverse_command(_frame(200, 1, 0, 8, 8, 8, 8, 6)) == FreedriveControl(FreedriveAction.START)


def test_a_negative_point_count_is_reported_as_read() -> None:
    assert decode_reverse_command(_frame(200, 1, -4, 0, 0, 0, 0, 3)) == TrajectoryControl(
        TrajectoryAction.START, -4, 0.2
    )


def test_decoding_at_an_offset_and_several_frames_per_chunk() -> None:
    one, two = _sent(ServoJ((1, 2, 3, 4, 5, 6))), _sent(Idle(0.5))
    assert decode_reverse_command(b"xyz" + two, 3) == Idle(0.5)
    events = feed_all_ways(_robot, one + two + one)
    assert events == [ServoJ((1, 2, 3, 4, 5, 6)), Idle(0.5), ServoJ((1, 2, 3, 4, 5, 6))]


def test_a_partial_frame_waits_and_eof_inside_it_is_an_error() -> None:
    conn = _robot()
    assert conn.receive_data(_sent(Idle())[:31]) == []
    with pytest.raises(RemoteProtocolError) as info:
        conn.receive_eof()
    assert info.value.offset == 0
    with pytest.raises(RemoteProtocolError):
        conn.receive_data(b"\x00")


def test_a_clean_eof_ends_receiving() -> None:
    conn = _robot()
    assert conn.receive_data(_sent(Idle())) == [Idle()]
    assert conn.receive_eof() == []
    with pytest.raises(LocalProtocolError):
        conn.receive_data(b"\x00")


# -- daemon side: input is ignored, counted and capped --------------------------------------------------


def test_the_daemon_side_counts_and_drops_what_it_receives() -> None:
    conn = ReverseConnection(Side.DAEMON)
    assert conn.receive_data(b"hello") == []
    assert conn.receive_data(bytes(100)) == []
    assert conn.ignored_bytes == 105
    conn.send(Idle())
    assert len(conn.data_to_send()) == FRAME_BYTES


def test_the_daemon_side_gives_up_on_a_chatty_peer() -> None:
    conn = ReverseConnection(Side.DAEMON)
    conn.receive_data(bytes(MAX_IGNORED_BYTES))
    with pytest.raises(RemoteProtocolError) as info:
        conn.receive_data(b"\x00")
    assert info.value.protocol == "reverse"
    with pytest.raises(RemoteProtocolError):
        conn.receive_data(b"")
    with pytest.raises(LocalProtocolError):
        conn.send(Idle())


# -- timeout clamping (§4.2 rules) ----------------------------------------------------------------------


def test_step_time_follows_urcl() -> None:
    assert step_time_for_frequency(500) == 0.002
    assert step_time_for_frequency(125) == 0.008
    assert step_time_for_frequency(300) == 0.003  # ⌊1000 / 300⌋ ms


@pytest.mark.parametrize(
    ("mode", "timeout", "expected"),
    [
        (ControlMode.SERVOJ, 0.04, 0.04),
        (ControlMode.SERVOJ, 0.0, 0.002),
        (ControlMode.SERVOJ, -1.0, 0.002),
        (ControlMode.SPEEDJ, 0.001, 0.002),
        (ControlMode.SPEEDL, 0.5, 0.2),
        (ControlMode.POSE, 0.2, 0.2),
        (ControlMode.TORQUE, 10.0, 0.2),
        (ControlMode.IDLE, 0.0, 0.0),
        (ControlMode.IDLE, 0.001, 0.002),
        (ControlMode.IDLE, 1.0, 1.0),
        (ControlMode.IDLE, -1.0, -1.0),
        (ControlMode.FORWARD, 60.0, 60.0),
        (ControlMode.FREEDRIVE, 0.0015, 0.002),
        (ControlMode.STOPPED, 5.0, 0.1),
    ],
)
def test_clamp_timeout_applies_urcls_rules(mode: ControlMode, timeout: float, expected: float) -> None:
    assert clamp_timeout(mode, timeout, 0.002) == expected


def test_clamp_timeout_with_a_cb3_step() -> None:
    assert clamp_timeout(ControlMode.SERVOJ, 0.004, 0.008) == 0.008
    assert clamp_timeout(ControlMode.FORWARD, 0.004, 0.008) == 0.008


@pytest.mark.parametrize("mode", [ControlMode.UNINITIALIZED, ControlMode.TOOL_IN_CONTACT])
def test_clamp_timeout_refuses_modes_that_are_never_sent(mode: ControlMode) -> None:
    with pytest.raises(LocalProtocolError):
        clamp_timeout(mode, 0.02, 0.002)


# -- hypothesis: round trips and fuzz -------------------------------------------------------------------

scaled = st.integers(INT32_MIN, INT32_MAX).map(lambda i: i / MULT)
vector6 = st.tuples(scaled, scaled, scaled, scaled, scaled, scaled)
timeouts = st.integers(INT32_MIN, INT32_MAX).map(lambda ms: ms / 1000)
counted = st.sampled_from([TrajectoryAction.START, TrajectoryAction.STREAM_END, TrajectoryAction.CANCEL])

commands = st.one_of(
    st.builds(ServoJ, vector6, timeouts),
    st.builds(SpeedJ, vector6, timeouts),
    st.builds(SpeedL, vector6, timeouts),
    st.builds(Pose, vector6, timeouts),
    st.builds(Torque, vector6, timeouts),
    st.builds(Idle, timeouts),
    st.just(Stopped()),
    st.builds(TrajectoryControl, counted, st.integers(0, INT32_MAX), timeouts),
    st.builds(
        TrajectoryControl,
        st.sampled_from([TrajectoryAction.NOOP, TrajectoryAction.STREAM_START]),
        st.just(0),
        timeouts,
    ),
    st.builds(FreedriveControl, st.sampled_from(FreedriveAction), timeouts),
)


@given(st.lists(commands, min_size=1, max_size=6), st.data())
@settings(max_examples=300, deadline=None)
def test_every_command_round_trips_daemon_to_robot(
    messages: list[ReverseCommand], data: st.DataObject
) -> None:
    daemon, robot = ReverseConnection(Side.DAEMON), ReverseConnection(Side.ROBOT)
    for message in messages:
        daemon.send(message)
    wire = daemon.data_to_send()
    assert len(wire) == FRAME_BYTES * len(messages)
    cuts = sorted(data.draw(st.lists(st.integers(0, len(wire)), max_size=5)))
    events = []
    for start, end in zip([0, *cuts], [*cuts, len(wire)], strict=True):
        events += robot.receive_data(wire[start:end])
    assert events == messages


@given(st.binary(max_size=400), st.lists(st.integers(0, 400), max_size=6))
@settings(max_examples=300, deadline=None)
def test_any_bytes_give_events_or_a_remote_protocol_error(blob: bytes, cuts: list[int]) -> None:
    for side in (Side.ROBOT, Side.DAEMON):
        conn = ReverseConnection(side)
        events: list[object] = []
        failure: RemoteProtocolError | None = None
        try:
            for start, end in zip([0, *sorted(cuts)], [*sorted(cuts), len(blob)], strict=True):
                events += conn.receive_data(blob[start:end])
            events += conn.receive_eof()
        except RemoteProtocolError as err:
            failure = err
        assert failure is None or failure.protocol == "reverse"
        if side is Side.ROBOT:
            assert len(events) <= len(blob) // FRAME_BYTES
        else:
            assert events == []


field = st.one_of(st.integers(INT32_MIN, INT32_MAX), st.integers(-2, 4))


@given(st.integers(INT32_MIN, INT32_MAX), st.lists(field, min_size=6, max_size=6), st.integers(-3, 9))
@settings(max_examples=300, deadline=None)
def test_every_complete_frame_decodes_to_exactly_one_event(ms: int, fields: list[int], mode: int) -> None:
    frame = _frame(ms, *fields, mode)
    (event,) = _robot().receive_data(frame)
    if isinstance(event, UnknownReverseCommand):
        assert (event.mode, event.fields) == (mode, tuple(fields))
        return
    try:
        wire = encode_reverse_command(event)
    except LocalProtocolError:
        return  # read as-is (e.g. a negative point count), but not something the daemon may send
    assert wire[28:] == frame[28:]  # same mode back
    assert decode_reverse_command(wire) == event


# -- a whole session, both parties in memory ------------------------------------------------------------


def test_pair_a_session_from_first_keepalive_to_stop() -> None:
    daemon, robot = ReverseConnection(Side.DAEMON), ReverseConnection(Side.ROBOT)
    script: list[ReverseCommand] = [
        Idle(1.0),
        *(ServoJ((0.01 * i, -0.5, 1.0, 0.0, 1.5, 0.0), 0.04) for i in range(5)),
        SpeedJ((0.1, 0, 0, 0, 0, 0), 0.04),
        TrajectoryControl(TrajectoryAction.START, 3, clamp_timeout(ControlMode.FORWARD, 0.2, 0.002)),
        *(TrajectoryControl(TrajectoryAction.NOOP, 0, 0.01) for _ in range(3)),
        FreedriveControl(FreedriveAction.START),
        FreedriveControl(FreedriveAction.NOOP),
        FreedriveControl(FreedriveAction.STOP),
        Idle(1.0),
        Stopped(),
    ]
    received: list[object] = []
    for message in script:
        daemon.send(message)
        wire = daemon.data_to_send()
        assert len(wire) == FRAME_BYTES  # one write per frame (§4.1)
        received += robot.receive_data(wire[:13])
        received += robot.receive_data(wire[13:])
        assert daemon.receive_data(robot.data_to_send()) == []
    assert received == script
    assert robot.receive_eof() == []


# -- the 500 Hz servoj path (encode_servoj, no message object) ------------------------------------------


@settings(max_examples=300, deadline=None)
@given(
    positions=st.lists(st.floats(min_value=-2147.0, max_value=2147.0), min_size=6, max_size=6),
    timeout=st.floats(min_value=0.0, max_value=1000.0),
)
def test_encode_servoj_gives_the_bytes_of_sending_servoj(positions: list[float], timeout: float) -> None:
    assert encode_servoj(positions, timeout) == _sent(ServoJ(tuple(positions), timeout))


@pytest.mark.parametrize(
    ("positions", "timeout"),
    [
        ((math.nan, 0.0, 0.0, 0.0, 0.0, 0.0), 0.1),
        ((math.inf, 0.0, 0.0, 0.0, 0.0, 0.0), 0.1),
        ((3000.0, 0.0, 0.0, 0.0, 0.0, 0.0), 0.1),
        ((0.0,) * 5, 0.1),
        ((0.0,) * 6, math.nan),
    ],
)
def test_encode_servoj_refuses_what_sending_servoj_refuses(
    positions: tuple[float, ...], timeout: float
) -> None:
    with pytest.raises(LocalProtocolError) as expected:
        _sent(ServoJ(positions, timeout))
    with pytest.raises(LocalProtocolError) as got:
        encode_servoj(positions, timeout)
    assert str(got.value) == str(expected.value)
