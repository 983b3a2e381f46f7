"""Helpers for the judge tests: independent clients (ur_rtde, python-urx, plain sockets) against the fake
controller, run as users run it, and independent readers of what the fake does.

The fake runs as ``urdaemon fake-robot`` in its own process (``fake_robot``): ur_rtde's calls hold the
GIL while they block on the network, so a fake in the test's own process could never answer them.
What the fake says is read by our own codecs on their own threads (``PrimaryWatch`` on the primary
interface, ``RtdeWatch`` on RTDE), so a failing judge can show the controller's messages.

Every wait here is bounded in count and in time, and wakes on the data it waits for (a sample, a
message), never on a sleep.
"""

from __future__ import annotations

import contextlib
import math
import os
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from typing import Any

from tests.helpers import drain_in_background, fake_address
from urdaemon.description.kinematics import DhKinematics
from urdaemon.description.urmodels import load_ur_model
from urdaemon.protocols import primary as prim
from urdaemon.protocols import rtde
from urdaemon.protocols._buffer import Side

__all__ = [
    "FakeProcess",
    "PrimaryWatch",
    "RtdeWatch",
    "fake_robot",
    "pose_error",
    "pose_off",
    "send_script",
    "tcp_pose",
    "wait_until",
]

Pose = tuple[float, float, float, float, float, float]


# ---- the fake, in its own process ---------------------------------------------------------------------


class FakeProcess:
    """One ``urdaemon fake-robot`` process serving one fake at ``address``; ``log`` keeps its stderr."""

    def __init__(self, proc: subprocess.Popen[str], address: str, model: str, log: list[str]) -> None:
        self.proc = proc
        self.address = address
        self.model = model
        self.log = log

    def close(self) -> None:
        """Stop the process (SIGTERM, then SIGKILL if it does not end)."""
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=10)

    def log_tail(self, lines: int = 30) -> str:
        """The fake's last log lines, for a failing judge's message."""
        return "".join(self.log[-lines:])


def start_fake(model: str = "ur10e", *flags: str) -> FakeProcess:
    """``urdaemon fake-robot --model MODEL`` on a fresh run-specific address, started and serving."""
    address = fake_address()
    proc = subprocess.Popen(
        [sys.executable, "-m", "urdaemon", "fake-robot", "--model", model, "--address", address, *flags],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    assert proc.stderr is not None
    lines: list[str] = []
    for _ in range(200):
        line = proc.stderr.readline()
        if not line:
            raise AssertionError(f"fake-robot exited ({proc.poll()}): {''.join(lines)}")
        lines.append(line)
        if "serving 1 fake robot(s)" in line:
            drain_in_background(proc, lines)
            return FakeProcess(proc, address, model, lines)
    proc.kill()
    raise AssertionError(f"fake-robot did not start: {''.join(lines)}")


@contextlib.contextmanager
def fake_robot(model: str = "ur10e", *flags: str) -> Iterator[FakeProcess]:
    """A fake robot process for the duration of the block."""
    fake = start_fake(model, *flags)
    try:
        yield fake
    finally:
        fake.close()


# ---- waiting, bounded ---------------------------------------------------------------------------------


def wait_until(condition: Callable[[], bool], seconds: float, *, step: float = 0.01) -> bool:
    """Ask ``condition`` every ``step`` s until it holds or ``seconds`` passed; whether it held.

    For clients that can only be polled (ur_rtde's getters): the loop is bounded in count and time.
    """
    deadline = time.monotonic() + seconds
    for _ in range(int(seconds / step) + 2):
        if condition():
            return True
        if time.monotonic() > deadline:
            break
        time.sleep(step)
    return bool(condition())


class _Watch(threading.Thread):
    """A daemon thread reading one socket of the fake; ``wait_for`` wakes on every thing it reads."""

    def __init__(self, name: str) -> None:
        super().__init__(name=name, daemon=True)
        self._changed = threading.Condition()
        self._closing = threading.Event()
        self.error: BaseException | None = None

    def _notify(self) -> None:
        with self._changed:
            self._changed.notify_all()

    def wait_for(self, predicate: Callable[[], bool], seconds: float) -> bool:
        """Wait until ``predicate()`` holds (checked on every arrival), at most ``seconds``; whether it
        held."""
        deadline = time.monotonic() + seconds
        with self._changed:
            for _ in range(1_000_000):
                if predicate():
                    return True
                left = deadline - time.monotonic()
                if left <= 0 or not self.is_alive():
                    return bool(predicate())
                self._changed.wait(min(left, 0.5))
        return bool(predicate())

    def close(self) -> None:
        self._closing.set()
        self.join(timeout=5)


class PrimaryWatch(_Watch):
    """Reads the fake's primary interface (30001) with our codec: every robot message, and the state."""

    def __init__(self, address: str, port: int = 30001) -> None:
        super().__init__(f"primary-watch-{address}")
        self.sock = socket.create_connection((address, port), timeout=10)
        self.sock.settimeout(0.2)
        self.conn = prim.PrimaryConnection(Side.DAEMON)
        self.messages: list[Any] = []
        self.mode: prim.RobotModeData | None = None
        self.joints: prim.JointData | None = None
        self.states = 0
        self.start()

    def run(self) -> None:
        try:
            for _ in range(100_000_000):
                if self._closing.is_set():
                    return
                try:
                    data = self.sock.recv(65536)
                except TimeoutError:
                    continue
                if not data:
                    return
                for event in self.conn.receive_data(data):
                    self._take(event)
                self._notify()
        except BaseException as err:  # kept for the test's message
            self.error = err
        finally:
            self.sock.close()
            self._notify()

    def _take(self, event: Any) -> None:
        if isinstance(event, prim.RobotState):
            self.states += 1
            mode = event.get(prim.RobotModeData)
            if mode is not None:
                self.mode = mode
            joints = event.get(prim.JointData)
            if joints is not None:
                self.joints = joints
        elif not isinstance(event, prim.OtherPackage | prim.VersionMessage):
            self.messages.append(event)

    @property
    def program_running(self) -> bool:
        return self.mode is not None and self.mode.is_program_running

    def runtime_exceptions(self) -> list[prim.RuntimeExceptionMessage]:
        return [m for m in self.messages if isinstance(m, prim.RuntimeExceptionMessage)]

    def texts(self) -> list[str]:
        """Every message as one line of text (the controller's words)."""
        return [_message_text(m) for m in self.messages]

    def describe(self) -> str:
        """What the controller said, for a failing judge's message."""
        said = "\n  ".join(self.texts()[-40:]) or "(nothing)"
        running = None if self.mode is None else self.mode.is_program_running
        return f"program running: {running}; the fake's primary messages:\n  {said}"

    def wait_for_state(self, count: int, seconds: float) -> bool:
        """Wait until ``count`` more robot states arrived (the 10 Hz state is the controller's clock)."""
        target = self.states + count
        return self.wait_for(lambda: self.states >= target, seconds)


def _message_text(message: Any) -> str:
    if isinstance(message, prim.RuntimeExceptionMessage):
        return f"RuntimeException {message.line}:{message.column}: {message.text}"
    if isinstance(message, prim.KeyMessage):
        return f"Key {message.title}: {message.text}"
    if isinstance(message, prim.TextMessage):
        return f"Text: {message.text}"
    return repr(message)


class RtdeWatch(_Watch):
    """Reads the fake's RTDE outputs ``names`` at ``frequency`` with our own codec; keeps the last sample."""

    def __init__(self, address: str, names: Sequence[str], frequency: float = 125.0) -> None:
        super().__init__(f"rtde-watch-{address}")
        self.names = tuple(names)
        self.sock = socket.create_connection((address, 30004), timeout=10)
        self.sock.settimeout(10)
        self.conn = rtde.RtdeConnection(Side.DAEMON)
        self.sample: dict[str, Any] = {}
        self.samples = 0
        self._pending: list[Any] = []
        for request in (
            rtde.RequestProtocolVersion(2),
            rtde.SetupOutputs(frequency, self.names),
            rtde.Start(),
        ):
            self.conn.send(request)
            self.sock.sendall(self.conn.data_to_send())
            reply = self._next_event()
            if isinstance(reply, rtde.OutputsConfigured) and reply.not_found:
                raise AssertionError(f"the fake's RTDE does not know {reply.not_found}")
        self.sock.settimeout(0.2)
        self.start()

    def _next_event(self) -> Any:
        for _ in range(1000):
            if self._pending:
                return self._pending.pop(0)
            data = self.sock.recv(65536)
            assert data, "the fake closed the RTDE connection"
            self._pending.extend(self.conn.receive_data(data))
        raise AssertionError("no RTDE reply")

    def run(self) -> None:
        try:
            for _ in range(100_000_000):
                if self._closing.is_set():
                    return
                events, self._pending = self._pending, []
                if not events:
                    try:
                        data = self.sock.recv(65536)
                    except TimeoutError:
                        continue
                    if not data:
                        return
                    events = self.conn.receive_data(data)
                for event in events:
                    if isinstance(event, rtde.DataPackage):
                        self.sample = dict(zip(self.names, event.values, strict=True))
                        self.samples += 1
                self._notify()
        except BaseException as err:  # kept for the test's message
            self.error = err
        finally:
            self.sock.close()
            self._notify()

    def next_samples(self, count: int, seconds: float = 10.0) -> dict[str, Any]:
        """The sample after ``count`` more arrived (AssertionError if they do not within ``seconds``)."""
        target = self.samples + count
        assert self.wait_for(lambda: self.samples >= target, seconds), f"no RTDE sample: {self.error}"
        return self.sample


# ---- sending scripts ----------------------------------------------------------------------------------


def send_script(address: str, port: int, text: str) -> None:
    """Send URScript ``text`` to the fake's port (30001, 30002 or 30003), as a plain client does."""
    with socket.create_connection((address, port), timeout=10) as sock:
        sock.sendall(text.encode("ascii"))
        # a client that closes at once is normal (python-urx keeps the socket; nc does not)
        sock.shutdown(socket.SHUT_WR)
        sock.settimeout(0.5)
        with contextlib.suppress(OSError):
            for _ in range(10):  # let the controller read it before the socket goes
                if not sock.recv(65536):
                    break


# ---- kinematics, independent of the fake --------------------------------------------------------------


def _quaternion_matrix(qx: float, qy: float, qz: float, qw: float) -> list[list[float]]:
    return [
        [1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qz * qw), 2 * (qx * qz + qy * qw)],
        [2 * (qx * qy + qz * qw), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qx * qw)],
        [2 * (qx * qz - qy * qw), 2 * (qy * qz + qx * qw), 1 - 2 * (qx * qx + qy * qy)],
    ]


def _rotvec_matrix(r: Sequence[float]) -> list[list[float]]:
    angle = math.sqrt(sum(v * v for v in r))
    if angle < 1e-15:
        return [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    half = angle / 2
    s = math.sin(half) / angle
    return _quaternion_matrix(r[0] * s, r[1] * s, r[2] * s, math.cos(half))


def _matrix_rotvec(m: Sequence[Sequence[float]]) -> tuple[float, float, float]:
    cos = max(-1.0, min(1.0, (m[0][0] + m[1][1] + m[2][2] - 1) / 2))
    angle = math.acos(cos)
    if angle < 1e-12:
        return (0.0, 0.0, 0.0)
    if math.pi - angle < 1e-6:  # near a half turn: the axis from the diagonal
        axis = [math.sqrt(max(0.0, (m[i][i] + 1) / 2)) for i in range(3)]
        largest = max(range(3), key=lambda i: axis[i])
        for i in range(3):
            if i != largest:
                axis[i] = math.copysign(axis[i], m[largest][i] + m[i][largest])
        return (axis[0] * angle, axis[1] * angle, axis[2] * angle)
    k = angle / (2 * math.sin(angle))
    return ((m[2][1] - m[1][2]) * k, (m[0][2] - m[2][0]) * k, (m[1][0] - m[0][1]) * k)


def _matmul(a: Sequence[Sequence[float]], b: Sequence[Sequence[float]]) -> list[list[float]]:
    return [[sum(a[i][k] * b[k][j] for k in range(3)) for j in range(3)] for i in range(3)]


def tcp_pose(model: str, q: Sequence[float], tcp: Sequence[float] = (0.0,) * 6) -> Pose:
    """The TCP pose ``p[x, y, z, rx, ry, rz]`` of nominal ``model`` at joints ``q`` with TCP offset
    ``tcp`` (flange -> TCP), by our own forward kinematics (the fake runs the nominal DH unless given
    a calibration)."""
    x, y, z, qx, qy, qz, qw = DhKinematics(load_ur_model(model).dh).tool_pose(q)
    flange = _quaternion_matrix(qx, qy, qz, qw)
    offset = [sum(flange[i][k] * tcp[k] for k in range(3)) for i in range(3)]
    rot = _matmul(flange, _rotvec_matrix(tcp[3:]))
    rx, ry, rz = _matrix_rotvec(rot)
    return (x + offset[0], y + offset[1], z + offset[2], rx, ry, rz)


def pose_error(a: Sequence[float], b: Sequence[float]) -> tuple[float, float]:
    """(position distance in m, rotation angle between the two orientations in rad) of two UR poses."""
    position = math.dist(a[:3], b[:3])
    ra, rb = _rotvec_matrix(a[3:6]), _rotvec_matrix(b[3:6])
    relative = _matmul([list(col) for col in zip(*ra, strict=True)], rb)
    cos = max(-1.0, min(1.0, (relative[0][0] + relative[1][1] + relative[2][2] - 1) / 2))
    return position, math.acos(cos)


def pose_off(
    actual: Sequence[float],
    target: Sequence[float],
    position_tol: float = 1e-4,
    orientation_tol: float = 1e-3,
) -> str:
    """ "" when pose ``actual`` is within the tolerances (m, rad) of ``target``, else how far off it is."""
    position, orientation = pose_error(actual, target)
    if position <= position_tol and orientation <= orientation_tol:
        return ""
    return f"{list(actual)} is {position:.3g} m / {orientation:.3g} rad from {list(target)}"
