"""A rig that runs our rendered control script in the URScript interpreter against a test daemon.

The test plays the daemon: three loopback servers on ports from the OS, speaking the DAEMON side of the
reverse, trajectory-point and script-command codecs. The rig plays the fake controller's cycle as
``FakeController`` does: ``run.step()`` while the program plays (not while it is paused), then
``arm.step(DT)``; when the program ends its host is closed (its sockets with it).

Time is controller time only: the rig runs cycles as fast as the machine allows, and hands the event
loop one turn after every cycle so the daemon's servers accept, read and answer in step with the robot.
Every wait is a bounded number of cycles (and a wall-clock bound), never a sleep.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import socket
from collections.abc import AsyncIterator, Callable, Sequence
from typing import Any, Final

from urdaemon.description.urmodels import load_ur_model
from urdaemon.fakeur.fake_arm import FakeArm
from urdaemon.fakeur.urscript import compile_program
from urdaemon.fakeur.urscript.runtime import ScriptRun
from urdaemon.fakeur.urscript.script_host import ScriptHost
from urdaemon.protocols import script_command as sc
from urdaemon.protocols._buffer import Side
from urdaemon.protocols.reverse import (
    ReverseCommand,
    ReverseConnection,
    ServoJ,
    TrajectoryAction,
    TrajectoryControl,
)
from urdaemon.protocols.rtde_variables import RuntimeState
from urdaemon.protocols.trajectory_point import (
    TrajectoryPoint,
    TrajectoryPointConnection,
    TrajectoryResult,
    TrajectoryResultCode,
)
from urdaemon.urscript import ScriptParameters, render_control_script

__all__ = [
    "CB3_DT",
    "DT",
    "HOME",
    "NAMES",
    "REV",
    "SCRIPT",
    "TRAJ",
    "WAIT_S",
    "ZERO",
    "Daemon",
    "Rig",
    "hold_servo",
    "j0",
    "make_arm",
    "running_script",
    "start_rig",
    "v0",
]

DT: Final = 0.002
"""s: the e-Series controller cycle."""
VERSION: Final = (5, 15)
"""The e-Series controller version the script is rendered and compiled for."""
CB3_DT: Final = 0.008
"""s: the CB3 controller cycle."""
CB3_VERSION: Final = (3, 15)
"""The CB3 controller version the script is rendered and compiled for."""
HOME: Final = (0.0, -1.57, 1.57, -1.57, -1.57, 0.0)
ZERO: Final = (0.0,) * 6
WAIT_S: Final = 20.0
"""s of wall-clock time: the outer bound on any wait (the cycle bounds are the real ones)."""
MAX_CYCLES: Final = 5000
"""The default bound on the cycles one wait may run (10 s of controller time)."""
TRAJ, SCRIPT, REV = "trajectory_socket", "script_command_socket", "reverse_socket"
NAMES: Final = (TRAJ, SCRIPT, REV)
"""The callback sockets, in the order the script connects them."""


def j0(offset: float) -> tuple[float, ...]:
    """HOME with joint 0 moved by ``offset``."""
    return (HOME[0] + offset, *HOME[1:])


def v0(value: float) -> tuple[float, ...]:
    """A joint vector that is ``value`` in joint 0 and zero elsewhere."""
    return (value, 0.0, 0.0, 0.0, 0.0, 0.0)


def make_arm(model_name: str = "ur10e") -> FakeArm:
    model = load_ur_model(model_name)
    arm = FakeArm(model, model.dh, initial_positions=HOME, powered=True)
    assert arm.start_program() is None
    return arm


class Daemon:
    """The daemon's three callback servers, speaking the daemon side of the codecs."""

    def __init__(self) -> None:
        self.accepted: list[str] = []
        self.connected = {name: asyncio.Event() for name in NAMES}
        self.closed = {name: asyncio.Event() for name in NAMES}
        self.writers: dict[str, asyncio.StreamWriter] = {}
        self.ports: dict[str, int] = {}
        self.reverse = ReverseConnection(Side.DAEMON)
        self.trajectory = TrajectoryPointConnection(Side.DAEMON)
        self.script = sc.ScriptCommandConnection(Side.DAEMON)
        self.results: list[TrajectoryResultCode] = []
        """Every trajectory result the robot sent, in order."""
        self.tool_contact: list[sc.ToolContactResultCode] = []
        self.greeting: dict[str, bytes] = {}
        """Bytes written to a socket the moment it is accepted."""
        self._servers: list[asyncio.Server] = []

    async def serve(self, name: str, sock: socket.socket | None = None) -> None:
        handler = functools.partial(self._handle, name)
        if sock is None:
            server = await asyncio.start_server(handler, "127.0.0.1", 0)
        else:
            server = await asyncio.start_server(handler, sock=sock)
        self.ports[name] = server.sockets[0].getsockname()[1]
        self._servers.append(server)

    async def _handle(self, name: str, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self.accepted.append(name)
        self.writers[name] = writer
        if name in self.greeting:
            writer.write(self.greeting[name])
        self.connected[name].set()
        try:
            while data := await reader.read(65536):
                if name == TRAJ:
                    for event in self.trajectory.receive_data(data):
                        assert isinstance(event, TrajectoryResult)
                        self.results.append(event.result)
                elif name == SCRIPT:
                    for reply in self.script.receive_data(data):
                        assert isinstance(reply, sc.ToolContactResult)
                        self.tool_contact.append(reply.code)
                else:
                    self.reverse.receive_data(data)
        except ConnectionError:
            pass
        finally:
            self.closed[name].set()

    def send(self, message: ReverseCommand) -> None:
        self.reverse.send(message)
        self.writers[REV].write(self.reverse.data_to_send())

    def send_points(self, *points: TrajectoryPoint) -> None:
        for point in points:
            self.trajectory.send(point)
        self.writers[TRAJ].write(self.trajectory.data_to_send())

    def send_command(self, command: sc.ScriptCommand) -> None:
        self.script.send(command)
        self.writers[SCRIPT].write(self.script.data_to_send())

    def all_closed(self) -> bool:
        """Every socket the robot connected has been closed by the robot."""
        return all(self.closed[name].is_set() for name in self.writers)

    async def close(self) -> None:
        """Close every connection and server, and let each connection's handler end."""
        for writer in self.writers.values():
            writer.close()
        for server in self._servers:
            server.close()
        async with asyncio.timeout(WAIT_S):
            for name in self.writers:
                await self.closed[name].wait()
            for server in self._servers:
                await server.wait_closed()


class Rig:
    """The program, its arm and host, the test daemon, and the controller's cycle."""

    def __init__(self, daemon: Daemon, arm: FakeArm, text: str, series: str = "e") -> None:
        self.daemon = daemon
        self.arm = arm
        self.messages: list[tuple[str, str]] = []
        """Every ``host.message(kind, text)``: textmsg, popup and runtime messages."""
        version = VERSION if series == "e" else CB3_VERSION
        self.step_time = DT if series == "e" else CB3_DT
        self.host = ScriptHost(
            arm, step_time=self.step_time, series=series, version=version, message=self._message
        )
        self.program = compile_program(text, series=series, version=version)
        self.run: ScriptRun = self.program.start(self.host)
        self.cycles = 0
        self.history: list[list[float]] = []
        """``history[k]``: the arm's joints after cycle k + 1."""
        self.speeds: list[list[float]] = []
        """``speeds[k]``: the arm's joint speeds after cycle k + 1."""
        self._closed = False

    def _message(self, kind: str, text: str) -> None:
        self.messages.append((kind, text))

    def texts(self) -> list[str]:
        return [text for _, text in self.messages]

    def said(self, needle: str) -> bool:
        return any(needle in text for _, text in self.messages)

    def count(self, needle: str) -> int:
        return sum(needle in text for _, text in self.messages)

    @property
    def done(self) -> bool:
        return self.run.done

    def cycle(self) -> None:
        """One controller cycle, as ``FakeController._cycle`` runs it."""
        if not self.run.done and self.arm.runtime_state in (RuntimeState.PLAYING, RuntimeState.PAUSING):
            self.run.step()
        if self.run.done and not self._closed:
            self._closed = True
            self.host.close()
            self.arm.stop_program()
        self.arm.step(self.step_time)
        self.cycles += 1
        self.history.append(list(self.arm.q))
        self.speeds.append(list(self.arm.qd))

    async def step(self, count: int) -> None:
        """Run ``count`` cycles, the event loop taking one turn after each."""
        async with asyncio.timeout(WAIT_S):
            for _ in range(count):
                self.cycle()
                await asyncio.sleep(0)

    async def until(self, predicate: Callable[[], bool], max_cycles: int = MAX_CYCLES) -> int:
        """Run cycles until ``predicate()`` holds after one; the number of cycles run so far."""
        async with asyncio.timeout(WAIT_S):
            for _ in range(max_cycles):
                if predicate():
                    return self.cycles
                self.cycle()
                await asyncio.sleep(0)
        if predicate():
            return self.cycles
        raise AssertionError(f"not within {max_cycles} cycles; messages: {self.texts()[-8:]}")

    async def said_within(self, needle: str, max_cycles: int = MAX_CYCLES) -> None:
        await self.until(lambda: self.said(needle), max_cycles)

    async def result(self, max_cycles: int = MAX_CYCLES) -> TrajectoryResultCode:
        """The next trajectory result (the first one not taken yet)."""
        taken = self._taken
        await self.until(lambda: len(self.daemon.results) > taken, max_cycles)
        self._taken = taken + 1
        return self.daemon.results[taken]

    _taken = 0

    async def trajectory(self, *points: TrajectoryPoint) -> TrajectoryResultCode:
        """START(n) as urcl does it (START first, then the points); the trajectory's result."""
        self.daemon.send(TrajectoryControl(TrajectoryAction.START, len(points), timeout=0.0))
        self.daemon.send_points(*points)
        return await self.result()

    async def all_closed(self, max_cycles: int = MAX_CYCLES) -> None:
        await self.until(self.daemon.all_closed, max_cycles)

    def index_reached(self, target: Sequence[float], after: int = 0, tolerance: float = 1e-9) -> int:
        """Index in ``history`` of the first cycle (from ``after``) with the arm within ``tolerance``."""
        for index in range(after, len(self.history)):
            if max(abs(a - b) for a, b in zip(self.history[index], target, strict=True)) < tolerance:
                return index
        raise AssertionError(f"the arm never reached {target}")

    def first_motion(self, after: int = 0) -> int:
        """Index in ``history`` of the first cycle (from ``after``) in which the arm moved."""
        for index in range(max(after, 1), len(self.history)):
            if self.history[index] != self.history[index - 1]:
                return index
        raise AssertionError("the arm never moved")

    def last_motion(self, after: int = 0, tolerance: float = 0.0) -> int:
        """Index in ``history`` of the last cycle (from ``after``) in which the arm moved (a joint by more
        than ``tolerance``: float noise of a path that ends on its target is not a motion)."""
        history = self.history
        for index in range(len(history) - 1, max(after, 1) - 1, -1):
            if any(abs(a - b) > tolerance for a, b in zip(history[index], history[index - 1], strict=True)):
                return index
        raise AssertionError("the arm never moved")

    def at_rest(self) -> bool:
        return all(v == 0.0 for v in self.arm.qd)

    def variable(self, name: str) -> Any:
        """A program-level or global variable's value now."""
        return self.run.variable(name)


async def hold_servo(rig: Rig, q: Sequence[float], tolerance: float = 1e-9, max_cycles: int = 1000) -> int:
    """Send servo frame ``q`` every cycle until the arm is within ``tolerance`` of it, at rest within
    ``tolerance`` rad/s (servoj's gain and
    lookahead make the arm settle on a held setpoint, not reach it at once); the cycles it took."""
    for count in range(1, max_cycles + 1):
        rig.daemon.send(ServoJ(tuple(q), timeout=0.1))
        await rig.step(1)
        near = max(abs(a - b) for a, b in zip(rig.arm.q, q, strict=True)) < tolerance
        if near and max(abs(v) for v in rig.arm.qd) < tolerance:
            return count
    raise AssertionError(f"the arm did not settle on {list(q)} within {max_cycles} cycles")


def script_text(ports: dict[str, int], server_ip: str = "127.0.0.1", series: str = "e") -> str:
    version = VERSION if series == "e" else CB3_VERSION
    return render_control_script(
        ScriptParameters(
            server_ip,
            reverse_port=ports[REV],
            trajectory_port=ports[TRAJ],
            script_command_port=ports[SCRIPT],
            controller_version=(*version, 0),
        )
    )


def start_rig(daemon: Daemon, server_ip: str = "127.0.0.1", series: str = "e") -> Rig:
    arm = make_arm("ur10e" if series == "e" else "ur10")
    return Rig(daemon, arm, script_text(daemon.ports, server_ip, series), series)


async def connect(rig: Rig) -> None:
    """Run cycles until all three sockets are connected and the control loop is active."""
    await rig.until(lambda: all(e.is_set() for e in rig.daemon.connected.values()), 500)
    await rig.said_within("urdaemon: control active", 50)


@contextlib.asynccontextmanager
async def running_script(*, reverse_greeting: bytes = b"", series: str = "e") -> AsyncIterator[Rig]:
    """The rendered script, connected to a test daemon and in its control loop; closes everything after."""
    daemon = Daemon()
    if reverse_greeting:
        daemon.greeting[REV] = reverse_greeting
    for name in NAMES:
        await daemon.serve(name)
    rig = start_rig(daemon, series=series)
    try:
        await connect(rig)
        yield rig
    finally:
        if not rig.run.done:
            rig.run.stop()
        rig.host.close()
        await daemon.close()
