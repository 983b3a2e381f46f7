"""URScript's ``socket_*`` builtins over real TCP, driven by the controller cycle (no event loop).

A program's sockets are plain non-blocking sockets kept in ``host.sockets`` (a :class:`SocketTable`).
``socket_open`` connects from ``host.local_address`` (a robot's connections come from its own address)
and blocks its thread cycle by cycle until connected, refused, or :data:`CONNECT_TIMEOUT_S` of controller
time. Reads take from the kernel buffer with non-blocking ``recv`` only when the script asks, and only as
many bytes as the request needs (a delimited read takes at most :data:`READ_CHUNK` at a time): a peer
that floods a socket the script reads slowly or not at all only fills the kernel buffer, and TCP flow
control stops it. A request not yet complete keeps what arrived, for the next read. Waiting is cycle by
cycle, timed in controller time (``host.now``); a timeout of 0 or less waits forever; a closed or failed
socket fails a read at once. Sends are non-blocking; what the kernel does not take at once is kept and
sent first by the socket's next operation.

These are the one kind of socket the fake keeps off the asyncio shell (``urdaemon.shell``), on purpose:
a controller's program reads its socket in its own cycle, at the moment of the read, and gets every
byte the kernel holds by then. A shell pushes only what the event loop has read, after a loop turn, so
a frame that reached the kernel just before a cycle would wait for the next one; the control-script
tests (tests/fakeur/test_control_script.py) send a frame and run the cycle at once, and fail on that
model. Reading in the cycle also keeps a flooding peer's bytes in the kernel, not in the fake.

Results follow UR's URScript manual: ``socket_read_binary_integer(3)`` gives ``[3, a, b, c]``, or
``[0, -1, -1, -1]`` on a timeout, a closed socket or an unknown name; ``socket_read_ascii_float`` reads
``(1.5, 2, 3)`` and fails with ``[0, nan, ...]``; string reads fail with ``""``.
"""

from __future__ import annotations

import errno
import math
import socket
import struct
from collections.abc import Generator
from typing import Any, Final

from urdaemon.fakeur.urscript.checker import DEFAULT_SOCKET
from urdaemon.fakeur.urscript.lib_core import text as printed
from urdaemon.fakeur.urscript.runtime import ScriptRuntimeError, UrList, builtin
from urdaemon.fakeur.urscript.script_host import ScriptHost

__all__ = [
    "CONNECT_TIMEOUT_S",
    "DEFAULT_SOCKET",
    "MAX_PENDING_BYTES",
    "READ_CHUNK",
    "ScriptSocket",
    "SocketTable",
]

CONNECT_TIMEOUT_S: Final = 2.0
"""s: how long ``socket_open`` tries before it returns False (UR's manual: it times out after 2 s)."""
READ_CHUNK: Final = 4096
"""B: most a delimited read (line, string, ASCII floats) takes from the kernel per attempt."""
MAX_DELIMITED_BYTES: Final = 65536
"""B: a delimited read that finds no delimiter in this much data fails (and drops that data)."""
MAX_PENDING_BYTES: Final = 1 << 20
"""B: unsent data kept per socket while the peer does not read; beyond it a send returns False."""
_TIME_EPSILON: Final = 1e-9
_IN_PROGRESS: Final = frozenset({errno.EINPROGRESS, errno.EALREADY, errno.EWOULDBLOCK, errno.EAGAIN})
_INT32: Final = (-(2**31), 2**31 - 1)
_ESCAPES: Final = {"n": "\n", "r": "\r", "t": "\t", "\\": "\\", '"': '"', "'": "'", "0": "\0"}

Blocking = Generator[None, None, Any]


class ScriptSocket:
    """One named socket of a program: the connected socket, bytes read but not yet taken, unsent bytes."""

    __slots__ = ("buffer", "eof", "pending", "sock")

    def __init__(self, sock: socket.socket) -> None:
        self.sock: socket.socket | None = sock
        """None once closed by the script or broken."""
        self.buffer = bytearray()
        self.pending = bytearray()
        self.eof = False
        """The peer has finished sending (or the socket failed): reads stop waiting."""

    def take(self, size: int) -> bytes | None:
        """Exactly ``size`` bytes if they have arrived, else None (what arrived stays buffered).

        Takes from the kernel only what the request still lacks (at most :data:`READ_CHUNK` per
        ``recv``), so a peer sending faster than the script reads is held back by TCP flow control."""
        if self.pending:
            self.flush()
        buffer = self.buffer
        have = len(buffer)
        sock = self.sock
        if have < size and sock is not None and not self.eof:
            try:
                while have < size:
                    data = sock.recv(min(size - have, READ_CHUNK))
                    if len(data) == size:
                        return data  # the common case: one whole frame at once, no copy
                    if not data:
                        self.eof = True
                        break
                    buffer += data
                    have += len(data)
            except BlockingIOError:
                pass
            except OSError:
                self.eof = True
        if have < size:
            return None
        data = bytes(buffer[:size])
        del buffer[:size]
        return data

    def fill(self) -> None:
        """Read what has arrived, at most :data:`READ_CHUNK` bytes, into the buffer."""
        if self.pending:
            self.flush()
        sock = self.sock
        if sock is None or self.eof:
            return
        try:
            data = sock.recv(READ_CHUNK)
        except BlockingIOError:
            return
        except OSError:
            self.eof = True
            return
        if data:
            self.buffer += data
        else:
            self.eof = True

    def send(self, data: bytes) -> bool:
        """Send ``data`` without blocking; False if the socket is closed or broken or too far behind."""
        sock = self.sock
        if sock is None:
            return False
        if self.pending:
            self.flush()
            if self.sock is None:
                return False
            if self.pending:
                if len(self.pending) + len(data) > MAX_PENDING_BYTES:
                    return False
                self.pending += data
                return True
        try:
            sent = sock.send(data)
        except BlockingIOError:
            sent = 0
        except OSError:
            self.close()
            return False
        if sent < len(data):
            self.pending += data[sent:]
        return True

    def flush(self) -> None:
        """Send what earlier sends left over, as far as the kernel takes it now."""
        sock = self.sock
        if sock is None:
            self.pending.clear()
            return
        try:
            sent = sock.send(self.pending)
        except BlockingIOError:
            return
        except OSError:
            self.close()
            return
        del self.pending[:sent]

    def close(self) -> None:
        sock, self.sock = self.sock, None
        self.eof = True
        self.pending.clear()
        if sock is not None:
            sock.close()


class SocketTable:
    """A program's open sockets by name (``host.sockets``)."""

    __slots__ = ("sockets",)

    def __init__(self) -> None:
        self.sockets: dict[str, ScriptSocket] = {}

    def get(self, name: str) -> ScriptSocket | None:
        return self.sockets.get(name)

    def add(self, name: str, sock: socket.socket) -> ScriptSocket:
        self.close(name)
        entry = self.sockets[name] = ScriptSocket(sock)
        return entry

    def close(self, name: str) -> None:
        entry = self.sockets.pop(name, None)
        if entry is not None:
            entry.close()

    def close_all(self) -> None:
        """The program ended: flush what is unsent (best effort, without blocking) and close everything."""
        for entry in self.sockets.values():
            if entry.pending:
                entry.flush()
            entry.close()
        self.sockets.clear()


def _table(host: ScriptHost) -> SocketTable:
    table = host.sockets
    if table is None:
        table = host.sockets = SocketTable()
    return table  # type: ignore[no-any-return]


def _entry(host: ScriptHost, name: Any) -> ScriptSocket | None:
    table = host.sockets
    return None if table is None else table.sockets.get(name)


def _deadline(host: ScriptHost, timeout: Any) -> float:
    """Controller time at which a read gives up; infinity for a timeout of 0 or less (wait forever)."""
    seconds = float(timeout)
    return host.now + seconds - _TIME_EPSILON if seconds > 0 else math.inf


MAX_READ_COUNT = 1000
"""The most values one socket read may ask for: the fake's own bound (memory), far above the 8-30
values the scripts we know read at once."""


def _count(function: str, number: Any) -> int:
    if number.__class__ is int and 0 < number <= MAX_READ_COUNT:
        return int(number)
    if isinstance(number, float) and number.is_integer():
        number = int(number)
    if isinstance(number, bool) or not isinstance(number, int) or number < 1:
        raise ScriptRuntimeError(f"{function}: number must be a positive integer, got {number!r}")
    if number > MAX_READ_COUNT:
        raise ScriptRuntimeError(
            f"{function}: number {number} is more than the {MAX_READ_COUNT} values the fake reads at once"
        )
    return number


def _int32(function: str, value: Any) -> int:
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    if isinstance(value, bool) or not isinstance(value, int) or not _INT32[0] <= value <= _INT32[1]:
        raise ScriptRuntimeError(f"{function}: {value!r} is not a 32-bit integer")
    return value


def _ascii(function: str, text: Any) -> bytes:
    if not isinstance(text, str):
        raise ScriptRuntimeError(f"{function}: expected a string, got {text!r}")
    return text.encode("latin-1", errors="replace")


# ---- connecting -------------------------------------------------------------------------------------


@builtin("socket_open", blocking=True)
def socket_open(
    host: ScriptHost,
    address: Any,
    port: Any,
    socket_name: Any = DEFAULT_SOCKET,
    timeout: Any = CONNECT_TIMEOUT_S,
) -> Blocking:
    """Connect ``socket_name`` to ``address:port``; True once connected, False if refused or timed out.

    A name that is still connected stays as it is (True); a closed or failed one is connected anew."""
    if not isinstance(address, str) or isinstance(port, bool) or not isinstance(port, int):
        raise ScriptRuntimeError(
            f"socket_open: expected an address string and a port number, got {address!r}, {port!r}"
        )
    table = _table(host)
    existing = table.get(socket_name)
    if existing is not None and existing.sock is not None and not existing.eof:
        return True
    started = _start_connect(host.local_address, address, port)
    if started is None:
        return False
    sock, target = started
    deadline = host.now + (float(timeout) if float(timeout) > 0 else CONNECT_TIMEOUT_S) - _TIME_EPSILON
    try:
        while True:
            status = sock.connect_ex(target)
            if status in (0, errno.EISCONN):
                table.add(socket_name, sock)
                return True
            if status not in _IN_PROGRESS or host.now >= deadline:
                return False
            yield
    finally:  # refused, timed out, or the thread was killed (or the program stopped) while connecting
        if table.get(socket_name) is None or table.sockets[socket_name].sock is not sock:
            sock.close()


def _target(address: str, port: int) -> tuple[str, int]:
    try:
        socket.inet_aton(address)
    except OSError:
        infos = socket.getaddrinfo(address, port, socket.AF_INET, socket.SOCK_STREAM)
        return (str(infos[0][4][0]), port)
    return (address, port)


def _start_connect(
    local_address: str, address: str, port: int
) -> tuple[socket.socket, tuple[str, int]] | None:
    """A non-blocking socket bound to ``local_address`` with its connection under way; None on failure."""
    try:
        target = _target(address, port)
    except (OSError, UnicodeError):
        return None
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    try:
        sock.setblocking(False)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        sock.bind((local_address, 0))
        status = sock.connect_ex(target)
    except (OSError, OverflowError):
        sock.close()
        return None
    if status not in (0, *_IN_PROGRESS):
        sock.close()
        return None
    return sock, target


@builtin("socket_close")
def socket_close(host: ScriptHost, socket_name: Any = DEFAULT_SOCKET) -> None:
    """Close ``socket_name`` (nothing happens for a name that is not open)."""
    table = host.sockets
    if table is not None:
        table.close(socket_name)


# ---- sending ------------------------------------------------------------------------------------------


def _send(host: ScriptHost, socket_name: Any, data: bytes) -> bool:
    entry = _entry(host, socket_name)
    return entry is not None and entry.send(data)


@builtin("socket_send_int")
def socket_send_int(host: ScriptHost, value: Any, socket_name: Any = DEFAULT_SOCKET) -> bool:
    """Send ``value`` as a 32-bit big-endian integer."""
    return _send(host, socket_name, _INT.pack(_int32("socket_send_int", value)))


@builtin("socket_send_byte")
def socket_send_byte(host: ScriptHost, value: Any, socket_name: Any = DEFAULT_SOCKET) -> bool:
    """Send one byte (0..255)."""
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 255:
        raise ScriptRuntimeError(f"socket_send_byte: {value!r} is not a byte (0..255)")
    return _send(host, socket_name, bytes((value,)))


@builtin("socket_send_string")
def socket_send_string(host: ScriptHost, text: Any, socket_name: Any = DEFAULT_SOCKET) -> bool:
    """Send ``text`` in ASCII, nothing added; another value as the controller prints it (``p[0.1, ...]``)."""
    return _send(host, socket_name, _ascii("socket_send_string", printed(text)))


@builtin("socket_send_line")
def socket_send_line(host: ScriptHost, text: Any, socket_name: Any = DEFAULT_SOCKET) -> bool:
    """Send ``text`` (or another value, printed) in ASCII followed by a newline."""
    return _send(host, socket_name, _ascii("socket_send_line", printed(text)) + b"\n")


@builtin("socket_set_var")
def socket_set_var(host: ScriptHost, name: Any, value: Any, socket_name: Any = DEFAULT_SOCKET) -> None:
    """Send ``SET <name> <value>\\n`` (value an integer)."""
    line = f"SET {name} {_int32('socket_set_var', value)}\n"
    _send(host, socket_name, _ascii("socket_set_var", line))


# ---- reading fixed-size items ------------------------------------------------------------------------

_INT: Final = struct.Struct(">i")
_INTS: dict[int, struct.Struct] = {}


def _ints_format(number: int) -> struct.Struct:
    fmt = _INTS.get(number)
    if fmt is None:
        fmt = _INTS[number] = struct.Struct(f">{number}i")
    return fmt


def _wait_exact(
    host: ScriptHost, entry: ScriptSocket, size: int, timeout: Any
) -> Generator[None, None, bytes | None]:
    """Exactly ``size`` bytes, waiting cycle by cycle; None on a timeout or when the socket ends."""
    deadline = _deadline(host, timeout)
    while True:
        yield
        data = entry.take(size)
        if data is not None or entry.eof or host.now >= deadline:
            return data


@builtin("socket_read_binary_integer", blocking=True)
def socket_read_binary_integer(
    host: ScriptHost, number: Any, socket_name: Any = DEFAULT_SOCKET, timeout: Any = 2.0
) -> Blocking:
    """``[number, v1, ..., vn]``: ``number`` big-endian int32s; ``[0, -1, ...]`` if they do not come."""
    count = _count("socket_read_binary_integer", number)
    entry = _entry(host, socket_name)
    data = None if entry is None else entry.take(4 * count)
    if data is None and entry is not None and not entry.eof:
        data = yield from _wait_exact(host, entry, 4 * count, timeout)
    if data is None:
        return UrList((0, *(-1,) * count))
    return UrList((count, *_ints_format(count).unpack(data)))


@builtin("socket_read_byte_list", blocking=True)
def socket_read_byte_list(
    host: ScriptHost, number: Any, socket_name: Any = DEFAULT_SOCKET, timeout: Any = 2.0
) -> Blocking:
    """``[number, b1, ..., bn]``: ``number`` bytes (0..255); ``[0, -1, ...]`` if they do not come."""
    count = _count("socket_read_byte_list", number)
    entry = _entry(host, socket_name)
    data = None if entry is None else entry.take(count)
    if data is None and entry is not None and not entry.eof:
        data = yield from _wait_exact(host, entry, count, timeout)
    if data is None:
        return UrList((0, *(-1,) * count))
    return UrList((count, *data))


# ---- reading delimited text --------------------------------------------------------------------------


def _read_until(
    host: ScriptHost, socket_name: Any, timeout: Any, find: Any
) -> Generator[None, None, tuple[ScriptSocket, int] | None]:
    """Wait until ``find(buffer)`` gives an index (>= 0) into the socket's buffer; None on failure.

    Reads at most :data:`READ_CHUNK` bytes per attempt; fails (dropping the data) if
    :data:`MAX_DELIMITED_BYTES` arrive without a match."""
    entry = _entry(host, socket_name)
    if entry is None:
        return None
    deadline = _deadline(host, timeout)
    while True:
        end = find(entry.buffer)
        if end < 0:
            entry.fill()
            end = find(entry.buffer)
        if end >= 0:
            return entry, end
        if len(entry.buffer) > MAX_DELIMITED_BYTES:
            entry.buffer.clear()
            return None
        if entry.eof or host.now >= deadline:
            return None
        yield


@builtin("socket_read_line", blocking=True)
def socket_read_line(host: ScriptHost, socket_name: Any = DEFAULT_SOCKET, timeout: Any = 2.0) -> Blocking:
    """The next line without its ``\\n`` or ``\\r\\n``; ``""`` if none comes."""
    found = yield from _read_until(host, socket_name, timeout, lambda buffer: buffer.find(b"\n"))
    if found is None:
        return ""
    entry, end = found
    line = bytes(entry.buffer[:end])
    del entry.buffer[: end + 1]
    if line.endswith(b"\r"):
        line = line[:-1]
    return line.decode("latin-1")


@builtin("socket_read_ascii_float", blocking=True)
def socket_read_ascii_float(
    host: ScriptHost, number: Any, socket_name: Any = DEFAULT_SOCKET, timeout: Any = 2.0
) -> Blocking:
    """``[number, f1, ..., fn]`` from text like ``(1.414, 3.14, 0)``; ``[0, nan, ...]`` if none comes or it
    does not hold ``number`` numbers. Text before the ``(`` is skipped."""
    count = _count("socket_read_ascii_float", number)
    failed = UrList((0, *(math.nan,) * count))

    def closing(buffer: bytearray) -> int:
        start = buffer.find(b"(")
        return -1 if start < 0 else buffer.find(b")", start)

    found = yield from _read_until(host, socket_name, timeout, closing)
    if found is None:
        return failed
    entry, end = found
    text = bytes(entry.buffer[entry.buffer.find(b"(") + 1 : end]).decode("latin-1")
    del entry.buffer[: end + 1]
    try:
        values = [float(part) for part in text.split(",")]
    except ValueError:
        return failed
    if len(values) != count:
        return failed
    return UrList((count, *values))


@builtin("socket_read_string", blocking=True)
def socket_read_string(
    host: ScriptHost,
    socket_name: Any = DEFAULT_SOCKET,
    prefix: Any = "",
    suffix: Any = "",
    interpret_escape: Any = False,
    timeout: Any = 2.0,
) -> Blocking:
    """What has arrived, as text; with ``prefix`` and/or ``suffix``, the text between them (both dropped,
    and whatever came before the prefix); ``""`` if nothing (complete) comes."""
    start_mark = _ascii("socket_read_string", prefix)
    end_mark = _ascii("socket_read_string", suffix)

    def search(buffer: bytearray) -> int:
        start = 0
        if start_mark:
            start = buffer.find(start_mark)
            if start < 0:
                return -1
            start += len(start_mark)
        if end_mark:
            return buffer.find(end_mark, start)
        return len(buffer) if len(buffer) > start else -1

    found = yield from _read_until(host, socket_name, timeout, search)
    if found is None:
        return ""
    entry, end = found
    buffer = entry.buffer
    start = buffer.find(start_mark) + len(start_mark) if start_mark else 0
    text = bytes(buffer[start:end]).decode("latin-1")
    del buffer[: end + len(end_mark)]
    return _unescape(text) if interpret_escape else text


def _unescape(text: str) -> str:
    parts = text.split("\\")
    out = [parts[0]]
    iterator = iter(parts[1:])
    for part in iterator:
        if not part:  # a doubled backslash
            out.append("\\")
            out.append(next(iterator, ""))
            continue
        out.append(_ESCAPES.get(part[0], "\\" + part[0]) + part[1:])
    return "".join(out)


@builtin("socket_get_var", blocking=True)
def socket_get_var(host: ScriptHost, name: Any, socket_name: Any = DEFAULT_SOCKET) -> Blocking:
    """Send ``GET <name>\\n`` and wait (2 s) for ``<name> <integer>\\n``; 0 if it does not come."""
    if not _send(host, socket_name, _ascii("socket_get_var", f"GET {name}\n")):
        return 0
    line = yield from socket_read_line(host, socket_name, 2.0)
    head, _, value = str(line).partition(" ")
    if head != name:
        return 0
    try:
        return int(value.strip())
    except ValueError:
        return 0
