"""The codec base (protocols/_codec.py): the feed loop, the final error state and the one send path."""

from __future__ import annotations

import pytest

from tests.protocols.feeding import feed_all_ways
from urdaemon.errors import LocalProtocolError, RemoteProtocolError
from urdaemon.protocols._buffer import Side
from urdaemon.protocols._codec import Codec, CodecState
from urdaemon.protocols.primary import Script
from urdaemon.protocols.realtime import RealtimeConnection, RealtimeState

LIMIT = 8


class Lines(Codec[str, str]):
    """A toy codec: newline-terminated lines of at most LIMIT - 1 bytes; "bad" is a protocol error."""

    PROTOCOL = "lines"

    def __init__(self) -> None:
        super().__init__(Side.DAEMON, LIMIT)

    def _parse(self, events: list[str]) -> None:
        while (line := self._buffer.take_line(LIMIT - 1)) is not None:
            if line == b"bad\n":
                raise self._remote("bad line", self._consumed)
            self._consumed += len(line)
            events.append(line[:-1].decode())

    def _encode(self, message: str) -> None:
        if "\n" in message:
            raise self._local("a line holds no newline")
        self._queue(message.encode() + b"\n")


def test_many_short_units_in_one_chunk_pass_the_limit_in_slices() -> None:
    data = b"".join(f"l{i}\n".encode() for i in range(20))  # 80+ bytes, ten times the limit
    assert feed_all_ways(Lines, data) == [f"l{i}" for i in range(20)]


def test_an_over_long_unit_fails_and_every_later_call_raises() -> None:
    conn = Lines()
    with pytest.raises(RemoteProtocolError, match="lines: line longer than 7 bytes"):
        conn.receive_data(b"abcdefghijk\n")
    assert conn._stream is CodecState.ERROR
    with pytest.raises(RemoteProtocolError, match="already failed"):
        conn.receive_data(b"ok\n")
    with pytest.raises(LocalProtocolError, match="already failed"):
        conn.send("ok")


def test_a_bad_unit_is_reported_at_its_stream_offset() -> None:
    conn = Lines()
    with pytest.raises(RemoteProtocolError) as err:
        conn.receive_data(b"one\ntwo\nbad\n")
    assert err.value.offset == 8


def test_send_queues_into_one_buffer_that_data_to_send_clears() -> None:
    conn = Lines()
    conn.send("a")
    conn.send("b")
    with pytest.raises(LocalProtocolError, match="no newline"):
        conn.send("c\n")
    assert conn.data_to_send() == b"a\nb\n"
    assert conn.data_to_send() == b""


def test_realtime_refuses_to_send_after_its_peer_broke_the_stream() -> None:
    """Old code: RealtimeConnection.send ignored the error state and queued a Script after a bad
    message size (the module promise says every later call raises)."""
    daemon = RealtimeConnection(Side.DAEMON)
    with pytest.raises(RemoteProtocolError, match="message size"):
        daemon.receive_data(b"\x00\x00\x00\x05" + b"\x00" * 8)
    with pytest.raises(LocalProtocolError, match="already failed"):
        daemon.send(Script("textmsg(1)"))


def test_realtime_robot_side_hands_script_text_through_the_buffer() -> None:
    robot = RealtimeConnection(Side.ROBOT)
    script = b"def prog():\n  textmsg(1)\nend\n" * 300  # larger than the realtime buffer's limit
    events = robot.receive_data(script)
    assert len(events) == 300
    robot.send(RealtimeState())
    assert len(robot.data_to_send()) == 1196
