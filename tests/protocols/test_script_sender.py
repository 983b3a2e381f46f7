"""Script sender codec (docs/protocols.md §4.3): the request, the program answer, both sides, fuzz, a pair."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.protocols.feeding import feed_all_ways
from urdaemon.errors import LocalProtocolError, RemoteProtocolError
from urdaemon.protocols import Side
from urdaemon.protocols.script_sender import (
    MAX_PROGRAM_BYTES,
    MAX_REQUEST_LINE_BYTES,
    REQUEST_LINE,
    Program,
    ProgramIncomplete,
    ProgramReceived,
    ProgramRequested,
    RequestProgram,
    ScriptSenderConnection,
    ScriptSenderEvent,
    UnknownRequest,
)

SCRIPT = "# HEADER_BEGIN\nsteptime = get_steptime()\n# HEADER_END\n# NODE_CONTROL_LOOP_BEGINS\nsync()\n"


def _daemon() -> ScriptSenderConnection:
    return ScriptSenderConnection(Side.DAEMON)


def _urcap() -> ScriptSenderConnection:
    conn = ScriptSenderConnection(Side.ROBOT)
    conn.send(RequestProgram())
    conn.data_to_send()
    return conn


def _answered(text: str) -> bytes:
    conn = _daemon()
    conn.receive_data(REQUEST_LINE)
    conn.send(Program(text))
    return conn.data_to_send()


def _robot_feed(data: bytes, cuts: list[int]) -> list[ScriptSenderEvent]:
    conn = _urcap()
    for start, end in zip([0, *cuts], [*cuts, len(data)], strict=True):
        assert conn.receive_data(data[start:end]) == []
    return conn.receive_eof()


# -- the request (§4.3 step 1) ---------------------------------------------------------------------------


def test_the_request_is_exactly_request_program_newline() -> None:
    assert REQUEST_LINE == b"request_program\n"
    conn = ScriptSenderConnection(Side.ROBOT)
    conn.send(RequestProgram())
    assert conn.data_to_send() == b"request_program\n"


def test_the_daemon_recognises_the_request_every_way() -> None:
    assert feed_all_ways(_daemon, b"request_program\n") == [ProgramRequested()]


@pytest.mark.parametrize(
    "line",
    [b"request_program ", b"REQUEST_PROGRAM", b"request_program\r", b"", b"hello", b"\xff\xfe"],
)
def test_other_lines_are_unknown_requests(line: bytes) -> None:
    assert feed_all_ways(_daemon, line + b"\n") == [UnknownRequest(line)]


def test_several_lines_in_one_chunk() -> None:
    wire = b"hello\nrequest_program\n\nrequest_program\n"
    assert feed_all_ways(_daemon, wire) == [
        UnknownRequest(b"hello"),
        ProgramRequested(),
        UnknownRequest(b""),
        ProgramRequested(),
    ]


def test_many_short_lines_may_exceed_the_line_cap_in_total() -> None:
    wire = b"x\n" * MAX_REQUEST_LINE_BYTES * 3
    assert _daemon().receive_data(wire) == [UnknownRequest(b"x")] * MAX_REQUEST_LINE_BYTES * 3


def test_a_line_of_exactly_the_cap_is_accepted() -> None:
    line = b"a" * MAX_REQUEST_LINE_BYTES
    assert feed_all_ways(_daemon, line + b"\n") == [UnknownRequest(line)]


def test_an_overlong_line_is_a_remote_protocol_error() -> None:
    conn = _daemon()
    with pytest.raises(RemoteProtocolError) as info:
        conn.receive_data(b"a" * (MAX_REQUEST_LINE_BYTES + 1))
    assert info.value.protocol == "script_sender"
    with pytest.raises(RemoteProtocolError):
        conn.receive_data(REQUEST_LINE)
    with pytest.raises(LocalProtocolError):
        conn.send(Program(SCRIPT))


def test_an_overlong_line_fed_slowly_fails_too() -> None:
    conn = _daemon()
    with pytest.raises(RemoteProtocolError):  # noqa: PT012 - the error comes at the byte over the cap
        for _ in range(MAX_REQUEST_LINE_BYTES + 2):
            conn.receive_data(b"b")


def test_an_unterminated_request_at_eof_is_not_a_request() -> None:
    conn = _daemon()
    assert conn.receive_data(b"request_program") == []
    assert conn.receive_eof() == [UnknownRequest(b"request_program")]
    with pytest.raises(LocalProtocolError):
        conn.receive_data(b"\n")


def test_a_clean_eof_on_the_daemon_side_gives_nothing() -> None:
    conn = _daemon()
    assert conn.receive_data(REQUEST_LINE) == [ProgramRequested()]
    assert conn.close() == []


# -- the answer (§4.3 step 2) ----------------------------------------------------------------------------


def test_the_program_is_the_text_plus_one_newline() -> None:
    assert _answered(SCRIPT) == SCRIPT.encode() + b"\n"
    assert _answered("textmsg(1)") == b"textmsg(1)\n"


def test_the_program_is_utf8() -> None:
    assert _answered('textmsg("Grüße")') == 'textmsg("Grüße")\n'.encode()


def test_a_program_answers_one_request_each() -> None:
    conn = _daemon()
    with pytest.raises(LocalProtocolError):
        conn.send(Program(SCRIPT))  # nobody asked yet
    conn.receive_data(REQUEST_LINE + REQUEST_LINE)
    conn.send(Program(SCRIPT))
    conn.send(Program(SCRIPT))
    with pytest.raises(LocalProtocolError):
        conn.send(Program(SCRIPT))
    assert conn.data_to_send() == (SCRIPT.encode() + b"\n") * 2


@pytest.mark.parametrize("text", ["", "\ud800", b"bytes"])
def test_bad_programs_are_local_protocol_errors(text: str) -> None:
    conn = _daemon()
    conn.receive_data(REQUEST_LINE)
    with pytest.raises(LocalProtocolError):
        conn.send(Program(text))
    conn.send(Program(SCRIPT))  # the request is still pending
    assert conn.data_to_send() == SCRIPT.encode() + b"\n"


def test_each_side_sends_only_its_own_messages() -> None:
    with pytest.raises(LocalProtocolError):
        _daemon().send(RequestProgram())
    robot = ScriptSenderConnection(Side.ROBOT)
    with pytest.raises(LocalProtocolError):
        robot.send(Program(SCRIPT))
    with pytest.raises(LocalProtocolError):
        robot.send(ProgramRequested())  # type: ignore[arg-type]


# -- the URCap side (§4.3 step 3) ------------------------------------------------------------------------


def test_the_urcap_requests_once() -> None:
    conn = _urcap()
    with pytest.raises(LocalProtocolError):
        conn.send(RequestProgram())


def test_the_urcap_gets_the_text_on_eof_or_when_it_stops_reading() -> None:
    wire = SCRIPT.encode() + b"\n"
    assert _robot_feed(wire, [10, 40]) == [ProgramReceived(SCRIPT)]
    conn = _urcap()
    conn.receive_data(wire)
    assert conn.close() == [ProgramReceived(SCRIPT)]
    with pytest.raises(LocalProtocolError):
        conn.receive_data(b"more")
    with pytest.raises(LocalProtocolError):
        conn.receive_eof()


def test_only_the_senders_newline_is_stripped() -> None:
    assert _robot_feed(b"a\n\n", []) == [ProgramReceived("a\n")]


@pytest.mark.parametrize("data", [b"", b"def x():\n  sync()", b"partial"])
def test_an_unterminated_or_missing_program_is_incomplete(data: bytes) -> None:
    assert _robot_feed(data, []) == [ProgramIncomplete(data)]


def test_data_before_the_request_is_a_remote_protocol_error() -> None:
    conn = ScriptSenderConnection(Side.ROBOT)
    with pytest.raises(RemoteProtocolError):
        conn.receive_data(b"x")
    with pytest.raises(RemoteProtocolError):
        conn.receive_eof()


def test_a_program_that_is_not_utf8_is_a_remote_protocol_error() -> None:
    conn = _urcap()
    conn.receive_data(b"ok\n\xff\n")
    with pytest.raises(RemoteProtocolError) as info:
        conn.receive_eof()
    assert info.value.offset == 3


def test_an_oversized_program_is_a_remote_protocol_error_before_buffering() -> None:
    conn = _urcap()
    conn.receive_data(bytes(MAX_PROGRAM_BYTES - 1))
    with pytest.raises(RemoteProtocolError):
        conn.receive_data(b"\n\n")


# -- hypothesis: round trips and fuzz -------------------------------------------------------------------

texts = st.text(st.characters(codec="utf-8"), min_size=1, max_size=300)


@given(texts, st.lists(st.integers(0, 1300), max_size=6))
@settings(max_examples=300, deadline=None)
def test_any_program_round_trips_daemon_to_urcap(text: str, cuts: list[int]) -> None:
    wire = _answered(text)
    assert _robot_feed(wire, sorted(c for c in cuts if c <= len(wire))) == [ProgramReceived(text)]


@given(st.lists(st.binary(max_size=40).filter(lambda b: b"\n" not in b), max_size=8), st.data())
@settings(max_examples=200, deadline=None)
def test_any_request_lines_round_trip(lines: list[bytes], data: st.DataObject) -> None:
    wire = b"".join(line + b"\n" for line in lines)
    cuts = sorted(data.draw(st.lists(st.integers(0, len(wire)), max_size=5)))
    conn = _daemon()
    events: list[ScriptSenderEvent] = []
    for start, end in zip([0, *cuts], [*cuts, len(wire)], strict=True):
        events += conn.receive_data(wire[start:end])
    expected = [ProgramRequested() if line == b"request_program" else UnknownRequest(line) for line in lines]
    assert events == expected


@given(st.binary(max_size=800), st.lists(st.integers(0, 800), max_size=6))
@settings(max_examples=300, deadline=None)
def test_any_bytes_give_events_or_a_remote_protocol_error(blob: bytes, cuts: list[int]) -> None:
    for make in (_daemon, _urcap, lambda: ScriptSenderConnection(Side.ROBOT)):
        conn = make()
        failure: RemoteProtocolError | None = None
        try:
            for start, end in zip([0, *sorted(cuts)], [*sorted(cuts), len(blob)], strict=True):
                for event in conn.receive_data(blob[start:end]):
                    assert isinstance(event, ProgramRequested | UnknownRequest)
            for event in conn.receive_eof():
                assert isinstance(event, UnknownRequest | ProgramReceived | ProgramIncomplete)
        except RemoteProtocolError as err:
            failure = err
        assert failure is None or failure.protocol == "script_sender"


# -- the whole exchange, both parties in memory ----------------------------------------------------------


def test_pair_the_urcap_fetches_the_script() -> None:
    daemon, urcap = _daemon(), ScriptSenderConnection(Side.ROBOT)
    urcap.send(RequestProgram())
    events = []
    for byte in urcap.data_to_send():  # the request may arrive in pieces
        events += daemon.receive_data(bytes([byte]))
    assert events == [ProgramRequested()]
    daemon.send(Program(SCRIPT))
    wire = daemon.data_to_send()
    assert urcap.receive_data(wire[:7]) == []
    assert urcap.receive_data(wire[7:]) == []
    assert urcap.close() == [ProgramReceived(SCRIPT)]  # the URCap stops reading and closes
    assert daemon.receive_eof() == []
