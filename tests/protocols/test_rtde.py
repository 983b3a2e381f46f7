"""RTDE codec (urdaemon.protocols.rtde): golden bytes, every split, round trips, order rules, fuzz."""

from __future__ import annotations

import itertools
import struct
from collections.abc import Callable
from pathlib import Path
from typing import Any, get_args

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.protocols.feeding import feed_all_ways
from urdaemon.errors import LocalProtocolError, RemoteProtocolError
from urdaemon.protocols import Side
from urdaemon.protocols.rtde import (
    CB3_MAX_FREQUENCY_HZ,
    E_SERIES_MAX_FREQUENCY_HZ,
    MAX_PACKAGE_BYTES,
    MAX_RECIPE_NAMES_BYTES,
    MAX_UNANSWERED_REQUESTS,
    ControllerVersion,
    ControllerVersionReply,
    ControllerVersionRequested,
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
    PackageType,
    Pause,
    PauseAccept,
    PauseReply,
    PauseRequested,
    ProtocolVersionAccept,
    ProtocolVersionReply,
    ProtocolVersionRequested,
    Recipe,
    RequestProtocolVersion,
    RtdeConnection,
    RtdeState,
    RtdeValue,
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
    max_frequency,
)
from urdaemon.protocols.rtde_variables import (
    IN_USE,
    INPUT_VARIABLES,
    NOT_FOUND,
    OUTPUT_VARIABLES,
    RTDE_TYPES,
    input_types,
    output_types,
    type_size,
)

RESOURCES = Path(__file__).resolve().parents[2] / "resources" / "rtde"
OUTPUT_NAMES = tuple(RESOURCES.joinpath("output_recipe.txt").read_text().split())
INPUT_NAMES = tuple(RESOURCES.joinpath("input_recipe.txt").read_text().split())

# §1.10, typed by hand from the reference tables: an independent check of the variable table
V6, V3, D, U8, U32, U64, I32 = "VECTOR6D", "VECTOR3D", "DOUBLE", "UINT8", "UINT32", "UINT64", "INT32"
# fmt: off
OUTPUT_RECIPE_TYPES = (
    D, V6, V6, D, D, U32, V6, V6, V6, U64, U64, D, D, D, D, U32,
    U32, U32, D, D, I32, D, D, I32, I32, U32, U32, V6, V6, D, V3, V6,
)
# fmt: on
INPUT_RECIPE_TYPES = (U32, D, U8, U8, U8, U8, U8, U8, U8, U8, D, D)


def frame(kind: int, payload: bytes = b"") -> bytes:
    """An RTDE package built by hand (§1.1), independent of the codec."""
    return struct.pack(">HB", 3 + len(payload), kind) + payload


def sample(rtde_type: str, seed: int = 1) -> RtdeValue:
    """A representative value of ``rtde_type``."""
    if rtde_type == "BOOL":
        return seed % 2 == 1
    if rtde_type == "DOUBLE":
        return seed * 0.25
    if rtde_type.startswith("VECTOR"):
        n = 3 if rtde_type == "VECTOR3D" else 6
        if rtde_type.endswith("D"):
            return tuple(seed + i * 0.5 for i in range(n))
        return tuple(seed + i for i in range(n))
    return seed


def standard_output_values(seed: int = 1) -> tuple[RtdeValue, ...]:
    return tuple(sample(t, seed + i) for i, t in enumerate(OUTPUT_RECIPE_TYPES))


INPUT_VALUES: tuple[RtdeValue, ...] = (1, 0.5, 0x01, 0xFF, 0, 0, 0, 0, 0x02, 0x00, 0.0, 0.75)


class Pair:
    """A DAEMON-side and a ROBOT-side connection joined back to back in memory."""

    def __init__(self, version: int = 2) -> None:
        self.daemon = RtdeConnection(Side.DAEMON, protocol_version=version)
        self.robot = RtdeConnection(Side.ROBOT, protocol_version=version)
        self.daemon_received = 0

    def to_robot(self, *messages: Message) -> list[Event]:
        for message in messages:
            self.daemon.send(message)
        return self.robot.receive_data(self.daemon.data_to_send())

    def to_daemon(self, *messages: Message) -> list[Event]:
        for message in messages:
            self.robot.send(message)
        data = self.robot.data_to_send()
        self.daemon_received += len(data)
        return self.daemon.receive_data(data)

    def exchange(self, request: Message, reply: Message) -> Event:
        """Send ``request``, answer it with ``reply``; the daemon's one event."""
        assert len(self.to_robot(request)) == 1
        events = self.to_daemon(reply)
        assert len(events) == 1
        return events[0]

    def configure(self, *, start: bool = True, inputs: bool = True) -> None:
        """Standard recipes set up (and started): output recipe id 1, input recipe id 2."""
        if self.daemon.protocol_version == 2:
            self.exchange(SetupOutputs(500.0, OUTPUT_NAMES), OutputsSetup(1, output_types(OUTPUT_NAMES)))
        else:
            self.exchange(SetupOutputs(None, OUTPUT_NAMES), OutputsSetup(None, output_types(OUTPUT_NAMES)))
        if inputs:
            self.exchange(SetupInputs(INPUT_NAMES), InputsSetup(2, input_types(INPUT_NAMES)))
        if start:
            assert self.exchange(Start(), StartAccept(True)) == StartReply(True)


def states(pair: Pair) -> tuple[RtdeState, RtdeState]:
    """(daemon state, robot state), read fresh each time."""
    return pair.daemon.state, pair.robot.state


def both(state: RtdeState) -> tuple[RtdeState, RtdeState]:
    return state, state


def daemon_after(*messages: Message, version: int = 2, configure: bool = False) -> RtdeConnection:
    """A daemon side that sent ``messages`` (and, with ``configure``, is running the standard recipes)."""
    if configure:
        pair = Pair(version)
        pair.configure()
        conn = pair.daemon
    else:
        conn = RtdeConnection(Side.DAEMON, protocol_version=version)
    for message in messages:
        conn.send(message)
    conn.data_to_send()
    return conn


def robot_running(version: int = 2) -> RtdeConnection:
    pair = Pair(version)
    pair.configure()
    return pair.robot


# -- golden bytes (§1.11) -------------------------------------------------------------------------


def test_request_protocol_version_golden_bytes() -> None:
    daemon = RtdeConnection(Side.DAEMON)
    daemon.send(RequestProtocolVersion(2))
    assert daemon.data_to_send() == bytes.fromhex("00 05 56 00 02")
    assert feed_all_ways(lambda: RtdeConnection(Side.ROBOT), bytes.fromhex("00 05 56 00 02")) == [
        ProtocolVersionRequested(2)
    ]


def test_protocol_version_accepted_golden_bytes() -> None:
    robot = RtdeConnection(Side.ROBOT)
    robot.receive_data(bytes.fromhex("00 05 56 00 02"))
    robot.send(ProtocolVersionAccept(True))
    assert robot.data_to_send() == bytes.fromhex("00 04 56 01")
    events = feed_all_ways(lambda: daemon_after(RequestProtocolVersion(2)), bytes.fromhex("00 04 56 01"))
    assert events == [ProtocolVersionReply(True)]


def test_controller_version_golden_bytes() -> None:
    daemon = RtdeConnection(Side.DAEMON)
    daemon.send(GetControllerVersion())
    assert daemon.data_to_send() == bytes.fromhex("00 03 76")
    reply = bytes.fromhex("00 13 76") + struct.pack(">IIII", 5, 12, 2, 1101534)
    robot = RtdeConnection(Side.ROBOT)
    assert robot.receive_data(bytes.fromhex("00 03 76")) == [ControllerVersionRequested()]
    robot.send(ControllerVersionReply(5, 12, 2, 1101534))
    assert robot.data_to_send() == reply
    events = feed_all_ways(lambda: daemon_after(GetControllerVersion()), reply)
    assert events == [ControllerVersion(5, 12, 2, 1101534)]


def test_setup_outputs_golden_bytes() -> None:
    request = bytes.fromhex("00 1D 4F 40 7F 40 00 00 00 00 00") + b"timestamp,actual_q"
    daemon = RtdeConnection(Side.DAEMON)
    daemon.send(SetupOutputs(500.0, ("timestamp", "actual_q")))
    assert daemon.data_to_send() == request
    assert feed_all_ways(lambda: RtdeConnection(Side.ROBOT), request) == [
        SetupOutputsRequested(500.0, ("timestamp", "actual_q"))
    ]
    reply = bytes.fromhex("00 13 4F 01") + b"DOUBLE,VECTOR6D"
    robot = RtdeConnection(Side.ROBOT)
    robot.receive_data(request)
    robot.send(OutputsSetup(1, ("DOUBLE", "VECTOR6D")))
    assert robot.data_to_send() == reply
    events = feed_all_ways(lambda: daemon_after(SetupOutputs(500.0, ("timestamp", "actual_q"))), reply)
    assert events == [OutputsConfigured(1, ("DOUBLE", "VECTOR6D"), ())]


@pytest.mark.parametrize(
    ("message", "request_hex", "reply_message", "reply_hex", "event"),
    [
        (Start(), "00 03 53", StartAccept(True), "00 04 53 01", StartReply(True)),
        (Pause(), "00 03 50", PauseAccept(True), "00 04 50 01", PauseReply(True)),
    ],
)
def test_start_and_pause_golden_bytes(
    message: Message, request_hex: str, reply_message: Message, reply_hex: str, event: Event
) -> None:
    pair = Pair()
    pair.configure(start=isinstance(message, Pause))
    pair.daemon.send(message)
    assert pair.daemon.data_to_send() == bytes.fromhex(request_hex)
    assert pair.robot.receive_data(bytes.fromhex(request_hex)) == [
        StartRequested() if isinstance(message, Start) else PauseRequested()
    ]
    pair.robot.send(reply_message)
    assert pair.robot.data_to_send() == bytes.fromhex(reply_hex)
    assert pair.daemon.receive_data(bytes.fromhex(reply_hex)) == [event]


def test_standard_recipes_give_the_documented_package_sizes() -> None:
    """§1.10: 560-byte output packages (v2) and 40-byte input packages for the driver recipes."""
    pair = Pair()
    pair.configure()
    pair.robot.send(OutputData(standard_output_values()))
    output = pair.robot.data_to_send()
    assert len(output) == 560
    assert output[:4] == bytes.fromhex("02 30 55 01")
    pair.daemon.send(InputData(INPUT_VALUES))
    data = pair.daemon.data_to_send()
    assert len(data) == 40
    assert data[:4] == bytes.fromhex("00 28 55 02")


def test_output_data_package_decodes_every_way_it_is_split() -> None:
    values = standard_output_values(3)
    robot = robot_running()
    robot.send(OutputData(values))
    wire = robot.data_to_send()
    events = feed_all_ways(lambda: daemon_after(configure=True), wire + wire)
    assert events == [DataPackage(1, values), DataPackage(1, values)]
    first = events[0]
    assert isinstance(first, DataPackage)
    assert first.values[OUTPUT_NAMES.index("actual_q")] == (4.0, 4.5, 5.0, 5.5, 6.0, 6.5)


def test_output_data_package_by_hand() -> None:
    """A data package packed with struct directly (not by the codec) decodes to the same values."""
    daemon = daemon_after(SetupOutputs(125.0, ("timestamp", "actual_q", "robot_mode")))
    daemon.receive_data(frame(ord("O"), b"\x07DOUBLE,VECTOR6D,INT32"))
    daemon.send(Start())
    daemon.data_to_send()
    daemon.receive_data(frame(ord("S"), b"\x01"))
    body = struct.pack(">Bd6di", 7, 12.5, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 7)
    assert daemon.receive_data(frame(ord("U"), body)) == [
        DataPackage(7, (12.5, (0.1, 0.2, 0.3, 0.4, 0.5, 0.6), 7))
    ]


def test_input_data_package_decodes_every_way_it_is_split() -> None:
    pair = Pair()
    pair.configure()
    pair.daemon.send(InputData(INPUT_VALUES))
    wire = pair.daemon.data_to_send()
    assert wire == frame(ord("U"), struct.pack(">BIdBBBBBBBBdd", 2, *INPUT_VALUES))
    assert feed_all_ways(robot_running, wire) == [InputDataReceived(2, INPUT_VALUES)]


def _fresh(version: int = 2) -> Callable[[], Pair]:
    return lambda: Pair(version)


def _prepared(*requests: Message, version: int = 2, start: bool | None = None) -> Callable[[], Pair]:
    """A pair configured (when ``start`` is not None) that then sent ``requests`` to the robot."""

    def make() -> Pair:
        pair = Pair(version)
        if start is not None:
            pair.configure(start=start)
        if requests:
            pair.to_robot(*requests)
        return pair

    return make


SHORT = ("timestamp", "actual_q", "robot_mode")
EVERY_MESSAGE: list[tuple[str, Callable[[], Pair], Message]] = [
    ("RequestProtocolVersion", _fresh(), RequestProtocolVersion(1)),
    ("GetControllerVersion", _fresh(), GetControllerVersion()),
    ("SetupOutputs-v2", _fresh(), SetupOutputs(250.0, SHORT)),
    ("SetupOutputs-v1", _fresh(1), SetupOutputs(None, SHORT)),
    ("SetupInputs", _fresh(), SetupInputs(INPUT_NAMES)),
    ("Start", _prepared(start=False), Start()),
    ("Pause", _prepared(start=True), Pause()),
    ("InputData", _prepared(start=True), InputData(INPUT_VALUES)),
    ("SendText-v2", _fresh(), SendText(1, "from the daemon", "urdaemon")),
    ("SendText-v1", _fresh(1), SendText(1, "from the daemon", "")),
    ("ProtocolVersionAccept", _prepared(RequestProtocolVersion(1)), ProtocolVersionAccept(True)),
    ("ControllerVersionReply", _prepared(GetControllerVersion()), ControllerVersionReply(10, 11, 0, 7)),
    (
        "OutputsSetup-v2",
        _prepared(SetupOutputs(9.0, SHORT)),
        OutputsSetup(4, ("DOUBLE", "VECTOR6D", "INT32")),
    ),
    (
        "OutputsSetup-v1",
        _prepared(SetupOutputs(None, SHORT), version=1),
        OutputsSetup(None, ("DOUBLE", NOT_FOUND, "INT32")),
    ),
    ("InputsSetup", _prepared(SetupInputs(("a", "b"))), InputsSetup(6, (IN_USE, "UINT8"))),
    ("StartAccept", _prepared(Start(), start=False), StartAccept(False)),
    ("PauseAccept", _prepared(Pause(), start=True), PauseAccept(True)),
    ("OutputData-v2", _prepared(start=True), OutputData(standard_output_values(5))),
    ("OutputData-v1", _prepared(start=True, version=1), OutputData(standard_output_values(6))),
    ("Text-v2", _fresh(), Text(0, "runtime exception", "Controller")),
    ("Text-v1", _fresh(1), Text(0, "runtime exception", "")),
]


ROBOT_MESSAGES = {
    "ProtocolVersionAccept",
    "ControllerVersionReply",
    "OutputsSetup",
    "InputsSetup",
    "StartAccept",
    "PauseAccept",
    "OutputData",
    "Text",
}


def vars_of(obj: object) -> dict[str, Any]:
    """The fields of a slotted dataclass as a dict."""
    return {name: getattr(obj, name) for name in getattr(obj, "__slots__", ())}


@pytest.mark.parametrize(
    ("prepare", "message"), [(p, m) for _, p, m in EVERY_MESSAGE], ids=[n for n, _, _ in EVERY_MESSAGE]
)
def test_every_message_decodes_whole_split_and_bytewise(
    prepare: Callable[[], Pair], message: Message
) -> None:
    pair = prepare()
    sender, side = (
        (pair.robot, "daemon") if type(message).__name__ in ROBOT_MESSAGES else (pair.daemon, "robot")
    )
    sender.send(message)
    wire = sender.data_to_send()
    events = feed_all_ways(lambda: getattr(prepare(), side), wire)
    assert len(events) == 1
    # every field of the message reappears in the event (the ids the codec fills in aside)
    fields = {k: v for k, v in vars_of(message).items() if k != "recipe_id"}
    assert fields.items() <= vars_of(events[0]).items()


# -- protocol v1 (§1.4) ---------------------------------------------------------------------------


def test_v1_setup_outputs_has_no_frequency_and_no_recipe_id() -> None:
    daemon = RtdeConnection(Side.DAEMON, protocol_version=1)
    daemon.send(SetupOutputs(None, ("timestamp",)))
    assert daemon.data_to_send() == frame(ord("O"), b"timestamp")
    events = feed_all_ways(
        lambda: daemon_after(SetupOutputs(None, ("timestamp",)), version=1), frame(ord("O"), b"DOUBLE")
    )
    assert events == [OutputsConfigured(None, ("DOUBLE",), ())]


def test_v1_data_package_has_no_recipe_id() -> None:
    pair = Pair(version=1)
    pair.configure()
    pair.robot.send(OutputData(standard_output_values()))
    wire = pair.robot.data_to_send()
    assert len(wire) == 559
    assert pair.daemon.receive_data(wire) == [DataPackage(None, standard_output_values())]
    # inputs carry their recipe id in v1 too
    pair.daemon.send(InputData(INPUT_VALUES))
    assert len(pair.daemon.data_to_send()) == 40


def test_v1_and_v2_text_message_layouts() -> None:
    v2 = frame(ord("M"), b"\x05hello\x03urc\x02")
    assert feed_all_ways(lambda: RtdeConnection(Side.DAEMON), v2) == [TextMessage(2, "hello", "urc")]
    v1 = frame(ord("M"), b"\x01broken")
    assert feed_all_ways(lambda: RtdeConnection(Side.DAEMON, protocol_version=1), v1) == [
        TextMessage(MessageLevel.ERROR, "broken", "")
    ]
    daemon = RtdeConnection(Side.DAEMON)
    daemon.send(SendText(MessageLevel.INFO, "hi", "py"))
    assert daemon.data_to_send() == frame(ord("M"), b"\x02hi\x02py\x03")


def test_accepted_version_switches_the_framing_after_the_reply() -> None:
    pair = Pair(version=2)
    assert pair.exchange(RequestProtocolVersion(1), ProtocolVersionAccept(True)) == ProtocolVersionReply(True)
    assert pair.daemon.protocol_version == pair.robot.protocol_version == 1
    assert pair.to_daemon(Text(3, "now v1", "")) == [TextMessage(3, "now v1", "")]


def test_refused_version_keeps_the_framing() -> None:
    pair = Pair(version=1)
    assert pair.exchange(RequestProtocolVersion(2), ProtocolVersionAccept(False)) == ProtocolVersionReply(
        False
    )
    assert pair.daemon.protocol_version == pair.robot.protocol_version == 1


# -- a whole conversation -------------------------------------------------------------------------


def test_full_conversation_daemon_and_robot() -> None:
    pair = Pair(version=1)
    # urcl's order (§1.6): protocol version, controller version, outputs, inputs, start
    assert pair.to_robot(RequestProtocolVersion(2)) == [ProtocolVersionRequested(2)]
    assert pair.to_daemon(ProtocolVersionAccept(True)) == [ProtocolVersionReply(True)]
    assert pair.to_robot(GetControllerVersion()) == [ControllerVersionRequested()]
    warning = "SafetySetup has not been confirmed yet"  # PolyScope X on every connect (§1.6 step 3)
    assert pair.to_daemon(Text(MessageLevel.WARNING, warning, "Controller")) == [
        TextMessage(MessageLevel.WARNING, warning, "Controller")
    ]
    assert pair.to_daemon(ControllerVersionReply(5, 21, 0, 1)) == [ControllerVersion(5, 21, 0, 1)]
    names = (*OUTPUT_NAMES, "input_bit_register_0")
    assert pair.to_robot(SetupOutputs(500.0, names)) == [SetupOutputsRequested(500.0, names)]
    refused = pair.to_daemon(OutputsSetup(1, output_types(names)))
    assert refused == [OutputsConfigured(1, (*OUTPUT_RECIPE_TYPES, NOT_FOUND), ("input_bit_register_0",))]
    assert states(pair) == both(RtdeState.IDLE)
    pair.configure(start=False)
    assert states(pair) == both(RtdeState.CONFIGURED)
    assert pair.daemon.input_recipe_id == pair.robot.input_recipe_id == 2
    assert pair.to_robot(Start()) == [StartRequested()]
    assert states(pair)[0] == RtdeState.STARTING
    assert pair.to_daemon(StartAccept(True), OutputData(standard_output_values(1))) == [
        StartReply(True),
        DataPackage(1, standard_output_values(1)),
    ]
    for seed in range(5):
        assert pair.to_daemon(OutputData(standard_output_values(seed))) == [
            DataPackage(1, standard_output_values(seed))
        ]
        assert pair.to_robot(InputData(INPUT_VALUES)) == [InputDataReceived(2, INPUT_VALUES)]
    assert pair.to_robot(SendText(MessageLevel.INFO, "hello", "urdaemon")) == [
        TextReceived(MessageLevel.INFO, "hello", "urdaemon")
    ]
    assert pair.to_robot(Pause()) == [PauseRequested()]
    assert states(pair)[0] == RtdeState.PAUSING
    # samples sent before the PAUSE was handled still arrive, then the reply
    assert pair.to_daemon(OutputData(standard_output_values(9)), PauseAccept(True)) == [
        DataPackage(1, standard_output_values(9)),
        PauseReply(True),
    ]
    assert states(pair) == both(RtdeState.PAUSED)
    assert pair.exchange(Start(), StartAccept(True)) == StartReply(True)
    assert states(pair) == both(RtdeState.RUNNING)
    assert pair.daemon.data_to_send() == pair.robot.data_to_send() == b""


def test_several_input_recipes_each_with_its_id() -> None:
    pair = Pair()
    pair.configure(start=False)
    registers = ("input_int_register_24", "input_double_register_24", "input_bit_register_64")
    assert pair.exchange(SetupInputs(registers), InputsSetup(3, input_types(registers))) == InputsConfigured(
        3, ("INT32", "DOUBLE", "BOOL"), (), ()
    )
    assert set(pair.daemon.input_recipes) == set(pair.robot.input_recipes) == {2, 3}
    pair.exchange(Start(), StartAccept(True))
    assert pair.to_robot(InputData((-5, 2.5, True))) == [InputDataReceived(3, (-5, 2.5, True))]
    assert pair.to_robot(InputData(INPUT_VALUES, recipe_id=2)) == [InputDataReceived(2, INPUT_VALUES)]


def test_in_use_inputs_are_reported_and_give_no_recipe() -> None:
    pair = Pair()
    types = (IN_USE, "DOUBLE")
    event = pair.exchange(SetupInputs(("speed_slider_mask", "speed_slider_fraction")), InputsSetup(0, types))
    assert event == InputsConfigured(0, types, (), ("speed_slider_mask",))
    assert pair.daemon.input_recipes == {} == pair.robot.input_recipes


def test_a_large_chunk_of_many_packages_is_decoded_whole() -> None:
    """A read far larger than one package (a daemon that fell behind) is not mistaken for a flood."""
    robot = robot_running()
    for seed in range(200):
        robot.send(OutputData(standard_output_values(seed)))
    wire = robot.data_to_send()
    assert len(wire) > MAX_PACKAGE_BYTES
    events = daemon_after(configure=True).receive_data(wire)
    assert events == [DataPackage(1, standard_output_values(seed)) for seed in range(200)]


# -- the daemon refuses to send out of order ------------------------------------------------------


def refuses(conn: RtdeConnection, message: Message, match: str) -> None:
    state, pending = conn.state, conn.pending_requests
    with pytest.raises(LocalProtocolError, match=match) as caught:
        conn.send(message)
    assert caught.value.protocol == "rtde"
    assert conn.data_to_send() == b""
    assert (conn.state, conn.pending_requests) == (state, pending)


def test_daemon_refuses_start_before_outputs_are_set_up() -> None:
    refuses(RtdeConnection(Side.DAEMON), Start(), "REQUEST_START is out of order in state IDLE")


def test_daemon_refuses_pause_when_not_running() -> None:
    refuses(daemon_after(), Pause(), "REQUEST_PAUSE")


def test_daemon_refuses_input_data_before_start() -> None:
    pair = Pair()
    pair.configure(start=False)
    refuses(pair.daemon, InputData(INPUT_VALUES), "INPUT_DATA is out of order in state CONFIGURED")


def test_daemon_refuses_input_data_without_an_input_recipe() -> None:
    pair = Pair()
    pair.configure(inputs=False)
    refuses(pair.daemon, InputData(INPUT_VALUES), "never set up")
    refuses(daemon_after(configure=True), InputData(INPUT_VALUES, recipe_id=9), "input recipe 9")


def test_daemon_refuses_values_that_do_not_fit_the_input_recipe() -> None:
    conn = daemon_after(configure=True)
    refuses(conn, InputData(INPUT_VALUES[:-1]), "12 fields, got 11")
    refuses(conn, InputData((1, 0.5, 256, *INPUT_VALUES[3:])), "do not fit")


def test_daemon_sends_one_request_at_a_time() -> None:
    refuses(daemon_after(GetControllerVersion()), RequestProtocolVersion(2), "GET_URCONTROL_VERSION reply")


def test_daemon_refuses_a_version_change_after_setup() -> None:
    pair = Pair()
    pair.configure(start=False)
    refuses(pair.daemon, RequestProtocolVersion(1), "REQUEST_VERSION is out of order")


def test_daemon_refuses_versions_it_cannot_speak() -> None:
    refuses(RtdeConnection(Side.DAEMON), RequestProtocolVersion(3), "speaks RTDE protocol versions")


def test_daemon_refuses_text_while_the_version_may_change() -> None:
    refuses(daemon_after(RequestProtocolVersion(1)), SendText(3, "x", ""), "version change is pending")


@pytest.mark.parametrize("frequency", [0.0, -1.0, 500.5, float("nan"), float("inf"), None])
def test_daemon_refuses_bad_v2_frequencies(frequency: float | None) -> None:
    refuses(RtdeConnection(Side.DAEMON), SetupOutputs(frequency, ("timestamp",)), "frequency")


def test_daemon_bounds_the_frequency_by_the_controller_generation() -> None:
    pair = Pair()
    pair.exchange(GetControllerVersion(), ControllerVersionReply(3, 15, 8, 0))
    refuses(pair.daemon, SetupOutputs(126.0, ("timestamp",)), r"not in \(0, 125.0\]")
    pair.daemon.send(SetupOutputs(CB3_MAX_FREQUENCY_HZ, ("timestamp",)))
    assert max_frequency(3) == CB3_MAX_FREQUENCY_HZ
    assert max_frequency(5) == max_frequency(10) == E_SERIES_MAX_FREQUENCY_HZ


def test_daemon_refuses_a_frequency_under_v1() -> None:
    refuses(RtdeConnection(Side.DAEMON, protocol_version=1), SetupOutputs(125.0, ("timestamp",)), "v1")


@pytest.mark.parametrize(
    "names",
    [(), ("",), ("a,b",), ("tëmp",), ("x" * (MAX_RECIPE_NAMES_BYTES + 1),)],
    ids=["empty", "empty-name", "comma", "non-ascii", "too-long"],
)
def test_daemon_refuses_names_a_controller_cannot_read(names: tuple[str, ...]) -> None:
    refuses(RtdeConnection(Side.DAEMON), SetupInputs(names), "name")


def test_name_list_limit_is_inclusive() -> None:
    names = (*("a" * 9 for _ in range(MAX_RECIPE_NAMES_BYTES // 10)), "a" * 8)
    assert len(",".join(names)) == MAX_RECIPE_NAMES_BYTES
    pair = Pair()
    assert pair.to_robot(SetupOutputs(1.0, names)) == [SetupOutputsRequested(1.0, names)]


def test_text_fields_are_limited_by_their_length_byte() -> None:
    refuses(RtdeConnection(Side.DAEMON), SendText(3, "x" * 256, ""), "255 bytes")
    refuses(RtdeConnection(Side.DAEMON, protocol_version=1), SendText(3, "x", "src"), "no source field")
    refuses(RtdeConnection(Side.DAEMON), SendText(256, "x", ""), "uint8")


def test_each_side_sends_only_its_own_messages() -> None:
    refuses(RtdeConnection(Side.DAEMON), StartAccept(True), "DAEMON side does not send StartAccept")
    refuses(RtdeConnection(Side.ROBOT), Start(), "ROBOT side does not send Start")


# -- the robot reports requests in any order and lets the fake answer -----------------------------


def test_robot_reports_start_before_setup_and_may_only_refuse_it() -> None:
    robot = RtdeConnection(Side.ROBOT)
    assert robot.receive_data(frame(ord("S"))) == [StartRequested()]
    refuses(robot, StartAccept(True), "without an output recipe")
    robot.send(StartAccept(False))
    assert robot.data_to_send() == bytes.fromhex("00 04 53 00")
    assert robot.state is RtdeState.IDLE
    assert robot.pending_requests == ()


def test_robot_reports_pause_before_setup() -> None:
    robot = RtdeConnection(Side.ROBOT)
    assert robot.receive_data(frame(ord("P"))) == [PauseRequested()]
    robot.send(PauseAccept(False))
    assert robot.data_to_send() == bytes.fromhex("00 04 50 00")
    assert robot.state is RtdeState.IDLE


def test_robot_reports_input_data_before_start() -> None:
    pair = Pair()
    pair.configure(start=False)
    wire = frame(ord("U"), struct.pack(">BIdBBBBBBBBdd", 2, *INPUT_VALUES))
    assert pair.robot.receive_data(wire) == [InputDataReceived(2, INPUT_VALUES)]
    assert pair.robot.state is RtdeState.CONFIGURED


def test_robot_judges_order_when_it_answers() -> None:
    """A client that pipelines SETUP_OUTPUTS and START gets both handled in order, like a controller."""
    robot = RtdeConnection(Side.ROBOT)
    wire = frame(ord("O"), struct.pack(">d", 500.0) + b"timestamp") + frame(ord("S"))
    assert robot.receive_data(wire) == [SetupOutputsRequested(500.0, ("timestamp",)), StartRequested()]
    assert robot.pending_requests == (
        PackageType.CONTROL_PACKAGE_SETUP_OUTPUTS,
        PackageType.CONTROL_PACKAGE_START,
    )
    refuses(robot, StartAccept(True), "oldest unanswered request is CONTROL_PACKAGE_SETUP_OUTPUTS")
    robot.send(OutputsSetup(1, ("DOUBLE",)))
    robot.send(StartAccept(True))
    assert robot.state is RtdeState.RUNNING
    robot.send(OutputData((1.0,)))
    assert robot.data_to_send()[-12:] == frame(ord("U"), struct.pack(">Bd", 1, 1.0))


def test_robot_answers_need_a_request() -> None:
    refuses(RtdeConnection(Side.ROBOT), ControllerVersionReply(5, 1, 1, 1), "no request is waiting")


def test_robot_may_not_accept_a_version_after_setup() -> None:
    pair = Pair()
    pair.configure(start=False)
    assert pair.robot.receive_data(frame(ord("V"), b"\x00\x01")) == [ProtocolVersionRequested(1)]
    refuses(pair.robot, ProtocolVersionAccept(True), "answer accepted=False")
    pair.robot.send(ProtocolVersionAccept(False))
    assert pair.robot.protocol_version == 2


def test_robot_may_not_accept_a_version_it_cannot_speak() -> None:
    robot = RtdeConnection(Side.ROBOT)
    assert robot.receive_data(frame(ord("V"), b"\x00\x03")) == [ProtocolVersionRequested(3)]
    refuses(robot, ProtocolVersionAccept(True), "cannot speak protocol version 3")


def test_robot_setup_answers_must_match_the_request() -> None:
    robot = RtdeConnection(Side.ROBOT)
    robot.receive_data(frame(ord("O"), struct.pack(">d", 10.0) + b"timestamp,actual_q"))
    refuses(robot, OutputsSetup(1, ("DOUBLE",)), "one type per requested name")
    refuses(robot, OutputsSetup(1, ("DOUBLE", IN_USE)), "cannot carry 'IN_USE'")
    refuses(robot, OutputsSetup(None, ("DOUBLE", "VECTOR6D")), "v2 only")
    refuses(robot, OutputsSetup(256, ("DOUBLE", "VECTOR6D")), "uint8")
    robot.send(OutputsSetup(1, ("DOUBLE", "VECTOR6D")))
    robot.data_to_send()
    refuses(robot, OutputData((1.0,)), "OUTPUT_DATA is out of order in state CONFIGURED")


def test_robot_refuses_output_values_that_do_not_fit() -> None:
    robot = robot_running()
    values = list(standard_output_values())
    values[1] = (1.0, 2.0)
    refuses(robot, OutputData(tuple(values)), "6-vector field got 2")


# -- the robot's protocol errors ------------------------------------------------------------------


def fails(conn: RtdeConnection, data: bytes, match: str) -> RemoteProtocolError:
    with pytest.raises(RemoteProtocolError, match=match) as caught:
        conn.receive_data(data)
    assert caught.value.protocol == "rtde"
    assert conn.state is RtdeState.ERROR
    with pytest.raises(RemoteProtocolError):
        conn.receive_data(b"")
    with pytest.raises(LocalProtocolError):
        conn.send(Text(3, "x", "") if conn.side is Side.ROBOT else SendText(3, "x", ""))
    return caught.value


def test_data_package_of_the_wrong_size_names_both_sizes() -> None:
    robot = robot_running()
    robot.send(OutputData(standard_output_values()))
    wire = robot.data_to_send()
    short = struct.pack(">H", len(wire) - 8) + wire[2:-8]
    pair = Pair()
    pair.configure()
    error = fails(pair.daemon, short, r"549 bytes, expected 1 \(id\) \+ 556")
    assert error.offset == pair.daemon_received


def test_error_offset_is_the_offending_package_position_in_the_stream() -> None:
    robot = robot_running()
    robot.send(OutputData(standard_output_values()))
    good = robot.data_to_send()
    pair = Pair()
    pair.configure()
    pair.daemon.receive_data(good + good[:100])
    error = fails(pair.daemon, good[100:] + frame(ord("Z")), "unknown package type 90")
    assert error.offset == pair.daemon_received + 2 * len(good)


def test_data_package_before_start_is_an_error() -> None:
    pair = Pair()
    pair.configure(start=False)
    fails(pair.daemon, frame(ord("U"), b"\x01"), "DATA_PACKAGE in state CONFIGURED")


def test_data_package_for_another_output_recipe_is_an_error() -> None:
    robot = robot_running()
    robot.send(OutputData(standard_output_values()))
    wire = bytearray(robot.data_to_send())
    wire[3] = 9
    fails(daemon_after(configure=True), bytes(wire), "output recipe 9, configured is 1")


def test_reply_without_request_is_an_error() -> None:
    fails(
        RtdeConnection(Side.DAEMON),
        bytes.fromhex("00 04 53 01"),
        "CONTROL_PACKAGE_START reply while no reply",
    )
    fails(daemon_after(GetControllerVersion()), bytes.fromhex("00 04 56 01"), "GET_URCONTROL_VERSION")


def test_package_size_below_the_header_is_an_error() -> None:
    fails(RtdeConnection(Side.ROBOT), bytes.fromhex("00 02 56"), "smaller than the 3-byte header")
    conn = RtdeConnection(Side.ROBOT)
    conn.receive_data(b"\x00")
    fails(conn, b"\x01V", "smaller than the 3-byte header")


@pytest.mark.parametrize(
    ("reply", "match"),
    [
        (b"\x01DOUBLE", "1 types for 2"),
        (b"\x01DOUBLE,FLOAT", "unknown type 'FLOAT'"),
        (b"\x01DOUBLE,IN_USE", "unknown type 'IN_USE'"),
        (b"\x01DOUBLE,\xff", "not ASCII"),
        (b"", "without its recipe id"),
    ],
)
def test_bad_setup_outputs_replies(reply: bytes, match: str) -> None:
    fails(daemon_after(SetupOutputs(1.0, ("timestamp", "actual_q"))), frame(ord("O"), reply), match)


@pytest.mark.parametrize(
    ("payload", "match"),
    [
        (b"\x05hell", "overruns"),
        (b"\x05hello\x03ur", "overruns"),
        (b"\x05hello\x03urc", "expected the level byte"),
        (b"\x05hello\x03urc\x01\x02", "expected the level byte"),
        (b"", "before its message length"),
    ],
)
def test_bad_v2_text_messages(payload: bytes, match: str) -> None:
    fails(RtdeConnection(Side.DAEMON), frame(ord("M"), payload), match)


def test_wrong_payload_sizes_of_fixed_packages() -> None:
    fails(daemon_after(GetControllerVersion()), frame(ord("v"), b"\x00" * 15), "expected 16")
    fails(daemon_after(RequestProtocolVersion(2)), frame(ord("V"), b"\x01\x00"), "expected 1")
    fails(RtdeConnection(Side.ROBOT), frame(ord("V"), b"\x02"), "expected 2")
    fails(RtdeConnection(Side.ROBOT), frame(ord("S"), b"\x00"), "expected none")
    fails(RtdeConnection(Side.ROBOT), frame(ord("O"), b"\x00" * 7), "shorter than its frequency")


def test_eof_inside_a_package_is_an_error() -> None:
    conn = RtdeConnection(Side.DAEMON)
    assert conn.receive_data(frame(ord("M"), b"\x01a\x00\x03")[:-1]) == []
    with pytest.raises(RemoteProtocolError, match="closed 6 bytes into a package") as caught:
        conn.receive_eof()
    assert caught.value.offset == 0
    assert conn.state is RtdeState.ERROR


def test_eof_between_packages_is_clean() -> None:
    conn = RtdeConnection(Side.ROBOT)
    assert conn.receive_data(frame(ord("v"))) == [ControllerVersionRequested()]
    assert conn.receive_eof() == []
    with pytest.raises(LocalProtocolError, match="after receive_eof"):
        conn.receive_data(b"\x00")
    conn.send(ControllerVersionReply(5, 0, 0, 0))  # the other direction may still be open
    assert len(conn.data_to_send()) == 19


def test_robot_rejects_input_data_for_an_unknown_recipe() -> None:
    fails(robot_running(), frame(ord("U"), b"\x07\x00"), "input recipe 7, which was never set up")


INPUT_BODY = struct.pack(">IdBBBBBBBBdd", *INPUT_VALUES)
"""INPUT_VALUES packed by hand for the input recipe (36 bytes, §1.5)."""


def test_robot_reports_longer_input_data_with_the_recipe_fields_and_its_size() -> None:
    # ur_rtde 1.6.5 sends such packages and works against controllers (docs/fake-robot.md)
    robot = robot_running()
    events = robot.receive_data(frame(ord("U"), b"\x02" + INPUT_BODY + b"\x7f" * 48))
    assert events == [InputDataReceived(2, INPUT_VALUES, size=84)]
    assert robot.state is RtdeState.RUNNING


def test_robot_reports_shorter_input_data_with_the_fields_it_holds_whole() -> None:
    robot = robot_running()
    # 35 bytes: the last double is cut off; 12: the UINT32 and the first double; 3: not one field
    assert robot.receive_data(frame(ord("U"), b"\x02" + INPUT_BODY[:35])) == [
        InputDataReceived(2, INPUT_VALUES[:-1], size=35)
    ]
    assert robot.receive_data(frame(ord("U"), b"\x02" + INPUT_BODY[:12])) == [
        InputDataReceived(2, INPUT_VALUES[:2], size=12)
    ]
    assert robot.receive_data(frame(ord("U"), b"\x02" + INPUT_BODY[:3])) == [InputDataReceived(2, (), size=3)]
    assert robot.state is RtdeState.RUNNING


def test_robot_rejects_names_beyond_the_limit() -> None:
    names = b"a" * (MAX_RECIPE_NAMES_BYTES + 1)
    fails(RtdeConnection(Side.ROBOT), frame(ord("I"), names), "the limit is 2048")
    fails(RtdeConnection(Side.ROBOT), frame(ord("I"), b""), "without variable names")
    fails(RtdeConnection(Side.ROBOT), frame(ord("I"), b"caf\xe9"), "not ASCII")


def test_robot_rejects_a_request_flood() -> None:
    robot = RtdeConnection(Side.ROBOT)
    assert len(robot.receive_data(frame(ord("v")) * MAX_UNANSWERED_REQUESTS)) == MAX_UNANSWERED_REQUESTS
    fails(robot, frame(ord("v")), "more than 64 requests")


# -- recipes and the variable table ---------------------------------------------------------------


def test_recipe_refuses_answers_that_are_not_types() -> None:
    for bad in (NOT_FOUND, IN_USE, "FLOAT"):
        with pytest.raises(ValueError, match="no RTDE value type"):
            Recipe(("x",), (bad,))
    with pytest.raises(ValueError, match="1 names but 2 types"):
        Recipe(("x",), ("DOUBLE", "DOUBLE"))


def test_recipe_of_one_vector_field_decodes_to_a_one_tuple() -> None:
    recipe = Recipe(("actual_q",), ("VECTOR6D",))
    wire = recipe.encode(((1.0, 2.0, 3.0, 4.0, 5.0, 6.0),))
    assert recipe.decode(wire) == ((1.0, 2.0, 3.0, 4.0, 5.0, 6.0),)
    assert Recipe(("a",), ("UINT8",)).decode(b"\x07") == (7,)


def test_recipe_layout_matches_the_reference() -> None:
    recipe = Recipe(OUTPUT_NAMES, OUTPUT_RECIPE_TYPES)
    assert recipe.size == 556
    assert recipe.index("payload_inertia") == 31
    assert Recipe(INPUT_NAMES, INPUT_RECIPE_TYPES).size == 36
    assert Recipe(("a", "b"), ("VECTOR6INT32", "VECTOR6UINT32")).decode(
        struct.pack(">6i6I", -1, -2, -3, -4, -5, -6, 1, 2, 3, 4, 5, 2**32 - 1)
    ) == ((-1, -2, -3, -4, -5, -6), (1, 2, 3, 4, 5, 2**32 - 1))


def test_standard_recipes_are_known_with_the_documented_types() -> None:
    assert len(OUTPUT_NAMES) == 32
    assert len(INPUT_NAMES) == 12
    assert output_types(OUTPUT_NAMES) == tuple(OUTPUT_RECIPE_TYPES)
    assert input_types(INPUT_NAMES) == tuple(INPUT_RECIPE_TYPES)
    assert sum(map(type_size, OUTPUT_RECIPE_TYPES)) == 556


def test_register_table() -> None:
    for direction in ("input", "output"):
        assert OUTPUT_VARIABLES[f"{direction}_bit_registers0_to_31"] == "UINT32"
        assert OUTPUT_VARIABLES[f"{direction}_bit_registers32_to_63"] == "UINT32"
        for n in range(64, 128):
            assert OUTPUT_VARIABLES[f"{direction}_bit_register_{n}"] == "BOOL"
        for n in range(48):
            assert OUTPUT_VARIABLES[f"{direction}_int_register_{n}"] == "INT32"
            assert OUTPUT_VARIABLES[f"{direction}_double_register_{n}"] == "DOUBLE"
        # single bits 0..63 are not published by a controller (urcl PR #385; UR's RTDE guide)
        assert f"{direction}_bit_register_0" not in OUTPUT_VARIABLES
        assert f"{direction}_bit_register_63" not in OUTPUT_VARIABLES
        assert f"{direction}_int_register_48" not in OUTPUT_VARIABLES
    assert INPUT_VARIABLES["input_int_register_47"] == "INT32"
    assert "output_int_register_0" not in INPUT_VARIABLES
    assert INPUT_VARIABLES["external_force_torque"] == "VECTOR6D"
    assert "actual_q" not in INPUT_VARIABLES
    assert "speed_slider_fraction" not in OUTPUT_VARIABLES
    assert set(OUTPUT_VARIABLES.values()) | set(INPUT_VARIABLES.values()) <= RTDE_TYPES
    assert output_types(("timestamp", "nonsense")) == ("DOUBLE", NOT_FOUND)


def test_type_sizes() -> None:
    sizes = {"BOOL": 1, "UINT8": 1, "UINT32": 4, "UINT64": 8, "INT32": 4, "DOUBLE": 8}
    sizes |= {"VECTOR3D": 24, "VECTOR6D": 48, "VECTOR6INT32": 24, "VECTOR6UINT32": 24}
    assert {t: type_size(t) for t in RTDE_TYPES} == sizes
    with pytest.raises(ValueError, match="not an RTDE value type"):
        type_size(NOT_FOUND)


# -- hypothesis: round trips ----------------------------------------------------------------------

NAME = st.text(alphabet="abcdefghijklmnopqrstuvwxyz_0123456789", min_size=1, max_size=24)
NAMES = st.lists(NAME, min_size=1, max_size=20).map(tuple)
UINT32S = st.integers(0, 2**32 - 1)
TEXT = st.text(max_size=60)
DOUBLES = st.floats(allow_nan=False)

VALUE_STRATEGIES: dict[str, st.SearchStrategy[Any]] = {
    "BOOL": st.booleans(),
    "UINT8": st.integers(0, 255),
    "UINT32": UINT32S,
    "UINT64": st.integers(0, 2**64 - 1),
    "INT32": st.integers(-(2**31), 2**31 - 1),
    "DOUBLE": DOUBLES,
    "VECTOR3D": st.tuples(DOUBLES, DOUBLES, DOUBLES),
    "VECTOR6D": st.tuples(*[DOUBLES] * 6),
    "VECTOR6INT32": st.tuples(*[st.integers(-(2**31), 2**31 - 1)] * 6),
    "VECTOR6UINT32": st.tuples(*[UINT32S] * 6),
}


@st.composite
def recipes_with_values(draw: st.DrawFn) -> tuple[tuple[str, ...], tuple[RtdeValue, ...]]:
    types = tuple(draw(st.lists(st.sampled_from(sorted(RTDE_TYPES)), min_size=1, max_size=12)))
    values = tuple(draw(VALUE_STRATEGIES[t]) for t in types)
    return types, values


def set_up(pair: Pair, types: tuple[str, ...], *, recipe_id: int = 5) -> None:
    names = tuple(f"field_{i}" for i in range(len(types)))
    version = pair.daemon.protocol_version
    pair.exchange(
        SetupOutputs(500.0 if version == 2 else None, names),
        OutputsSetup(recipe_id if version == 2 else None, types),
    )
    pair.exchange(SetupInputs(names), InputsSetup(recipe_id, types))
    pair.exchange(Start(), StartAccept(True))


@settings(max_examples=150, suppress_health_check=[HealthCheck.too_slow])
@given(recipe=recipes_with_values(), version=st.sampled_from([1, 2]), recipe_id=st.integers(0, 255))
def test_data_round_trips_both_ways(
    recipe: tuple[tuple[str, ...], tuple[RtdeValue, ...]], version: int, recipe_id: int
) -> None:
    types, values = recipe
    pair = Pair(version)
    set_up(pair, types, recipe_id=recipe_id)
    assert pair.to_daemon(OutputData(values)) == [DataPackage(recipe_id if version == 2 else None, values)]
    assert pair.to_robot(InputData(values)) == [InputDataReceived(recipe_id, values)]


@given(version=st.sampled_from([1, 2]), accepted=st.booleans())
def test_protocol_version_round_trip(version: int, accepted: bool) -> None:
    pair = Pair()
    assert pair.to_robot(RequestProtocolVersion(version)) == [ProtocolVersionRequested(version)]
    assert pair.to_daemon(ProtocolVersionAccept(accepted)) == [ProtocolVersionReply(accepted)]
    assert pair.daemon.protocol_version == pair.robot.protocol_version == (version if accepted else 2)


@given(major=UINT32S, minor=UINT32S, bugfix=UINT32S, build=UINT32S)
def test_controller_version_round_trip(major: int, minor: int, bugfix: int, build: int) -> None:
    pair = Pair()
    assert pair.to_robot(GetControllerVersion()) == [ControllerVersionRequested()]
    assert pair.to_daemon(ControllerVersionReply(major, minor, bugfix, build)) == [
        ControllerVersion(major, minor, bugfix, build)
    ]


@given(
    names=NAMES,
    frequency=st.floats(min_value=1e-3, max_value=E_SERIES_MAX_FREQUENCY_HZ),
    version=st.sampled_from([1, 2]),
    data=st.data(),
)
def test_setup_outputs_round_trip(
    names: tuple[str, ...], frequency: float, version: int, data: st.DataObject
) -> None:
    pair = Pair(version)
    sent = SetupOutputs(frequency if version == 2 else None, names)
    assert pair.to_robot(sent) == [SetupOutputsRequested(sent.frequency, names)]
    answers = tuple(data.draw(st.sampled_from([*sorted(RTDE_TYPES), NOT_FOUND])) for _ in names)
    recipe_id = data.draw(st.integers(0, 255)) if version == 2 else None
    not_found = tuple(n for n, t in zip(names, answers, strict=True) if t == NOT_FOUND)
    assert pair.to_daemon(OutputsSetup(recipe_id, answers)) == [
        OutputsConfigured(recipe_id, answers, not_found)
    ]
    expected = RtdeState.IDLE if not_found else RtdeState.CONFIGURED
    assert states(pair) == both(expected)
    assert pair.daemon.output_recipe == pair.robot.output_recipe


@given(names=NAMES, recipe_id=st.integers(0, 255), data=st.data())
def test_setup_inputs_round_trip(names: tuple[str, ...], recipe_id: int, data: st.DataObject) -> None:
    pair = Pair()
    assert pair.to_robot(SetupInputs(names)) == [SetupInputsRequested(names)]
    answers = tuple(data.draw(st.sampled_from([*sorted(RTDE_TYPES), NOT_FOUND, IN_USE])) for _ in names)
    event = pair.to_daemon(InputsSetup(recipe_id, answers))
    pairs = tuple(zip(names, answers, strict=True))
    assert event == [
        InputsConfigured(
            recipe_id,
            answers,
            tuple(n for n, t in pairs if t == NOT_FOUND),
            tuple(n for n, t in pairs if t == IN_USE),
        )
    ]
    assert pair.daemon.input_recipes == pair.robot.input_recipes


@given(start=st.booleans(), pause=st.booleans())
def test_start_and_pause_round_trip(start: bool, pause: bool) -> None:
    pair = Pair()
    pair.configure(start=False)
    assert pair.exchange(Start(), StartAccept(start)) == StartReply(start)
    assert states(pair) == both(RtdeState.RUNNING if start else RtdeState.CONFIGURED)
    if start:
        assert pair.exchange(Pause(), PauseAccept(pause)) == PauseReply(pause)
        assert states(pair) == both(RtdeState.PAUSED if pause else RtdeState.RUNNING)


@given(
    level=st.integers(0, 255),
    message=TEXT,
    source=TEXT,
    version=st.sampled_from([1, 2]),
)
def test_text_round_trips_both_ways(level: int, message: str, source: str, version: int) -> None:
    if version == 1:
        source = ""
    pair = Pair(version)
    assert pair.to_daemon(Text(level, message, source)) == [TextMessage(level, message, source)]
    assert pair.to_robot(SendText(level, message, source)) == [TextReceived(level, message, source)]


# -- hypothesis: fuzz -----------------------------------------------------------------------------

CONNECTIONS: dict[str, Callable[[], RtdeConnection]] = {
    "daemon-fresh": lambda: RtdeConnection(Side.DAEMON),
    "daemon-v1-fresh": lambda: RtdeConnection(Side.DAEMON, protocol_version=1),
    "daemon-awaiting-outputs": lambda: daemon_after(SetupOutputs(500.0, ("timestamp", "actual_q"))),
    "daemon-awaiting-inputs": lambda: daemon_after(SetupInputs(INPUT_NAMES)),
    "daemon-running": lambda: daemon_after(configure=True),
    "robot-fresh": lambda: RtdeConnection(Side.ROBOT),
    "robot-running": robot_running,
    "robot-v1-running": lambda: robot_running(1),
}


def feed_chunks(conn: RtdeConnection, data: bytes, cuts: list[int]) -> None:
    """Feed ``data`` cut at ``cuts``: only events or RemoteProtocolError, and nothing after an error."""
    bounds = [0, *sorted(c % (len(data) + 1) for c in cuts), len(data)]
    for lo, hi in itertools.pairwise(bounds):
        try:
            events = conn.receive_data(data[lo:hi])
        except RemoteProtocolError:
            assert conn.state is RtdeState.ERROR
            with pytest.raises(RemoteProtocolError):
                conn.receive_data(data[hi:])
            return
        assert all(isinstance(event, get_args(Event)) for event in events)


@settings(max_examples=300)
@given(
    which=st.sampled_from(sorted(CONNECTIONS)),
    data=st.binary(max_size=600),
    cuts=st.lists(st.integers(0, 10_000), max_size=8),
)
def test_fuzz_any_bytes_give_events_or_remote_protocol_error(
    which: str, data: bytes, cuts: list[int]
) -> None:
    feed_chunks(CONNECTIONS[which](), data, cuts)


PACKAGE_CODES = st.sampled_from([*(int(k) for k in PackageType), 0, 82, 255])


@settings(max_examples=300)
@given(
    which=st.sampled_from(sorted(CONNECTIONS)),
    packages=st.lists(st.tuples(PACKAGE_CODES, st.binary(max_size=80)), min_size=1, max_size=6),
    cuts=st.lists(st.integers(0, 10_000), max_size=8),
)
def test_fuzz_well_framed_packages_with_random_payloads(
    which: str, packages: list[tuple[int, bytes]], cuts: list[int]
) -> None:
    """Valid framing gets past the header checks, so every payload decoder meets random bytes."""
    feed_chunks(CONNECTIONS[which](), b"".join(frame(kind, payload) for kind, payload in packages), cuts)


def test_a_trailing_comma_in_a_setup_request_adds_no_name() -> None:
    """ur_rtde ends its name list with a comma; real controllers read it as no extra name."""
    robot = RtdeConnection(Side.ROBOT)
    names = b"timestamp,actual_q,"
    package = struct.pack(">HB", 3 + 8 + len(names), ord("O")) + struct.pack(">d", 500.0) + names
    (event,) = robot.receive_data(package)
    assert isinstance(event, SetupOutputsRequested)
    assert event.names == ("timestamp", "actual_q")


# -- the 500 Hz fast path (receive_output) ----------------------------------------------------------


@pytest.mark.parametrize("version", [1, 2])
def test_receive_output_gives_the_values_of_one_whole_package(version: int) -> None:
    pair = Pair(version)
    pair.configure()
    values = standard_output_values(5)
    pair.robot.send(OutputData(values))
    wire = pair.robot.data_to_send()
    assert pair.daemon.receive_output(wire) == values
    # the slow path sees the same values for the same bytes, and the stream stays in step afterwards
    assert pair.daemon.receive_data(wire) == [DataPackage(1 if version == 2 else None, values)]
    assert pair.daemon.receive_output(wire) == values


def test_receive_output_declines_anything_but_one_whole_package_and_consumes_nothing() -> None:
    pair = Pair()
    pair.configure()
    values = standard_output_values(2)
    pair.robot.send(OutputData(values))
    wire = pair.robot.data_to_send()
    other_recipe = wire[:3] + bytes([9]) + wire[4:]
    wrong_size_field = struct.pack(">H", len(wire) - 1) + wire[2:]
    wrong_kind = wire[:2] + b"M" + wire[3:]
    for chunk in (wire[:-1], wire + wire, wire + wire[:5], other_recipe, wrong_size_field, wrong_kind, b""):
        assert pair.daemon.receive_output(chunk) is None
    # nothing was consumed or buffered: the slow path decodes a split package as before
    assert pair.daemon.receive_data(wire[:100]) == []
    assert pair.daemon.receive_output(wire) is None  # bytes are buffered: only the slow path may go on
    assert pair.daemon.receive_data(wire[100:]) == [DataPackage(1, values)]
    assert pair.daemon.receive_output(wire) == values
    # and the slow path still reports what is wrong with a package the fast path declined
    with pytest.raises(RemoteProtocolError, match="recipe 9"):
        pair.daemon.receive_data(other_recipe)


def test_receive_output_declines_before_the_stream_started() -> None:
    started = Pair()
    started.configure()
    started.robot.send(OutputData(standard_output_values()))
    wire = started.robot.data_to_send()  # a well-formed package for the standard recipe, id 1
    pair = Pair()
    pair.configure(start=False)
    assert pair.daemon.receive_output(wire) is None
    with pytest.raises(RemoteProtocolError, match="before outputs were started"):
        pair.daemon.receive_data(wire)


def test_the_base_codecs_errors_name_rtde() -> None:
    """Data fed after EOF fails naming RTDE, as every error of ours does (the base codec said "codec")."""
    connection = RtdeConnection(Side.DAEMON)
    connection.receive_eof()
    with pytest.raises(LocalProtocolError, match=r"^rtde: data fed after receive_eof") as failed:
        connection.receive_data(b"\x00\x03V")
    assert failed.value.protocol == "rtde"
