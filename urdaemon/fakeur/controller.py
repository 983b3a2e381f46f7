"""The fake UR controller: RTDE, primary, secondary and dashboard servers over one simulated arm.

It serves the real protocols (the robot side of ``urdaemon.protocols``) on one address, so several
fakes can use the standard ports side by side on 127.0.0.5, 127.0.0.6, … (the address is always given:
tests take theirs from a run-specific range, so two runs never meet on one). Its clock runs at the
controller rate (500 Hz e-Series, 125 Hz CB3); every cycle it steps the running control program and
the arm, then sends RTDE outputs to every client whose requested frequency is due (drift-free on the
controller's own time grid); the primary and secondary interfaces get the robot state at 10 Hz, the
real-time interface (30003) every cycle, encoded only while a client is connected.

Programs start in two ways, as on a real controller: a script arriving on the primary, secondary or
real-time interface (headless), or ``play`` on the dashboard with a loaded program: the default
External Control program (which, like the URCap, fetches the script from the daemon's script-sender
port) or a URScript file in the programs directory. Every script runs in the URScript interpreter
(``fakeur.urscript``), compiled first as a controller does: a ``def`` program replaces the running
one, a ``sec`` program runs beside it, bare lines run as a program of their own; a compile or
runtime error is a RUNTIME_EXCEPTION message naming line and column, and a program that does not
compile never starts.

No client can stall the controller: a request/response service stops reading a client that does not
read its replies (TCP flow control), a stream skips its messages to a client whose unsent backlog
passes ``MAX_BACKLOG_BYTES`` (it stays connected: ur_rtde sends scripts on 30003 and never reads
it), and scripts are handled one at a time between controller cycles.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import socket
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from urdaemon.backends.clock import TickClock, tick_clock
from urdaemon.description.urmodels import DhParameters, UrModel, load_ur_model
from urdaemon.errors import ProtocolError
from urdaemon.fakeur.arm import FakeArm, RuntimeState
from urdaemon.fakeur.faults import FaultInjector
from urdaemon.fakeur.urscript.host import InputRegisters, ScriptHost
from urdaemon.model import RobotMode, SafetyMode
from urdaemon.protocols import dashboard as dash
from urdaemon.protocols import primary as prim
from urdaemon.protocols import realtime as rt
from urdaemon.protocols import rtde
from urdaemon.protocols._buffer import Side
from urdaemon.protocols.rtde_variables import IN_USE, INPUT_VARIABLES, NOT_FOUND, OUTPUT_VARIABLES

__all__ = ["FakeController", "FakePorts"]

log = logging.getLogger("urdaemon.fakeur")

STATE_PERIOD_S = 0.1
"""Robot state on the primary/secondary interfaces: 10 Hz (ur-protocols.md §0)."""
READ_CHUNK = 4096
"""Bytes read from a client at a time: a few hundred requests at most are handled in one turn."""
SERIAL_NUMBER = "20235500001"
PROGRAMS_DIR = "/programs"
"""Where programs live when no directory is given (as on URSim); only the default program exists there."""
EXTERNAL_CONTROL_PROGRAM = "external_control.urp"
"""The default program: the External Control URCap's, which fetches its script from the daemon."""
DEFAULT_URCAP_PROGRAM = f"{PROGRAMS_DIR}/{EXTERNAL_CONTROL_PROGRAM}"
SCRIPT_SUFFIXES = (".script", ".urscript")
"""Program files the fake plays by running their text as URScript (a ``.urp`` is not readable here)."""
MAX_BACKLOG_BYTES = 1 << 20
"""A client that leaves more than this unsent (it does not read) misses messages until it catches up."""
CONTROLLER_COMMANDS = frozenset(prim.ControllerCommand)
"""The single-line commands a controller takes on its script ports besides URScript (§2.4 step 6)."""
KINEMATICS_CALIBRATED = 0
"""KINEMATICS_INFO ``calibration_status`` of a calibrated arm: what URSim sends (ur-protocols.md §2.2)."""


@dataclass(frozen=True, slots=True)
class FakePorts:
    """Ports the fake listens on (UR's standard ones by default)."""

    dashboard: int = 29999
    primary: int = 30001
    secondary: int = 30002
    realtime: int = 30003
    rtde: int = 30004


@dataclass
class _Script:
    """A program the interpreter runs: its name, its run (``ScriptRun``) and the host its builtins use."""

    name: str
    run: Any
    host: ScriptHost
    failure: str | None = None
    """Why the interpreter itself failed while running it (a bug there, not the program's error)."""


@dataclass
class _RtdeClient:
    conn: rtde.RtdeConnection
    writer: asyncio.StreamWriter
    period: float = 0.0
    next_due: float = 0.0
    streaming: bool = False
    getters: list[Callable[[FakeArm], Any]] = field(default_factory=list)
    inputs: dict[int, tuple[str, ...]] = field(default_factory=dict)


class SharedClock:
    """One clock for every fake controller in a process, instead of one each.

    ``slots`` spreads the controllers over the period: slot ``k`` ticks ``k·period/slots`` after
    slot 0, so with one controller per slot each sends its RTDE packages at its own phase, as
    independent controllers do (the daemon sees one package at a time, the worst case for it).
    With one slot every controller ticks in the same loop callback and their packages leave in
    one burst (cheapest for the fake: one wake-up per period for the whole cell).

    The clock is ``tick_clock``'s: a timerfd the loop wakes on (Linux), else a timing thread. A
    stall of up to one period does not cost any controller its package: each slot whose time
    passed still ticks, late and in order (``catch_up``); beyond that, cycles are skipped, as a
    controller that was not running would skip them.
    """

    def __init__(self, period: float, slots: int = 1) -> None:
        if slots < 1:
            raise ValueError(f"slots must be at least 1, got {slots}")
        self.period = period
        self.slots: list[list[Callable[[], None]]] = [[] for _ in range(slots)]
        self._next = 0
        self._clock: TickClock | None = None

    def add(self, tick: Callable[[], None], slot: int, loop: asyncio.AbstractEventLoop) -> None:
        """Tick ``tick`` once per period in ``slot`` (modulo the slot count); starts the clock."""
        self.slots[slot % len(self.slots)].append(tick)
        if self._clock is None:
            self._clock = tick_clock(
                self.period / len(self.slots), self._fire, loop, catch_up=len(self.slots)
            )
            self._clock.start()

    def remove(self, tick: Callable[[], None]) -> None:
        """Stop ticking ``tick``; the clock stops with the last one."""
        for ticks in self.slots:
            if tick in ticks:
                ticks.remove(tick)
        if self._clock is not None and not any(self.slots):
            self._clock.stop()
            self._clock = None

    def _fire(self) -> None:
        ticks = self.slots[self._next]
        self._next = (self._next + 1) % len(self.slots)
        for tick in ticks:
            tick()


class FakeController:
    """One fake UR controller serving ``model`` on ``address``."""

    def __init__(
        self,
        model: str | UrModel,
        *,
        address: str,
        ports: FakePorts | None = None,
        controller_version: tuple[int, int, int, int] = (5, 15, 0, 0),
        dh: DhParameters | None = None,
        initial_positions: Sequence[float] | None = None,
        powered: bool = False,
        urcap: tuple[str, int] | None = None,
        faults: FaultInjector | None = None,
        rtde_versions: tuple[int, ...] = (1, 2),
        programs: str | Path | None = None,
    ) -> None:
        self.model = load_ur_model(model) if isinstance(model, str) else model
        self.address = address
        self.ports = ports or FakePorts()
        self.controller_version = controller_version
        self.arm = FakeArm(
            self.model, dh or self.model.dh, initial_positions=initial_positions, powered=powered
        )
        self.rate_hz = 125.0 if controller_version[0] < 5 else 500.0
        self.step_time = 1.0 / self.rate_hz
        self.faults = faults or FaultInjector()
        self.rtde_versions = rtde_versions
        """RTDE protocol versions it accepts: ``(1,)`` is a controller that speaks only v1 (no output
        frequency, no recipe ids), which a client must fall back to when v2 is refused."""
        self.urcap = urcap
        """Where a loaded External Control program fetches its script: the daemon's script sender."""
        self.programs_dir = Path(programs) if programs is not None else None
        """Where ``load`` finds program files (relative names resolve under it); None: URSim's default
        directory, holding only the default External Control program."""
        base = str(self.programs_dir) if self.programs_dir is not None else PROGRAMS_DIR
        self.default_program = f"{base.rstrip('/')}/{EXTERNAL_CONTROL_PROGRAM}"
        self.loaded_program: str | None = self.default_program if urcap else None
        self.input_registers = InputRegisters()
        """RTDE input registers (``input_*_register_N``), apart from the output ones on ``arm.io``."""
        self.program_name: str | None = None
        self._script: _Script | None = None
        self._secondary: list[_Script] = []
        self._input_times: dict[str, float] = {}
        """Controller time each RTDE input variable last arrived (what the watchdogs check)."""
        self._release_when_idle = False
        """Brake release asked while powering on: release once the arm is IDLE (as URSim does)."""
        self._realtime_clients: list[tuple[rt.RealtimeConnection, asyncio.StreamWriter]] = []
        self._servers: list[asyncio.Server] = []
        self._tasks: set[asyncio.Task[Any]] = set()
        self._rtde_clients: list[_RtdeClient] = []
        self._input_owner: dict[str, _RtdeClient] = {}
        self._state_clients: list[tuple[prim.PrimaryConnection, asyncio.StreamWriter, str]] = []
        self._writers: dict[str, set[asyncio.StreamWriter]] = {}
        self._next_state = 0.0
        self._clock: asyncio.Task[None] | None = None
        self._shared_clock: tuple[SharedClock, int] | None = None
        """A clock shared with the other fakes of this process, and this fake's slot on it."""
        self.cycles = 0

    # ---- lifecycle ---------------------------------------------------------------------------------

    def use_clock(self, clock: SharedClock, slot: int) -> None:
        """Tick on ``clock`` (in ``slot``) instead of a clock of its own; call before ``start``."""
        if abs(clock.period - self.step_time) > 1e-12:
            raise ValueError(
                f"a clock of period {clock.period} s cannot tick a {self.step_time} s controller"
            )
        self._shared_clock = (clock, slot)

    async def start(self) -> None:
        """Listen on every port and start the controller clock."""
        handlers = (
            ("dashboard", self.ports.dashboard, self._serve_dashboard),
            ("primary", self.ports.primary, self._serve_primary),
            ("secondary", self.ports.secondary, self._serve_secondary),
            ("realtime", self.ports.realtime, self._serve_realtime),
            ("rtde", self.ports.rtde, self._serve_rtde),
        )
        for service, port, handler in handlers:
            server = await asyncio.start_server(
                self._guard(service, handler), self.address, port, reuse_address=True
            )
            self._servers.append(server)
        self._clock = asyncio.get_running_loop().create_task(self._run_clock())
        log.info(
            "fake %s (controller %s) on %s",
            self.model.model,
            ".".join(map(str, self.controller_version)),
            self.address,
        )

    async def close(self) -> None:
        """Stop serving: close every connection and server, stop the program and the clock."""
        self._end_scripts()
        for server in self._servers:
            server.close()
        for writers in self._writers.values():
            for writer in list(writers):
                writer.close()
        tasks = [t for t in (self._clock,) if t is not None] + list(self._tasks)
        for task in tasks:
            task.cancel()
        for task in tasks:
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task
        for server in self._servers:
            with contextlib.suppress(Exception):
                await server.wait_closed()
        self._servers.clear()

    async def __aenter__(self) -> FakeController:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    # ---- faults and operator actions (Python API) ----------------------------------------------------

    def drop(self, service: str) -> int:
        """Close every open connection of ``service`` (or ``*``); how many were closed."""
        closed = 0
        for name, writers in self._writers.items():
            if service in (name, "*"):
                for writer in list(writers):
                    writer.close()
                    closed += 1
        return closed

    def stall(self, seconds: float) -> None:
        """Send nothing on the RTDE and robot-state streams for ``seconds`` of controller time."""
        self.faults.stalled_until = self.arm.timestamp + seconds

    def protective_stop(self) -> None:
        """Trigger a protective stop (as if the arm hit something)."""
        self.arm.protective_stop()

    def emergency_stop(self) -> None:
        """Press the emergency stop."""
        self.arm.emergency_stop()

    def release_emergency_stop(self) -> None:
        """Release the emergency stop button."""
        self.arm.release_emergency_stop()

    def set_speed_slider(self, fraction: float) -> None:
        """Move the teach pendant's speed slider."""
        self.arm.speed_slider = min(max(float(fraction), 0.0), 1.0)

    # ---- the clock -----------------------------------------------------------------------------------

    async def _run_clock(self) -> None:
        clock, slot = self._shared_clock or (SharedClock(self.step_time), 0)  # alone: a clock of its own
        clock.add(self._tick, slot, asyncio.get_running_loop())
        try:
            await asyncio.Event().wait()  # until cancelled by close()
        finally:
            clock.remove(self._tick)

    def _tick(self) -> None:
        """One controller cycle: the programs (which read their sockets themselves), the arm, and
        whatever streams are due."""
        self._cycle()

    def _cycle(self) -> None:
        arm, dt = self.arm, self.step_time
        if self._script is not None or self._secondary:
            self._step_scripts()
        if self._release_when_idle and arm.robot_mode is RobotMode.IDLE:
            self._release_when_idle = False
            arm.brake_release()
        arm.step(dt)
        self.cycles += 1
        now = arm.timestamp
        if now < self.faults.stalled_until:
            return
        if self._realtime_clients:
            self._send_realtime()
        for client in self._rtde_clients:
            if client.streaming and now + 1e-9 >= client.next_due:
                client.next_due += client.period
                if client.next_due < now:  # fell behind (a stall): resume on the grid, no burst
                    client.next_due = now + client.period
                self._send_rtde(client, rtde.OutputData(tuple(get(arm) for get in client.getters)))
        if now + 1e-9 >= self._next_state:
            self._next_state = now + STATE_PERIOD_S
            if self._state_clients:
                state = self._robot_state()
                for conn, writer, service in self._state_clients:
                    self._send_primary(conn, writer, service, state)

    # ---- connection plumbing -------------------------------------------------------------------------

    def _guard(
        self, service: str, handler: Callable[[asyncio.StreamReader, asyncio.StreamWriter], Any]
    ) -> Callable[[asyncio.StreamReader, asyncio.StreamWriter], Any]:
        async def serve(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
            if self.faults.is_refused(service):
                writer.close()
                return
            sock = writer.get_extra_info("socket")
            if sock is not None:
                with contextlib.suppress(OSError):
                    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._writers.setdefault(service, set()).add(writer)
            try:
                await handler(reader, writer)
            except (ConnectionError, asyncio.IncompleteReadError):
                pass
            except ProtocolError as err:  # a client that breaks the protocol is dropped, as a real one is
                log.info("%s %s: dropping client: %s", self.address, service, err)
            finally:
                self._writers[service].discard(writer)
                writer.close()

        return serve

    def _write(self, service: str, writer: asyncio.StreamWriter, data: bytes) -> None:
        if not data or writer.is_closing():
            return
        if writer.transport.get_write_buffer_size() > MAX_BACKLOG_BYTES:
            return  # whole messages are skipped, so what it reads later is still well framed
        mangled = self.faults.mangle(service, data)
        if mangled.delay_s <= 0.0 and len(mangled.pieces) == 1:
            writer.write(mangled.pieces[0])
            return

        async def later() -> None:
            if mangled.delay_s > 0:
                await asyncio.sleep(mangled.delay_s)
            for piece in mangled.pieces:
                if writer.is_closing():
                    return
                writer.write(piece)
                await writer.drain()

        task = asyncio.get_running_loop().create_task(later())
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    # ---- RTDE (30004) ---------------------------------------------------------------------------------

    async def _serve_rtde(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        conn = rtde.RtdeConnection(Side.ROBOT)
        client = _RtdeClient(conn, writer)
        try:
            while data := await reader.read(READ_CHUNK):
                for event in conn.receive_data(data):
                    self._on_rtde(client, event)
                self._write("rtde", writer, conn.data_to_send())
                await _paced(writer, data)
        finally:
            client.streaming = False
            with contextlib.suppress(ValueError):
                self._rtde_clients.remove(client)
            for name in [n for n, owner in self._input_owner.items() if owner is client]:
                del self._input_owner[name]

    def _send_rtde(self, client: _RtdeClient, message: Any) -> None:
        try:
            client.conn.send(message)
        except ProtocolError as err:
            log.info("%s rtde: not sent: %s", self.address, err)
            return
        self._write("rtde", client.writer, client.conn.data_to_send())

    def _on_rtde(self, client: _RtdeClient, event: Any) -> None:
        conn = client.conn
        if isinstance(event, rtde.ProtocolVersionRequested):
            conn.send(rtde.ProtocolVersionAccept(event.version in self.rtde_versions))
        elif isinstance(event, rtde.ControllerVersionRequested):
            conn.send(rtde.ControllerVersionReply(*self.controller_version))
        elif isinstance(event, rtde.SetupOutputsRequested):
            self._setup_outputs(client, event)
        elif isinstance(event, rtde.SetupInputsRequested):
            names = _names(event.names)
            types = []
            for name in names:
                owner = self._input_owner.get(name)
                if name not in INPUT_VARIABLES:
                    types.append(NOT_FOUND)
                elif owner is not None and owner is not client:
                    types.append(IN_USE)
                else:
                    types.append(INPUT_VARIABLES[name])
            ok = all(t not in (NOT_FOUND, IN_USE) for t in types)
            recipe_id = len(client.inputs) + 1 if ok else 0
            if ok:
                client.inputs[recipe_id] = names
                for name in names:
                    self._input_owner[name] = client
            conn.send(rtde.InputsSetup(recipe_id, tuple(types)))
        elif isinstance(event, rtde.StartRequested):
            ok = bool(client.getters)
            conn.send(rtde.StartAccept(ok))
            if ok and not client.streaming:
                client.streaming = True
                client.next_due = self.arm.timestamp + client.period
                if client not in self._rtde_clients:
                    self._rtde_clients.append(client)
        elif isinstance(event, rtde.PauseRequested):
            client.streaming = False
            conn.send(rtde.PauseAccept(True))
        elif isinstance(event, rtde.InputDataReceived):
            input_names = client.inputs.get(event.recipe_id)
            if input_names is not None:
                self._apply_inputs(dict(zip(input_names, event.values, strict=True)))
        elif isinstance(event, rtde.TextReceived):
            log.info("%s rtde text from client: %s", self.address, event.message)

    def _setup_outputs(self, client: _RtdeClient, event: rtde.SetupOutputsRequested) -> None:
        frequency = event.frequency if event.frequency is not None else self.rate_hz
        names = _names(event.names)
        types = tuple(OUTPUT_VARIABLES.get(name, NOT_FOUND) for name in names)
        # A real controller refuses a frequency it cannot serve: no recipe (id 0), all NOT_FOUND.
        if not (0 < frequency <= self.rate_hz) or NOT_FOUND in types:
            client.getters = []
            client.conn.send(rtde.OutputsSetup(0 if event.frequency is not None else None, types))
            return
        client.period = 1.0 / frequency
        client.getters = [
            _output_getter(name, OUTPUT_VARIABLES[name], self.input_registers) for name in names
        ]
        client.conn.send(rtde.OutputsSetup(1 if event.frequency is not None else None, types))

    def _apply_inputs(self, values: dict[str, Any]) -> None:
        arm, io = self.arm, self.arm.io
        now = arm.timestamp
        for name in values:
            self._input_times[name] = now
        if values.get("speed_slider_mask"):
            self.set_speed_slider(float(values.get("speed_slider_fraction", arm.speed_slider)))
        for kind, shift in (("standard", 0), ("configurable", 8), ("tool", 16)):
            mask = int(values.get(f"{kind}_digital_output_mask", 0)) & 0xFF
            if mask:
                value = int(values.get(f"{kind}_digital_output", 0)) & mask
                io.digital_out = (io.digital_out & ~(mask << shift)) | (value << shift)
        analog_mask = int(values.get("standard_analog_output_mask", 0))
        for pin in (0, 1):
            if analog_mask & (1 << pin):
                io.analog_out[pin] = float(values.get(f"standard_analog_output_{pin}", 0.0))
                if (int(values.get("standard_analog_output_type", 0)) >> pin) & 1:
                    io.analog_out_types |= 1 << (pin + 2)
                else:
                    io.analog_out_types &= ~(1 << (pin + 2))
        registers = self.input_registers
        for name, value in values.items():
            if name.startswith("input_int_register_"):
                registers.ints[int(name.rsplit("_", 1)[1])] = int(value)
            elif name.startswith("input_double_register_"):
                registers.doubles[int(name.rsplit("_", 1)[1])] = float(value)
            elif name.startswith("input_bit_register_"):
                registers.bits[int(name.rsplit("_", 1)[1])] = bool(value)

    # ---- primary (30001) and secondary (30002) ------------------------------------------------------

    async def _serve_primary(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        await self._serve_state(reader, writer, "primary")

    async def _serve_secondary(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        await self._serve_state(reader, writer, "secondary")

    async def _serve_state(
        self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, service: str
    ) -> None:
        conn = prim.PrimaryConnection(Side.ROBOT)
        major, minor, bugfix, build = self.controller_version
        self._send_primary(
            conn,
            writer,
            service,
            prim.VersionMessage("URControl", major, minor, bugfix, build, "01-01-2026, 00:00:00"),
        )
        entry = (conn, writer, service)
        self._state_clients.append(entry)  # the state follows on the controller's 10 Hz grid
        try:
            await self._read_scripts(reader, writer, conn)
        finally:
            self._state_clients.remove(entry)

    async def _read_scripts(
        self,
        reader: asyncio.StreamReader,
        writer: asyncio.StreamWriter,
        conn: prim.PrimaryConnection | rt.RealtimeConnection,
    ) -> None:
        """Run the scripts a client sends, one at a time: between two, the controller's cycles and
        other clients get their turn. Scripts get no replies, so reading never waits on the client
        reading (ur_rtde reads nothing of 30003, where it sends its scripts)."""
        while data := await reader.read(READ_CHUNK):
            for event in conn.receive_data(data):
                if isinstance(event, prim.CommandReceived | prim.ProgramReceived):
                    self._on_script(event)
                    await asyncio.sleep(0)

    # ---- real-time interface (30003) ---------------------------------------------------------------

    async def _serve_realtime(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        conn = rt.RealtimeConnection(Side.ROBOT, self.controller_version)
        entry = (conn, writer)
        self._realtime_clients.append(entry)  # the state follows every controller cycle
        try:
            await self._read_scripts(reader, writer, conn)
        finally:
            self._realtime_clients.remove(entry)

    def _send_realtime(self) -> None:
        state = self._realtime_state()
        for conn, writer in self._realtime_clients:
            conn.send(state)
            self._write("realtime", writer, conn.data_to_send())

    def _realtime_state(self) -> rt.RealtimeState:
        arm = self.arm
        q, qd, qdd = tuple(arm.q), tuple(arm.qd), tuple(arm.qdd)
        pose = arm.actual_tcp_pose()
        running = arm.robot_mode is RobotMode.RUNNING
        program_state = {RuntimeState.PLAYING: 2.0, RuntimeState.PAUSED: 3.0}.get(arm.runtime_state, 1.0)
        return rt.RealtimeState(
            time=arm.timestamp,
            q_target=q,
            qd_target=qd,
            qdd_target=qdd,
            i_target=tuple(arm.current),
            q_actual=q,
            qd_actual=qd,
            i_actual=tuple(arm.current),
            i_control=tuple(arm.current),
            tool_vector_actual=pose,
            tool_vector_target=pose,
            digital_input_bits=float(arm.io.digital_in),
            motor_temperatures=(30.0,) * 6,
            controller_timer=0.0002,
            robot_mode=float(arm.robot_mode),
            joint_modes=(253.0 if running else 255.0,) * 6,
            safety_mode=float(arm.safety_mode),
            tool_accelerometer_values=(0.0, 0.0, 9.82),
            speed_scaling=arm.speed_scaling,
            v_main=48.0,
            v_robot=48.0 if running else 0.0,
            v_actual=(48.0 if running else 0.0,) * 6,
            digital_outputs=float(arm.io.digital_out),
            program_state=program_state,
            safety_status=float(arm.safety_mode),
            payload_mass=arm.payload_mass,
            payload_cog=tuple(arm.payload_cog),
            payload_inertia=tuple(arm.payload_inertia),
        )

    def _send_primary(
        self, conn: prim.PrimaryConnection, writer: asyncio.StreamWriter, service: str, message: Any
    ) -> None:
        conn.send(message)
        self._write(service, writer, conn.data_to_send())

    def _broadcast(self, message: Any) -> None:
        """Send a robot message to every primary client (the secondary interface gets only state)."""
        for conn, writer, service in self._state_clients:
            if service == "primary":
                self._send_primary(conn, writer, service, message)

    def _on_script(self, event: prim.CommandReceived | prim.ProgramReceived) -> None:
        if isinstance(event, prim.CommandReceived):
            line = event.line.strip()
            if line in CONTROLLER_COMMANDS:
                self._controller_command(line)
            else:
                self._start_program("script", line + "\n")
        else:
            self._start_program(event.name, event.text)

    def _controller_command(self, line: str) -> None:
        arm = self.arm
        if line == prim.ControllerCommand.POWER_ON:
            arm.power_on()
        elif line == prim.ControllerCommand.POWER_OFF:
            self._stop_program()
            arm.power_off()
        elif line == prim.ControllerCommand.BRAKE_RELEASE:
            self._brake_release()
        elif line == prim.ControllerCommand.UNLOCK_PROTECTIVE_STOP:
            arm.unlock_protective_stop()
        elif line == prim.ControllerCommand.STOP_PROGRAM:
            self._stop_program()

    def _brake_release(self) -> str | None:
        """Release the brakes; from POWER_OFF power on first, then release once IDLE (as URSim does)."""
        arm = self.arm
        if arm.robot_mode in (RobotMode.POWER_OFF, RobotMode.BOOTING):
            reason = arm.power_on()
            if reason is None:
                self._release_when_idle = True
            return reason
        return arm.brake_release()

    # ---- programs ----------------------------------------------------------------------------------------

    def _stop_program(self) -> None:
        self._end_scripts()
        self.arm.stop_program()

    # ---- programs in the interpreter ---------------------------------------------------------------

    def _start_program(self, name: str, text: str) -> None:
        """Compile ``text``; a ``sec`` program runs beside the main one, any other replaces it."""
        from urdaemon.fakeur.urscript import ScriptCompileError, compile_program

        major, minor = self.controller_version[:2]
        try:
            program = compile_program(text, series="e" if major >= 5 else "cb3", version=(major, minor))
        except ScriptCompileError as err:
            self._broadcast(prim.RuntimeExceptionMessage(err.line, err.column, err.message))
            return
        if program.kind == "sec":
            host = self._script_host()
            self._secondary.append(_Script(name, program.start(host), host))
            return
        if self._script is not None:
            self._end_script(self._script)
        reason = self.arm.start_program()
        if reason is not None:
            self._broadcast(prim.TextMessage(f"program {name} not started: {reason}"))
            return
        host = self._script_host()
        self._script = _Script(name, program.start(host), host)
        self.program_name = name
        self._broadcast(prim.KeyMessage(0, 0, "PROGRAM_XXX_STARTED", name))

    def _script_host(self) -> ScriptHost:
        major, minor = self.controller_version[:2]
        return ScriptHost(
            self.arm,
            step_time=self.step_time,
            series="e" if major >= 5 else "cb3",
            version=(major, minor),
            local_address=self.address,  # a real robot's connections come from its own address
            message=self._script_message,
            input_registers=self.input_registers,
        )

    def _script_message(self, kind: str, text: str) -> None:
        if kind == "popup":
            self._broadcast(prim.popup_message(text))
        elif kind == "runtime":
            self._broadcast(prim.RuntimeExceptionMessage(0, 0, text))
        else:
            self._broadcast(prim.TextMessage(text))

    def _step_scripts(self) -> None:
        """One cycle of the programs: the main one while it plays or pauses (not once paused), then every
        ``sec`` program; a program that has ended is closed; the main one's RTDE watchdogs are checked."""
        script = self._script
        if script is not None:
            state = self.arm.runtime_state
            if state is RuntimeState.PLAYING or state is RuntimeState.PAUSING:
                # while pausing the program's motion goes on in time slowed to 0 along its path
                self._step(script)
                if script.run.done or script.failure is not None:
                    self._end_script(script)
                elif state is RuntimeState.PLAYING:
                    self._check_watchdogs(script)
            elif state is RuntimeState.STOPPED:  # stopped from outside: power off, stop, ...
                self._end_script(script)
        for sec in list(self._secondary):
            self._step(sec)
            if sec.run.done or sec.failure is not None:
                self._end_script(sec)

    def _step(self, script: _Script) -> None:
        try:
            script.run.step()
        except Exception as err:  # the interpreter's own fault ends this program, not the controller
            log.exception("%s program %s: the interpreter failed", self.address, script.name)
            script.failure = f"{type(err).__name__}: {err}"

    def _check_watchdogs(self, script: _Script) -> None:
        watchdogs = script.host.watchdogs
        if not watchdogs:
            return
        now = self.arm.timestamp
        for watchdog in list(watchdogs.values()):
            if watchdog.min_frequency <= 0 or watchdog.action == "ignore":
                continue
            last = max(self._input_times.get(watchdog.variable, -math.inf), watchdog.since)
            if now - last <= 1.0 / watchdog.min_frequency + 1e-9:
                continue
            text = f"RTDE watchdog: {watchdog.variable} not updated at {watchdog.min_frequency:g} Hz"
            self._broadcast(prim.TextMessage(text))
            if watchdog.action == "pause":
                self.arm.pause_program()
            else:
                self._stop_program()
            return

    def _end_script(self, script: _Script) -> None:
        """``script`` ends (by itself, by an error or stopped): report why, close what it opened."""
        run = script.run
        if not run.done:
            with contextlib.suppress(Exception):
                run.stop()
        script.host.close()
        error = run.error
        if error is not None:
            self._broadcast(prim.RuntimeExceptionMessage(error.line, error.column, error.message))
        elif script.failure is not None:
            self._broadcast(prim.RuntimeExceptionMessage(0, 0, script.failure))
        if script in self._secondary:
            self._secondary.remove(script)
            return
        if self._script is script:
            self._script = None
            self.arm.stop_program()
        log.info("%s program %s ended", self.address, script.name)
        self._broadcast(prim.KeyMessage(0, 0, "PROGRAM_XXX_STOPPED", script.name))

    def _end_scripts(self) -> None:
        for script in [*self._secondary, *([self._script] if self._script is not None else [])]:
            self._end_script(script)

    async def _play_urcap(self) -> None:
        """What the External Control URCap does on play: fetch the script, then run it."""
        if self.urcap is None:
            return
        host, port = self.urcap
        try:
            reader, writer = await asyncio.wait_for(
                asyncio.open_connection(host, port, local_addr=(self.address, 0)), 5.0
            )
        except (OSError, TimeoutError) as err:
            self._broadcast(
                prim.TextMessage(
                    f"External Control: connection to {host}:{port} could not be established: {err}"
                )
            )
            self.arm.stop_program()
            return
        try:
            writer.write(b"request_program\n")
            await writer.drain()
            chunks = [await asyncio.wait_for(reader.readline(), 5.0)]
            # the URCap keeps reading lines only while data is already buffered (ur-protocols.md §4.3)
            while True:
                try:
                    line = await asyncio.wait_for(reader.readline(), 0.2)
                except TimeoutError:
                    break
                if not line:
                    break
                chunks.append(line)
        finally:
            writer.close()
        text = b"".join(chunks).decode("utf-8", "replace")
        self.arm.runtime_state = RuntimeState.STOPPED
        self._start_program("externalControl", text)

    # ---- dashboard (29999) ------------------------------------------------------------------------------

    async def _serve_dashboard(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        conn = dash.DashboardConnection(Side.ROBOT)
        conn.send(dash.Banner())
        self._write("dashboard", writer, conn.data_to_send())
        while data := await reader.read(READ_CHUNK):
            for event in conn.receive_data(data):
                if isinstance(event, dash.CommandReceived):
                    reply = self._dashboard_reply(event.command)
                elif isinstance(event, dash.UnknownCommand):
                    reply = dash.unknown_command_text(event.line)
                else:  # the robot side receives nothing else
                    continue
                conn.send(dash.ReplyLine(reply))
                self._write("dashboard", writer, conn.data_to_send())
                await asyncio.sleep(0)  # one command per turn: a flood of them delays no cycle
                if isinstance(event, dash.CommandReceived) and isinstance(
                    event.command, dash.Quit | dash.Shutdown
                ):
                    await writer.drain()
                    return
            await _paced(writer, data)

    def _dashboard_reply(self, command: Any) -> str:
        arm = self.arm
        program = self.loaded_program
        if isinstance(command, dash.PowerOn):
            return "Powering on" if arm.power_on() is None else "Failed to execute: power on"
        if isinstance(command, dash.PowerOff):
            self._stop_program()
            arm.power_off()
            return "Powering off"
        if isinstance(command, dash.BrakeRelease):
            return "Brake releasing" if self._brake_release() is None else "Failed to execute: brake release"
        if isinstance(command, dash.UnlockProtectiveStop):
            return (
                "Protective stop releasing"
                if arm.unlock_protective_stop() is None
                else ("Cannot unlock protective stop: the robot is not in protective stop or still moving")
            )
        if isinstance(command, dash.Load):
            path = self._program_path(command.path)
            if path is None:
                return f"File not found: {command.path}"
            self._stop_program()
            self.loaded_program = path
            return f"Loading program: {path}"
        if isinstance(command, dash.Play):
            return "Starting program" if self._play() is None else "Failed to execute: play"
        if isinstance(command, dash.RestartSafety):
            self._stop_program()
            arm.power_off()
            if arm.safety_mode not in (SafetyMode.ROBOT_EMERGENCY_STOP, SafetyMode.SYSTEM_EMERGENCY_STOP):
                arm.safety_mode = SafetyMode.NORMAL
            return "Restarting safety"
        if isinstance(command, dash.IsProgramSaved):
            return dash.program_saved_text(program is not None, _basename(program))
        if isinstance(command, dash.GetOperationalMode) and self.controller_version[0] >= 5:
            return dash.operational_mode_text(dash.OperationalMode.NONE)  # no mode password set
        if isinstance(command, dash.GetUserRole) and self.controller_version[0] < 5:
            return dash.user_role_text(dash.UserRole.PROGRAMMER)  # no user password set
        if isinstance(command, dash.Pause):
            if arm.runtime_state is not RuntimeState.PLAYING:
                return "Failed to execute: pause"
            arm.pause_program()
            return "Pausing program"
        if isinstance(command, dash.Stop):
            if arm.runtime_state is RuntimeState.STOPPED:
                return "Failed to execute: stop"
            self._stop_program()
            return "Stopped"
        if isinstance(command, dash.GetRobotMode):
            return dash.robot_mode_text(arm.robot_mode)
        if isinstance(command, dash.GetSafetyMode):
            return dash.safety_mode_text(arm.safety_mode)
        if isinstance(command, dash.GetSafetyStatus):
            return dash.safety_status_text(arm.safety_mode)
        if isinstance(command, dash.GetProgramState):
            state = {
                RuntimeState.PLAYING: dash.ProgramState.PLAYING,
                RuntimeState.PAUSED: dash.ProgramState.PAUSED,
            }.get(arm.runtime_state, dash.ProgramState.STOPPED)
            return dash.program_state_text(state, _basename(program))
        if isinstance(command, dash.IsRunning):
            return dash.running_text(arm.program_running)
        if isinstance(command, dash.GetLoadedProgram):
            return dash.loaded_program_text(program)
        if isinstance(command, dash.IsInRemoteControl):
            return dash.remote_control_text(arm.remote_control)
        if isinstance(command, dash.GetPolyscopeVersion):
            return dash.polyscope_version_text(self.controller_version, "Jan 01 2026")
        if isinstance(command, dash.GetVersion):
            return dash.version_text(self.controller_version)
        if isinstance(command, dash.GetSerialNumber):
            return SERIAL_NUMBER
        if isinstance(command, dash.GetRobotModel):
            return self.model.model.upper().removesuffix("E")
        if isinstance(command, dash.GetOperationalMode | dash.GetUserRole):  # not on this series
            return dash.unknown_command_text(command.KEYWORD)
        if isinstance(command, dash.Quit):
            return "Disconnected"
        if isinstance(command, dash.Shutdown):
            arm.power_off()
            return "Shutting down"
        success = getattr(command, "success_text", None)
        return (
            success if isinstance(success, str) else dash.unknown_command_text(getattr(command, "line", ""))
        )

    def _program_path(self, name: str) -> str | None:
        """The program file ``name`` stands for (relative names under the programs directory), or None
        if there is no such file. The default External Control program always exists."""
        base = str(self.programs_dir) if self.programs_dir is not None else PROGRAMS_DIR
        path = name if name.startswith("/") else f"{base.rstrip('/')}/{name}"
        if path == self.default_program:
            return path
        if self.programs_dir is None or not Path(path).is_file():
            return None
        return path

    def _play(self) -> str | None:
        """``play``: resume a paused program, or start the loaded one; a reason if it cannot."""
        arm, program = self.arm, self.loaded_program
        if program is None:  # a headless program (sent, not loaded) cannot be played, not even resumed
            return "no program loaded"
        if arm.runtime_state is RuntimeState.PAUSED:
            return arm.resume_program()
        if program != self.default_program and not program.endswith(SCRIPT_SUFFIXES):
            return f"{program}: the fake plays only URScript files and the External Control program"
        reason = arm.start_program()
        if reason is not None or self._script is not None:
            return reason
        if program == self.default_program:
            task = asyncio.get_running_loop().create_task(self._play_urcap())
            self._tasks.add(task)
            task.add_done_callback(self._tasks.discard)
            return None
        try:
            text = Path(program).read_text(encoding="ascii")
        except (OSError, UnicodeDecodeError) as err:
            arm.stop_program()
            return str(err)
        arm.runtime_state = RuntimeState.STOPPED
        self._start_program(_basename(program) or program, text)
        return None

    # ---- robot state ---------------------------------------------------------------------------------

    def _robot_state(self) -> prim.RobotState:
        arm = self.arm
        dh = arm.dh
        q = tuple(arm.q)
        powered = arm.robot_mode in (RobotMode.IDLE, RobotMode.RUNNING, RobotMode.POWER_ON)
        running_modes = 253 if arm.robot_mode is RobotMode.RUNNING else 255 if powered else 239
        return prim.RobotState(
            (
                prim.RobotModeData(
                    timestamp=int(arm.timestamp * 1000),
                    is_real_robot_connected=True,
                    is_real_robot_enabled=True,
                    is_robot_power_on=powered,
                    is_emergency_stopped=arm.safety_mode
                    in (SafetyMode.ROBOT_EMERGENCY_STOP, SafetyMode.SYSTEM_EMERGENCY_STOP),
                    is_protective_stopped=arm.safety_mode is SafetyMode.PROTECTIVE_STOP,
                    is_program_running=arm.program_running,
                    is_program_paused=arm.runtime_state is RuntimeState.PAUSED,
                    robot_mode=int(arm.robot_mode),
                    control_mode=0,
                    target_speed_fraction=arm.speed_slider,
                    speed_scaling=arm.speed_scaling,
                    target_speed_fraction_limit=1.0,
                    reserved=0 if self.controller_version[0] >= 5 else None,  # CB3: 46 bytes
                ),
                prim.JointData(
                    q_actual=q,
                    q_target=q,
                    qd_actual=tuple(arm.qd),
                    i_actual=tuple(arm.current),
                    v_actual=(48.0,) * 6,
                    t_motor=(30.0,) * 6,
                    t_micro=(30.0,) * 6,
                    joint_mode=(running_modes,) * 6,
                ),
                prim.CartesianInfo(tcp_pose=arm.actual_tcp_pose(), tcp_offset=tuple(arm.tcp_offset)),
                prim.KinematicsInfo(
                    checksum=(0xFFFFFFFF,) * 6,
                    dh_theta=dh.theta,
                    dh_a=dh.a,
                    dh_d=dh.d,
                    dh_alpha=dh.alpha,
                    calibration_status=KINEMATICS_CALIBRATED,
                ),
                prim.MasterboardData(
                    digital_input_bits=arm.io.digital_in & 0xFFFF,
                    digital_output_bits=arm.io.digital_out & 0xFFFF,
                    analog_output0=arm.io.analog_out[0],
                    analog_output1=arm.io.analog_out[1],
                    robot_voltage_48v=48.0 if powered else 0.0,
                    safety_mode=int(arm.safety_mode),
                ),
                prim.ToolData(tool_output_voltage=arm.io.tool_voltage, tool_mode=running_modes),
                prim.ConfigurationData(
                    joint_min_limit=tuple(max(v, -6.335) for v in arm.min_position),
                    joint_max_limit=tuple(min(v, 6.335) for v in arm.max_position),
                    joint_max_speed=tuple(arm.max_velocity),
                    joint_max_acceleration=(40.0,) * 6,
                    v_joint_default=1.0472,
                    a_joint_default=1.3963,
                    v_tool_default=0.25,
                    a_tool_default=1.2,
                    eq_radius=0.25,
                    dh_a=dh.a,
                    dh_d=dh.d,
                    dh_alpha=dh.alpha,
                    dh_theta=dh.theta,
                    masterboard_version=6,
                    controller_box_type=4 if self.controller_version[0] >= 5 else 2,
                    robot_type=self.model.robot_type,
                    robot_sub_type=3 if self.controller_version[0] >= 5 else 2,
                ),
                prim.ForceModeData(),
                prim.AdditionalInfo(),
            )
        )


async def _paced(writer: asyncio.StreamWriter, data: bytes) -> None:
    """After handling one read: wait while the client does not read its replies (TCP flow control:
    it is not read meanwhile), and give others a turn when more is waiting (a full read)."""
    await writer.drain()
    if len(data) >= READ_CHUNK:
        await asyncio.sleep(0)


def _names(requested: tuple[str, ...]) -> tuple[str, ...]:
    """The requested variable names (an empty one, from ``a,,b``, is answered NOT_FOUND like any unknown)."""
    return requested


def _basename(path: str | None) -> str | None:
    return None if path is None else path.rsplit("/", 1)[-1]


def _output_getter(name: str, rtde_type: str, inputs: InputRegisters) -> Callable[[FakeArm], Any]:
    """How to read output ``name`` off the arm (zero of its type for what the fake does not model)."""
    getter = _OUTPUTS.get(name)
    if getter is not None:
        return getter
    if name.startswith("input_int_register_"):
        at = int(name.rsplit("_", 1)[1])
        return lambda arm: inputs.ints.get(at, 0)
    if name.startswith("input_double_register_"):
        at = int(name.rsplit("_", 1)[1])
        return lambda arm: inputs.doubles.get(at, 0.0)
    if name.startswith("input_bit_register_"):
        at = int(name.rsplit("_", 1)[1])
        return lambda arm: inputs.bits.get(at, False)
    if name.startswith("output_int_register_"):
        index = int(name.rsplit("_", 1)[1])
        return lambda arm: arm.io.registers_int.get(index, 0)
    if name.startswith("output_double_register_"):
        index = int(name.rsplit("_", 1)[1])
        return lambda arm: arm.io.registers_double.get(index, 0.0)
    if name.startswith("output_bit_register_"):
        index = int(name.rsplit("_", 1)[1])
        return lambda arm: arm.io.registers_bit.get(index, False)
    zero = _ZEROS[rtde_type]
    return lambda arm: zero


_ZEROS: dict[str, Any] = {
    "BOOL": False,
    "UINT8": 0,
    "UINT32": 0,
    "UINT64": 0,
    "INT32": 0,
    "DOUBLE": 0.0,
    "VECTOR3D": (0.0, 0.0, 0.0),
    "VECTOR6D": (0.0,) * 6,
    "VECTOR6INT32": (0,) * 6,
    "VECTOR6UINT32": (0,) * 6,
}

_OUTPUTS: dict[str, Callable[[FakeArm], Any]] = {
    "timestamp": lambda arm: arm.timestamp,
    "actual_q": lambda arm: tuple(arm.q),
    "actual_qd": lambda arm: tuple(arm.qd),
    "actual_qdd": lambda arm: tuple(arm.qdd),
    "target_q": lambda arm: tuple(arm.q),
    "target_qd": lambda arm: tuple(arm.qd),
    "target_qdd": lambda arm: tuple(arm.qdd),
    "actual_current": lambda arm: tuple(arm.current),
    "target_current": lambda arm: tuple(arm.current),
    "joint_temperatures": lambda arm: (30.0,) * 6,
    "joint_mode": lambda arm: (253 if arm.robot_mode is RobotMode.RUNNING else 255,) * 6,
    "speed_scaling": lambda arm: arm.speed_scaling,
    "target_speed_fraction": lambda arm: arm.speed_slider,
    "runtime_state": lambda arm: int(arm.runtime_state),
    "actual_TCP_pose": lambda arm: arm.actual_tcp_pose(),
    "target_TCP_pose": lambda arm: arm.actual_tcp_pose(),
    "actual_TCP_speed": lambda arm: (0.0,) * 6,
    "actual_TCP_force": lambda arm: (0.0,) * 6,
    "actual_digital_input_bits": lambda arm: arm.io.digital_in,
    "actual_digital_output_bits": lambda arm: arm.io.digital_out,
    "standard_analog_input0": lambda arm: arm.io.analog_in[0],
    "standard_analog_input1": lambda arm: arm.io.analog_in[1],
    "standard_analog_output0": lambda arm: arm.io.analog_out[0],
    "standard_analog_output1": lambda arm: arm.io.analog_out[1],
    "analog_io_types": lambda arm: arm.io.analog_out_types,
    "tool_analog_input0": lambda arm: arm.io.tool_analog_in[0],
    "tool_analog_input1": lambda arm: arm.io.tool_analog_in[1],
    "tool_output_voltage": lambda arm: arm.io.tool_voltage,
    "tool_mode": lambda arm: 253 if arm.robot_mode is RobotMode.RUNNING else 255,
    "tool_temperature": lambda arm: 30.0,
    "robot_mode": lambda arm: int(arm.robot_mode),
    "safety_mode": lambda arm: int(arm.safety_mode),
    "safety_status": lambda arm: int(arm.safety_mode),
    "robot_status_bits": lambda arm: arm.robot_status_bits,
    "safety_status_bits": lambda arm: arm.safety_status_bits,
    "tcp_offset": lambda arm: tuple(arm.tcp_offset),
    "payload": lambda arm: arm.payload_mass,
    "payload_cog": lambda arm: tuple(arm.payload_cog),
    "payload_inertia": lambda arm: tuple(arm.payload_inertia),
    "actual_main_voltage": lambda arm: 48.0,
    "actual_robot_voltage": lambda arm: 48.0,
    "actual_robot_current": lambda arm: 0.5,
    "actual_joint_voltage": lambda arm: (48.0,) * 6,
    "actual_execution_time": lambda arm: 0.1,
}
