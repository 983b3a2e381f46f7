"""Ssc32Link through the real pyserial on a pseudo-terminal: what reaches the wire, line by line."""

from __future__ import annotations

import errno
import os
import termios
import threading
from collections.abc import Iterator

import pytest
import serial
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.backends.servo.pty_port import PtyPort, apply_line, parse_line
from urdaemon.backends.servo.serial_link import Ssc32Link
from urdaemon.cell.servo import SerialOutput

CHANNELS = (0, 5, 31)


@pytest.fixture
def pty() -> Iterator[PtyPort]:
    port = PtyPort()
    try:
        yield port
    finally:
        port.close()


def link_on(
    port: PtyPort, *, move_time_ms: int | None = None, baud: int = 115200, ready_wait_s: float = 0.0
) -> Ssc32Link:
    """A link on the pty; by default it does not wait for the board's answer to ``VER`` (the tests
    below of that wait answer from a thread)."""
    output = SerialOutput(kind="serial", port=port.path, baud=baud, move_time_ms=move_time_ms)
    return Ssc32Link(output, CHANNELS, ready_wait_s=ready_wait_s)


def test_a_frame_is_one_command_group_of_whole_microseconds(pty: PtyPort) -> None:
    link = link_on(pty)
    link.open()
    try:
        assert link.write([1500.49, 1600.51, 700.0]) == 1
        assert pty.line() == b"#0P1500#5P1601#31P700"
    finally:
        link.close()


def test_only_the_channels_that_changed_are_sent(pty: PtyPort) -> None:
    link = link_on(pty)
    link.open()
    try:
        assert link.write([1500.0, 1600.0, 700.0]) == 1
        assert link.write([1500.0, 1600.0, 700.0]) == 0, "nothing changed: no line"
        assert link.write([1500.3, 1599.8, 700.0]) == 0, "the same whole microseconds: no line"
        assert link.write([1500.0, 1650.0, 700.0]) == 1
        assert link.write([1400.0, 1650.0, 800.0]) == 1
        # the lines in the order they came: nothing was sent between the first and the second
        assert pty.lines(3) == [b"#0P1500#5P1600#31P700", b"#5P1650", b"#0P1400#31P800"]
    finally:
        link.close()


def test_move_time_ends_every_group(pty: PtyPort) -> None:
    link = link_on(pty, move_time_ms=20)
    link.open()
    try:
        link.write([1500.0, 1600.0, 700.0])
        link.write([1500.0, 1610.0, 700.0])
        assert pty.lines(2) == [b"#0P1500#5P1600#31P700T20", b"#5P1610T20"]
    finally:
        link.close()


def test_off_stops_the_pulses_of_every_configured_channel(pty: PtyPort) -> None:
    link = link_on(pty, move_time_ms=20)
    link.open()
    try:
        link.write([1500.0, 1600.0, 700.0])
        link.off()
        # after off the board holds P0 everywhere: the same frame again is a change on every channel
        assert link.write([1500.0, 1600.0, 700.0]) == 1
        first, off, again = pty.lines(3)
        assert off == b"#0P0#5P0#31P0", "off is no move: no T"
        assert again == first
    finally:
        link.close()


def test_after_close_and_open_every_channel_is_sent_again(pty: PtyPort) -> None:
    link = link_on(pty)
    link.open()
    try:
        link.write([1500.0, 1600.0, 700.0])
        link.close()
        link.open()
        link.write([1500.0, 1600.0, 700.0])
        link.open()  # open on an open port starts over too
        link.write([1500.0, 1600.0, 700.0])
        assert pty.lines(3) == [b"#0P1500#5P1600#31P700"] * 3
    finally:
        link.close()


def test_a_port_not_open_refuses_to_write_with_an_os_error(pty: PtyPort) -> None:
    link = link_on(pty)
    with pytest.raises(OSError, match="not open"):
        link.write([1500.0, 1600.0, 700.0])
    link.off()  # nothing to stop, nothing raised
    link.close()


def test_the_port_is_opened_8n1_at_the_baud_rate_without_flow_control(pty: PtyPort) -> None:
    # the terminal starts out as something else entirely: 7 bits, even parity, 2 stop bits, RTS/CTS
    attributes = pty.attributes()
    attributes[2] = (attributes[2] & ~termios.CSIZE) | termios.CS7 | termios.PARENB | termios.CSTOPB
    attributes[2] |= termios.CRTSCTS
    attributes[0] |= termios.IXON | termios.IXOFF
    attributes[4] = attributes[5] = termios.B9600
    pty.set_attributes(attributes)
    assert pty.attributes()[4] == termios.B9600
    link = link_on(pty, baud=57600)
    link.open()
    try:
        iflag, _, cflag, _, ispeed, ospeed, _ = pty.attributes()
        assert (ispeed, ospeed) == (termios.B57600, termios.B57600)
        assert cflag & termios.CSIZE == termios.CS8
        assert not cflag & (termios.PARENB | termios.CSTOPB | termios.CRTSCTS)
        assert not iflag & (termios.IXON | termios.IXOFF)
    finally:
        link.close()


def test_an_unplugged_port_fails_the_next_write_and_cannot_be_opened(pty: PtyPort) -> None:
    link = link_on(pty)
    link.open()
    try:
        link.write([1500.0, 1600.0, 700.0])
        assert pty.line() == b"#0P1500#5P1600#31P700"
        pty.unplug()
        with pytest.raises(serial.SerialException) as raised:
            link.write([1510.0, 1600.0, 700.0])
        assert isinstance(raised.value, OSError), "the writer catches OSError"
        assert "Input/output error" in str(raised.value)
        link.close()  # the port is gone: closing still works
        with pytest.raises(OSError, match="could not open port") as reopening:
            link.open()
        assert reopening.value.errno == errno.ENOENT
        assert pty.path in str(reopening.value)
    finally:
        link.close()


_PULSE = st.builds(
    lambda whole, fraction: whole + fraction,
    st.integers(500, 2500),
    st.sampled_from([0.0, 0.2, 0.49, 0.51, 0.8]),  # never a tie: rounding has one answer
)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(frames=st.lists(st.tuples(_PULSE, _PULSE, _PULSE), min_size=1, max_size=8))
def test_the_board_always_ends_up_at_the_last_frame(frames: list[tuple[float, float, float]]) -> None:
    pty = PtyPort()
    link = link_on(pty)
    try:
        link.open()
        board: dict[int, int] = {}
        for frame in frames:
            wanted = {c: round(p) for c, p in zip(CHANNELS, frame, strict=True)}
            changed = {c: us for c, us in wanted.items() if board.get(c) != us}
            assert link.write(frame) == (1 if changed else 0)
            if changed:
                line = pty.line()
                assert parse_line(line) == (changed, None), "exactly the channels that changed"
                board = apply_line(board, line)
            assert board == wanted
    finally:
        link.close()
        pty.close()


def test_open_waits_for_the_boards_answer_before_the_first_frame(pty: PtyPort) -> None:
    link = link_on(pty, ready_wait_s=30.0)
    opening = threading.Thread(target=link.open)
    opening.start()
    try:
        pty.answer()  # the board answers the first VER: open returns at once, not after 30 s
        opening.join(10.0)
        assert not opening.is_alive()
        assert link.answered == "SSC32-V2.50USB"
        assert link.write([1500.0, 1600.0, 700.0]) == 1
        assert pty.line() == b"#0P1500#5P1600#31P700"
    finally:
        opening.join(10.0)
        link.close()


def test_a_board_that_never_answers_is_driven_after_the_wait() -> None:
    pty = PtyPort(answers=False)
    try:
        link = link_on(pty, ready_wait_s=0.3)
        link.open()  # bounded: 0.3 s of VER every 0.5 s, no answer
        assert link.answered == ""
        assert link.write([1500.0, 1600.0, 700.0]) == 1
        assert pty.line() == b"#0P1500#5P1600#31P700"
        assert pty.queries >= 1
        link.close()
    finally:
        pty.close()


def test_a_board_that_speaks_unasked_restarted_and_check_says_so(pty: PtyPort) -> None:
    link = link_on(pty)
    link.open()
    try:
        link.check()  # quiet: still there
        assert pty.master is not None
        os.write(pty.master, b"urdaemon-servo-bridge 1.0 boards=2\r\n")  # greeted after a brown-out
        with pytest.raises(OSError, match=r"restarted .*urdaemon-servo-bridge 1\.0"):
            link.check()
    finally:
        link.close()


def test_check_fails_on_an_unplugged_port(pty: PtyPort) -> None:
    link = link_on(pty)
    link.open()
    pty.unplug()
    with pytest.raises(OSError, match=r"Input/output error|disconnected"):
        link.check()
    link.close()
