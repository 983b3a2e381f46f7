"""The socket_* builtins over real TCP on 127.0.0.0/8, driven cycle by cycle like the controller does.

Each builtin is called as the compiled program calls it (host first, then every argument); a blocking one
is a generator resumed once per controller cycle, with the arm's clock advanced between cycles.
"""

from __future__ import annotations

import contextlib
import math
import select
import socket
import struct
from collections.abc import Generator, Iterator
from typing import Any

import pytest

from tests.helpers import fake_address, free_tcp_port
from urdaemon.description.urmodels import load_ur_model
from urdaemon.fakeur.fake_arm import FakeArm
from urdaemon.fakeur.urscript import compile_program
from urdaemon.fakeur.urscript import lib_sockets as ls
from urdaemon.fakeur.urscript.runtime import ScriptRuntimeError, UrList, UrPose
from urdaemon.fakeur.urscript.script_host import ScriptHost

DT = 0.002
WAIT_S = 5.0
"""Upper bound for a loopback event (data or a connection) to show up: never reached when things work."""


def _host() -> ScriptHost:
    model = load_ur_model("ur10e")
    return ScriptHost(FakeArm(model, model.dh), step_time=DT, local_address=fake_address())


def _drive(host: ScriptHost, call: Any, max_cycles: int = 5000) -> tuple[Any, int]:
    """Run a builtin's call to its end: (its value, cycles it waited). A plain value is returned as is."""
    if not isinstance(call, Generator):
        return call, 0
    cycles = 0
    while True:
        try:
            next(call)
        except StopIteration as stop:
            return stop.value, cycles
        cycles += 1
        assert cycles <= max_cycles, "the builtin never finished"
        host.arm.step(DT)


def _cycle(host: ScriptHost, call: Generator[None, None, Any]) -> tuple[bool, Any]:
    """Resume a waiting builtin for one cycle: (finished, value)."""
    host.arm.step(DT)
    try:
        next(call)
    except StopIteration as stop:
        return True, stop.value
    return False, None


@pytest.fixture
def server() -> Iterator[socket.socket]:
    listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    listener.bind(("127.0.0.1", 0))
    listener.listen(8)
    listener.settimeout(WAIT_S)
    with listener:
        yield listener


def _open(host: ScriptHost, listener: socket.socket, name: str = "socket_0") -> socket.socket:
    """socket_open to ``listener``; the server side of the connection."""
    port = listener.getsockname()[1]
    opened, _ = _drive(host, ls.socket_open(host, "127.0.0.1", port, name))
    assert opened is True
    peer, _ = listener.accept()
    peer.settimeout(WAIT_S)
    return peer


def _arrived(host: ScriptHost, name: str = "socket_0") -> None:
    """Wait (bounded) until the script's socket has data or an end to read: an event, not a sleep."""
    entry = host.sockets.get(name)
    assert entry is not None
    assert entry.sock is not None
    readable, _, _ = select.select([entry.sock], [], [], WAIT_S)
    assert readable, "nothing arrived"


def _frame(*values: int) -> bytes:
    return struct.pack(f">{len(values)}i", *values)


# ---- connecting ------------------------------------------------------------------------------------------


def test_open_connects_from_the_robots_own_address(server: socket.socket) -> None:
    host = _host()
    port = server.getsockname()[1]
    opened, _ = _drive(host, ls.socket_open(host, "127.0.0.1", port, "reverse_socket"))
    peer, (address, _) = server.accept()
    peer.close()
    assert opened is True
    assert address == host.local_address


def test_open_refused_returns_false_at_once() -> None:
    host = _host()
    opened, cycles = _drive(host, ls.socket_open(host, "127.0.0.1", free_tcp_port(), "socket_0"))
    assert opened is False
    assert cycles <= 2
    assert host.sockets.get("socket_0") is None


def test_open_gives_up_after_two_seconds_of_controller_time() -> None:
    """A peer that never answers the handshake: a listener whose accept queue is full drops the SYN."""
    with contextlib.ExitStack() as stack:
        listener = stack.enter_context(socket.socket(socket.AF_INET, socket.SOCK_STREAM))
        listener.bind(("127.0.0.1", 0))
        listener.listen(0)
        target = listener.getsockname()
        fillers = []
        for _ in range(4):  # fill the accept queue (backlog 0 keeps one or two, depending on the kernel)
            filler = stack.enter_context(socket.socket(socket.AF_INET, socket.SOCK_STREAM))
            filler.setblocking(False)
            filler.connect_ex(target)
            fillers.append(filler)
        host = _host()
        opened, cycles = _drive(host, ls.socket_open(host, *target, "socket_0"), max_cycles=2000)
    assert opened is False
    assert cycles == pytest.approx(ls.CONNECT_TIMEOUT_S / DT, abs=2)


def test_a_thread_killed_while_connecting_leaves_no_socket() -> None:
    """The scheduler drops a killed thread's generator: the half-open socket is closed with it."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as listener:
        listener.bind(("127.0.0.1", 0))
        listener.listen(0)
        target = listener.getsockname()
        fillers = [socket.socket(socket.AF_INET, socket.SOCK_STREAM) for _ in range(4)]
        for filler in fillers:
            filler.setblocking(False)
            filler.connect_ex(target)
        host = _host()
        call = ls.socket_open(host, *target, "socket_0")
        next(call)
        frame = call.gi_frame
        assert frame is not None
        half_open = frame.f_locals["sock"]
        call.close()
        assert half_open.fileno() == -1
        assert host.sockets.get("socket_0") is None
        for filler in fillers:
            filler.close()


def test_an_open_name_stays_connected_on_a_second_open(server: socket.socket) -> None:
    host = _host()
    peer = _open(host, server)
    first = host.sockets.get("socket_0")
    opened, _ = _drive(host, ls.socket_open(host, "127.0.0.1", server.getsockname()[1], "socket_0"))
    assert opened is True
    assert host.sockets.get("socket_0") is first
    peer.close()


# ---- binary integers -------------------------------------------------------------------------------------


def test_read_binary_integer_returns_count_then_values(server: socket.socket) -> None:
    host = _host()
    peer = _open(host, server, "reverse_socket")
    peer.sendall(_frame(1, -2, 2**31 - 1))
    _arrived(host, "reverse_socket")
    value, cycles = _drive(host, ls.socket_read_binary_integer(host, 3, "reverse_socket", 2.0))
    assert value == [3, 1, -2, 2**31 - 1]
    assert isinstance(value, UrList)
    assert cycles == 0


def test_partial_frame_stays_buffered_through_a_timeout(server: socket.socket) -> None:
    """Half a frame, then the read's timeout (5 cycles): count 0; the rest completes the same frame."""
    host = _host()
    peer = _open(host, server)
    whole = _frame(10, 20, 30, 40)
    peer.sendall(whole[:6])
    _arrived(host)
    value, cycles = _drive(host, ls.socket_read_binary_integer(host, 4, "socket_0", 5 * DT))
    assert value == [0, -1, -1, -1, -1]
    assert cycles == 5
    peer.sendall(whole[6:])
    _arrived(host)
    value, _ = _drive(host, ls.socket_read_binary_integer(host, 4, "socket_0", 5 * DT))
    assert value == [4, 10, 20, 30, 40]


def test_timeout_is_counted_in_controller_cycles(server: socket.socket) -> None:
    host = _host()
    peer = _open(host, server)
    _, cycles = _drive(host, ls.socket_read_binary_integer(host, 1, "socket_0", 0.5))
    assert cycles == round(0.5 / DT)
    _, cycles = _drive(host, ls.socket_read_binary_integer(host, 1, "socket_0", DT))
    assert cycles == 1
    peer.close()


def test_timeout_zero_waits_until_the_frame_comes(server: socket.socket) -> None:
    host = _host()
    peer = _open(host, server)
    call = ls.socket_read_binary_integer(host, 2, "socket_0", 0)
    next(call)
    for _ in range(3000):  # 6 s of controller time, far past any default timeout
        finished, _ = _cycle(host, call)
        assert not finished
    peer.sendall(_frame(7, 8))
    _arrived(host)
    finished, value = _cycle(host, call)
    assert finished
    assert value == [2, 7, 8]


def test_closed_peer_fails_reads_at_once(server: socket.socket) -> None:
    host = _host()
    peer = _open(host, server)
    peer.sendall(_frame(5))
    peer.close()
    _arrived(host)
    value, _ = _drive(host, ls.socket_read_binary_integer(host, 1, "socket_0", 0))
    assert value == [1, 5], "what came before the close is still read"
    value, cycles = _drive(host, ls.socket_read_binary_integer(host, 1, "socket_0", 0))
    assert value == [0, -1]
    assert cycles == 0


def test_peer_closing_while_a_read_waits_ends_it(server: socket.socket) -> None:
    host = _host()
    peer = _open(host, server)
    call = ls.socket_read_binary_integer(host, 8, "socket_0", 0)
    next(call)
    peer.close()
    _arrived(host)
    finished, value = _cycle(host, call)
    assert finished
    assert value[0] == 0


def test_unknown_socket_fails_reads_and_sends() -> None:
    host = _host()
    value, cycles = _drive(host, ls.socket_read_binary_integer(host, 2, "nothing", 0))
    assert value == [0, -1, -1]
    assert cycles == 0
    assert ls.socket_send_int(host, 1, "nothing") is False


def test_flooding_peer_only_fills_the_kernel_buffer(server: socket.socket) -> None:
    """A peer writes frames as fast as it can: every read completes in its cycle, the script's socket keeps
    no more than one frame, and the peer is pushed back by TCP flow control (its sends would block)."""
    host = _host()
    peer = _open(host, server)
    peer.setblocking(False)
    frame = _frame(*range(8))
    written = 0
    with contextlib.suppress(BlockingIOError):
        for _ in range(1_000_000):
            written += peer.send(frame * 256)
    assert written < 1_000_000 * len(frame) * 256, "the peer was never pushed back"
    entry = host.sockets.get("socket_0")
    for _ in range(500):
        value, cycles = _drive(host, ls.socket_read_binary_integer(host, 8, "socket_0", DT))
        assert cycles == 0
        assert value == [8, *range(8)]
        assert len(entry.buffer) == 0
    peer.close()


# ---- many sockets, closing -------------------------------------------------------------------------------


def test_many_named_sockets_and_close_at_program_end(server: socket.socket) -> None:
    host = _host()
    peers = {name: _open(host, server, name) for name in ("a", "b", "c")}
    for index, (name, peer) in enumerate(peers.items()):
        peer.sendall(_frame(index))
        _arrived(host, name)
    for index, name in enumerate(peers):
        assert _drive(host, ls.socket_read_binary_integer(host, 1, name, 1.0))[0] == [1, index]
    ls.socket_close(host, "a")
    assert peers["a"].recv(16) == b""
    host.close()
    host.close()  # idempotent
    for peer in peers.values():
        assert peer.recv(16) == b""
        peer.close()
    assert _drive(host, ls.socket_read_binary_integer(host, 1, "b", 0))[0] == [0, -1]


# ---- sending ---------------------------------------------------------------------------------------------


def test_sends_reach_the_peer_byte_for_byte(server: socket.socket) -> None:
    host = _host()
    peer = _open(host, server)
    assert ls.socket_send_int(host, -3, "socket_0") is True
    assert ls.socket_send_byte(host, 255, "socket_0") is True
    assert ls.socket_send_string(host, "hi", "socket_0") is True
    assert ls.socket_send_line(host, "power on", "socket_0") is True
    ls.socket_set_var(host, "X", 12, "socket_0")
    expected = struct.pack(">i", -3) + b"\xff" + b"hi" + b"power on\n" + b"SET X 12\n"
    got = b""
    while len(got) < len(expected):
        chunk = peer.recv(64)
        assert chunk
        got += chunk
    assert got == expected
    peer.close()


def test_send_string_prints_other_values_as_the_controller_does(server: socket.socket) -> None:
    """A common robot program sends its pose with socket_send_string(get_actual_tcp_pose())."""
    host = _host()
    peer = _open(host, server)
    assert ls.socket_send_string(host, UrPose([0.1, 0, 0.5, 0, 3.14159, 0]), "socket_0") is True
    assert ls.socket_send_line(host, 7, "socket_0") is True
    expected = b"p[0.1, 0, 0.5, 0, 3.14159, 0]7\n"
    got = b""
    while len(got) < len(expected):
        chunk = peer.recv(64)
        assert chunk
        got += chunk
    assert got == expected
    peer.close()


def test_send_to_a_broken_peer_returns_false_eventually(server: socket.socket) -> None:
    host = _host()
    peer = _open(host, server)
    peer.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
    peer.close()  # reset
    _arrived(host)
    results = [ls.socket_send_int(host, 1, "socket_0") for _ in range(5)]
    assert results[-1] is False


@pytest.mark.parametrize("value", [2**31, 1.5, "1", True])
def test_send_int_refuses_what_is_not_an_int32(server: socket.socket, value: Any) -> None:
    host = _host()
    peer = _open(host, server)
    with pytest.raises(ScriptRuntimeError, match="socket_send_int"):
        ls.socket_send_int(host, value, "socket_0")
    peer.close()


# ---- text ------------------------------------------------------------------------------------------------


def test_read_line_strips_the_line_end_and_keeps_the_rest(server: socket.socket) -> None:
    host = _host()
    peer = _open(host, server)
    peer.sendall(b"first\r\nsecond\nthi")
    _arrived(host)
    assert _drive(host, ls.socket_read_line(host, "socket_0", 1.0))[0] == "first"
    assert _drive(host, ls.socket_read_line(host, "socket_0", 1.0))[0] == "second"
    value, cycles = _drive(host, ls.socket_read_line(host, "socket_0", 10 * DT))
    assert (value, cycles) == ("", 10)
    peer.sendall(b"rd\n")
    _arrived(host)
    assert _drive(host, ls.socket_read_line(host, "socket_0", 1.0))[0] == "third"
    peer.close()


def test_read_ascii_float(server: socket.socket) -> None:
    host = _host()
    peer = _open(host, server)
    peer.sendall(b"junk(1.5, -2, 3e1)(1, 2)")
    _arrived(host)
    assert _drive(host, ls.socket_read_ascii_float(host, 3, "socket_0", 1.0))[0] == [3, 1.5, -2.0, 30.0]
    wrong, _ = _drive(host, ls.socket_read_ascii_float(host, 3, "socket_0", 1.0))
    assert wrong[0] == 0
    assert all(math.isnan(v) for v in wrong[1:])
    assert len(wrong) == 4
    peer.close()


def test_read_string_with_prefix_suffix_and_escapes(server: socket.socket) -> None:
    host = _host()
    peer = _open(host, server)
    peer.sendall(b"noise<a\\tb>tail")
    _arrived(host)
    text, _ = _drive(host, ls.socket_read_string(host, "socket_0", "<", ">", True, 1.0))
    assert text == "a\tb"
    rest, _ = _drive(host, ls.socket_read_string(host, "socket_0", "", "", False, 1.0))
    assert rest == "tail"
    nothing, cycles = _drive(host, ls.socket_read_string(host, "socket_0", "", "", False, 4 * DT))
    assert (nothing, cycles) == ("", 4)
    peer.close()


def test_read_byte_list(server: socket.socket) -> None:
    host = _host()
    peer = _open(host, server)
    peer.sendall(bytes([0, 7, 255]))
    _arrived(host)
    assert _drive(host, ls.socket_read_byte_list(host, 3, "socket_0", 1.0))[0] == [3, 0, 7, 255]
    assert _drive(host, ls.socket_read_byte_list(host, 2, "socket_0", DT))[0] == [0, -1, -1]
    peer.close()


def test_get_var_asks_and_parses_the_answer(server: socket.socket) -> None:
    host = _host()
    peer = _open(host, server)
    call = ls.socket_get_var(host, "speed", "socket_0")
    assert not _cycle_first(call)
    assert peer.recv(64) == b"GET speed\n"
    peer.sendall(b"speed 42\n")
    _arrived(host)
    finished, value = _cycle(host, call)
    assert (finished, value) == (True, 42)
    peer.close()


def _cycle_first(call: Generator[None, None, Any]) -> bool:
    try:
        next(call)
    except StopIteration:
        return True
    return False


def test_number_must_be_positive(server: socket.socket) -> None:
    host = _host()
    peer = _open(host, server)
    with pytest.raises(ScriptRuntimeError, match="number"):
        _drive(host, ls.socket_read_binary_integer(host, 0, "socket_0", 1.0))
    peer.close()


# ---- through a script ------------------------------------------------------------------------------------


def test_a_script_retries_until_the_server_listens() -> None:
    """Our control script's connect loop: socket_open is refused while nothing listens, the script sleeps
    and tries again, and connects once the server is up."""
    messages: list[str] = []
    model = load_ur_model("ur10e")
    host = ScriptHost(
        FakeArm(model, model.dh),
        step_time=DT,
        local_address=fake_address(),
        message=lambda kind, text: messages.append(text),
    )
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as server:
        server.bind(("127.0.0.1", 0))  # bound, not listening: connections are refused
        port = server.getsockname()[1]
        text = (
            "attempt = 0\n"
            f'while not socket_open("127.0.0.1", {port}, "trajectory_socket"):\n'
            '  attempt = attempt + 1\n  textmsg("refused ", attempt)\n  sleep(0.2)\n'
            "end\n"
            'textmsg("connected after ", attempt)\n'
        )
        run = compile_program(text, series="e", version=(5, 12)).start(host)
        for _ in range(1000):
            run.step()
            host.arm.step(DT)
            if len(messages) == 2:
                break
        assert messages == ["refused 1", "refused 2"]
        server.listen(1)
        for _ in range(1000):
            if run.done:
                break
            run.step()
            host.arm.step(DT)
        assert run.error is None
        assert messages[-1] == "connected after 2"
        peer, (address, _) = server.accept()
        peer.close()
    assert address == host.local_address


def test_a_script_echoes_frames_until_the_peer_stops(server: socket.socket) -> None:
    """The shape of our control script's main loop: open, read a frame per cycle, answer, end on a failed
    read (the peer closed), close."""
    host = _host()
    port = server.getsockname()[1]
    text = (
        f'if not socket_open("127.0.0.1", {port}, "reverse_socket"):\n  halt\nend\n'
        "while True:\n"
        '  frame = socket_read_binary_integer(2, "reverse_socket", 0)\n'
        "  if frame[0] != 2:\n    break\n  end\n"
        '  socket_send_int(frame[1] + frame[2], "reverse_socket")\n'
        "end\n"
        'socket_close("reverse_socket")\n'
    )
    run = compile_program(text, series="e", version=(5, 12)).start(host)
    run.step()
    peer, _ = server.accept()
    peer.settimeout(WAIT_S)
    for index in range(20):
        peer.sendall(_frame(index, 100))
        _arrived(host, "reverse_socket")
        run.step()
        host.arm.step(DT)
        assert struct.unpack(">i", peer.recv(4)) == (index + 100,)
    peer.close()
    _arrived(host, "reverse_socket")
    run.step()
    assert run.done
    assert run.error is None
    assert host.sockets.get("reverse_socket") is None


def test_a_read_of_more_values_than_the_fake_bounds_is_a_runtime_error() -> None:
    """A script asking for 400 million integers would make the fake allocate them on a timeout."""
    from urdaemon.fakeur.urscript import lib_sockets

    with pytest.raises(ScriptRuntimeError, match="more than the 1000 values"):
        lib_sockets._count("socket_read_binary_integer", 400_000_000)
    assert lib_sockets._count("socket_read_binary_integer", 28) == 28
