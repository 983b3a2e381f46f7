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
read its replies, a stream skips its messages to a client that does not read (``fakeur.connections``),
and scripts are compiled off the event loop (``fakeur.programs``).

The controller composes one job per module: ``programs`` (the programs it runs), ``rtde_service``
(30004), ``reports`` (what it reports of the arm), ``dashboard_answers`` (29999's replies and
``play``), ``connections`` (each client's shell and the writes), ``clock`` (the shared clock). This
module keeps the robot's life: the ports, the cycle, the script ports and the controller commands.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from urdaemon.description.urmodels import DhParameters, UrModel, load_ur_model
from urdaemon.fakeur.connections import Connections, ServiceShell
from urdaemon.fakeur.dashboard_answers import PROGRAMS_DIR, dashboard_answer
from urdaemon.fakeur.fake_arm import FakeArm
from urdaemon.fakeur.faults import FaultInjector
from urdaemon.fakeur.life import UNLOCK_TOO_SOON
from urdaemon.fakeur.programs import Programs
from urdaemon.fakeur.reports import realtime_state, robot_state
from urdaemon.fakeur.rtde_service import RtdeService
from urdaemon.fakeur.shared_clock import SharedClock
from urdaemon.fakeur.urscript.script_host import InputRegisters
from urdaemon.model import RobotMode
from urdaemon.protocols import dashboard as dash
from urdaemon.protocols import primary as prim
from urdaemon.protocols import realtime as rt
from urdaemon.protocols._buffer import Side
from urdaemon.protocols.rtde import RTDE_PORT, max_frequency
from urdaemon.shell import Shell, serve

__all__ = ["FakeController", "FakePorts"]

log = logging.getLogger("urdaemon.fakeur")

STATE_PERIOD_S = 0.1
"""Robot state on the primary/secondary interfaces: 10 Hz (docs/protocols.md §0)."""
EXTERNAL_CONTROL_PROGRAM = "external_control.urp"
"""The default program: the External Control URCap's, which fetches its script from the daemon."""
DEFAULT_URCAP_PROGRAM = f"{PROGRAMS_DIR}/{EXTERNAL_CONTROL_PROGRAM}"
CONTROLLER_COMMANDS = frozenset(prim.ControllerCommand)
"""The single-line commands a controller takes on its script ports besides URScript (§2.4 step 6)."""


@dataclass(frozen=True, slots=True)
class FakePorts:
    """Ports the fake listens on (UR's standard ones by default)."""

    dashboard: int = dash.DASHBOARD_PORT
    primary: int = prim.PRIMARY_PORT
    secondary: int = prim.SECONDARY_PORT
    realtime: int = rt.REALTIME_PORT
    rtde: int = RTDE_PORT


def _serving_parts(
    fake: FakeController, address: str, rtde_versions: tuple[int, ...]
) -> tuple[Connections, Programs, RtdeService]:
    """The parts of ``fake`` that serve its clients: the connections (with their faults), the programs
    it runs (and the scripts waiting to be compiled), and the RTDE interface (recipes, the output
    stream, the inputs)."""
    connections = Connections(address, fake.faults)
    programs = Programs(
        fake.arm,
        controller_version=fake.controller_version,
        step_time=fake.step_time,
        address=address,
        input_registers=fake.input_registers,
        broadcast=fake._broadcast,
    )
    rtde = RtdeService(
        fake.arm,
        address=address,
        rate_hz=fake.rate_hz,
        controller_version=fake.controller_version,
        versions=rtde_versions,
        input_registers=fake.input_registers,
        input_times=programs.input_times,
        wall_clock=fake.wall_clock,
    )
    return connections, programs, rtde


def _default_program(programs_dir: Path | None) -> str:
    """The default External Control program's path in the program directory (URSim's without one)."""
    base = str(programs_dir) if programs_dir is not None else PROGRAMS_DIR
    return f"{base.rstrip('/')}/{EXTERNAL_CONTROL_PROGRAM}"


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
        wall_clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.model = load_ur_model(model) if isinstance(model, str) else model
        self.address = address
        self.ports = ports or FakePorts()
        self.controller_version = controller_version
        self.arm = FakeArm(
            self.model, dh or self.model.dh, initial_positions=initial_positions, powered=powered
        )
        self.rate_hz = max_frequency(controller_version[0])
        self.step_time = 1.0 / self.rate_hz
        self.faults = faults or FaultInjector()
        self.rtde_versions = rtde_versions
        """RTDE versions it accepts: ``(1,)`` is a v1-only controller (no output frequency or recipe ids)."""
        self.wall_clock = wall_clock
        """The wall clock the I/O side reads (to tell that the fake was held up); tests pass their own."""
        self.urcap = urcap
        """Where a loaded External Control program fetches its script: the daemon's script sender."""
        self.programs_dir = Path(programs) if programs is not None else None
        """Where ``load`` finds program files (relative names resolve under it); None: URSim's default
        directory, holding only the default External Control program."""
        self.default_program = _default_program(self.programs_dir)
        self.loaded_program: str | None = self.default_program if urcap else None
        self.operational_mode = dash.OperationalMode.NONE
        """What ``get operational mode`` says (``fakeur.dashboard_answers``): NONE, no password set."""
        self.input_registers = InputRegisters()
        """RTDE input registers (``input_*_register_N``), apart from the output ones on ``arm.io``."""
        self.connections, self.programs, self.rtde = _serving_parts(self, address, rtde_versions)
        """Its clients' connections, the programs it runs and the RTDE interface."""
        self._release_when_idle = False
        """Brake release asked while powering on: release once the arm is IDLE (as URSim does)."""
        self._unlock_when_due = False
        """The primary interface's ``set unlock protective stop`` within UNLOCK_WAIT_S of the stop: done
        once the wait is over (the dashboard refuses it instead; fake-robot.md, "Errors, stops")."""
        self._realtime_clients: list[ServiceShell] = []
        self._servers: list[asyncio.Server] = []
        self._state_clients: list[ServiceShell] = []
        self._next_state = 0.0
        self._clock: asyncio.Task[None] | None = None
        self._shared_clock: tuple[SharedClock, int] | None = None
        """A clock shared with the other fakes of this process, and this fake's slot on it."""
        self.cycles = 0
        self._safety = prim.SafetyReports(self.arm.safety_mode)
        """What the primary clients were told of the safety mode (SAFETY_MODE, ERROR_CODE on changes)."""
        self._changed: asyncio.Event | None = None
        """Set (and dropped) after a cycle or a handled read; exists only while ``until`` waits."""

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
        shells: tuple[tuple[int, Callable[[], Shell]], ...] = (
            (self.ports.dashboard, self._dashboard_shell),
            (self.ports.primary, lambda: self._state_shell("primary")),
            (self.ports.secondary, lambda: self._state_shell("secondary")),
            (self.ports.realtime, self._realtime_shell),
            (self.ports.rtde, lambda: self.rtde.shell(self.connections, self._wake)),
        )
        for port, shell in shells:
            self._servers.append(await serve(shell, self.address, port))
        self._clock = asyncio.get_running_loop().create_task(self._run_clock())
        log.info(
            "fake %s (controller %s) on %s",
            self.model.model,
            ".".join(map(str, self.controller_version)),
            self.address,
        )

    async def close(self) -> None:
        """Stop serving: close every connection and server, stop the program and the clock."""
        await self.programs.close()
        for server in self._servers:
            server.close()
        for writers in self.connections.writers.values():
            for writer in list(writers):
                writer.close()
        tasks = [t for t in (self._clock,) if t is not None] + list(self.connections.tasks)
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
        return self.connections.drop(service)

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
        self.arm.life.release_emergency_stop()

    def set_speed_slider(self, fraction: float) -> None:
        """Move the teach pendant's speed slider."""
        self.arm.speed_slider = min(max(float(fraction), 0.0), 1.0)

    # ---- waiting on the controller (tests and tools) -------------------------------------------------

    async def until(self, done: Callable[[], bool], *, cycles: int = 5000, timeout: float = 30.0) -> int:
        """Wait until ``done()`` holds: checked now and after every controller cycle, every client read
        the controller handled (a connection accepted, a line or request read) and every time its
        script queue settles. TimeoutError once more than ``cycles`` cycles (0: on a clock turned by
        hand) or ``timeout`` seconds passed without it; returns the cycles it took. Costs the cycle
        one check while nobody waits."""
        start = self.cycles
        async with asyncio.timeout(timeout):
            while not done():
                if self.cycles - start > cycles:
                    raise TimeoutError(f"not done within {cycles} controller cycles")
                await self._change()
        return self.cycles - start

    async def cycles_pass(self, count: int, *, timeout: float = 30.0) -> None:
        """Wait until ``count`` more controller cycles have run (TimeoutError after ``timeout`` s)."""
        end = self.cycles + count
        await self.until(lambda: self.cycles >= end, cycles=count, timeout=timeout)

    async def _change(self) -> None:
        if self._changed is None:
            self._changed = asyncio.Event()
        if not self.programs.busy:
            await self._changed.wait()
            return
        changed = asyncio.ensure_future(self._changed.wait())
        settled = asyncio.ensure_future(self.programs.settled())
        try:
            await asyncio.wait((changed, settled), return_when=asyncio.FIRST_COMPLETED)
        finally:
            changed.cancel()
            settled.cancel()

    def _wake(self) -> None:
        if self._changed is not None:
            self._changed.set()
            self._changed = None

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
        if self._changed is not None:
            self._wake()

    def _cycle(self) -> None:
        arm, dt = self.arm, self.step_time
        programs = self.programs
        if programs.main is not None or programs.secondary:
            programs.step()
        if self._release_when_idle and arm.robot_mode is RobotMode.IDLE:
            self._release_when_idle = False
            arm.life.brake_release(arm.timestamp)
        if self._unlock_when_due:
            self._unlock_when_due = arm.unlock_protective_stop() == UNLOCK_TOO_SOON
        arm.step(dt)
        self.cycles += 1
        if arm.safety_mode is not self._safety.mode:  # told before any state that shows the new mode
            for message in self._safety.observe(arm.safety_mode):
                self._broadcast(message)
        self.rtde.after_cycle()
        now = arm.timestamp
        if now < self.faults.stalled_until:
            return
        if self._realtime_clients:
            self._send_realtime()
        if self.rtde.clients:
            self.rtde.send_due(now)
        if now + 1e-9 >= self._next_state:
            self._next_state = now + STATE_PERIOD_S
            if self._state_clients:
                state = robot_state(arm, self.model, self.controller_version)
                for shell in self._state_clients:
                    self._send_primary(shell, state)

    # ---- primary (30001), secondary (30002) and real-time (30003): the script ports ------------------

    def _state_shell(self, service: str) -> ServiceShell:
        """A primary or secondary client: VERSION first, then the state on the controller's 10 Hz grid."""

        def opened(shell: ServiceShell) -> None:
            major, minor, bugfix, build = self.controller_version
            version = prim.VersionMessage("URControl", major, minor, bugfix, build, "01-01-2026, 00:00:00")
            self._send_primary(shell, version)
            self._state_clients.append(shell)
            self._wake()  # the client is connected (and listed)

        return self.connections.shell(
            service,
            prim.PrimaryConnection(Side.ROBOT),
            self._on_script_port,
            on_open=opened,
            on_end=self._state_clients.remove,
        )

    def _realtime_shell(self) -> ServiceShell:
        """A real-time client: the state every controller cycle."""

        def opened(shell: ServiceShell) -> None:
            self._realtime_clients.append(shell)
            self._wake()

        conn = rt.RealtimeConnection(Side.ROBOT, self.controller_version)
        return self.connections.shell(
            "realtime", conn, self._on_script_port, on_open=opened, on_end=self._realtime_clients.remove
        )

    def _on_script_port(self, shell: ServiceShell, event: Any) -> Awaitable[None] | None:
        """Hand the scripts a client sends to the programs, in their order: each is compiled off the
        event loop, then started. Scripts get no replies, so reading never waits on the client reading
        (ur_rtde reads nothing of 30003, where it sends its scripts); it waits while too many scripts
        wait to be compiled (TCP flow control holds the client back meanwhile)."""
        self._wake()
        if isinstance(event, prim.CommandReceived | prim.ProgramReceived):
            self._on_script(event)
            return self.programs.room()
        return None

    def _send_realtime(self) -> None:
        state = realtime_state(self.arm)
        for shell in self._realtime_clients:
            shell.codec.send(state)
            shell.flush()

    def _send_primary(self, shell: Shell, message: Any) -> None:
        shell.codec.send(message)
        shell.flush()

    def _broadcast(self, message: Any) -> None:
        """Send a robot message to every primary client (the secondary interface gets only state)."""
        for shell in self._state_clients:
            if shell.name == "primary":
                self._send_primary(shell, message)

    def _on_script(self, event: prim.CommandReceived | prim.ProgramReceived) -> None:
        if isinstance(event, prim.CommandReceived):
            line = event.line.strip()
            if line in CONTROLLER_COMMANDS:  # after the scripts that arrived before it
                self.programs.then(lambda: self._controller_command(line))
            else:
                self.programs.submit("script", line + "\n")
        else:
            self.programs.submit(event.name, event.text)

    def _controller_command(self, line: str) -> None:
        arm = self.arm
        if line == prim.ControllerCommand.POWER_ON:
            arm.life.power_on(arm.timestamp)
        elif line == prim.ControllerCommand.POWER_OFF:
            self.programs.stop()
            arm.power_off()
        elif line == prim.ControllerCommand.BRAKE_RELEASE:
            self.brake_release()
        elif line == prim.ControllerCommand.UNLOCK_PROTECTIVE_STOP:
            self._unlock_when_due = arm.unlock_protective_stop() == UNLOCK_TOO_SOON
        elif line == prim.ControllerCommand.STOP_PROGRAM:
            self.programs.stop()

    # ---- programs (fakeur.programs) and the dashboard's answers (fakeur.dashboard_answers) -----------

    def brake_release(self) -> str | None:
        """Release the brakes; from POWER_OFF power on first, then release once IDLE (as URSim does)."""
        arm = self.arm
        if arm.robot_mode in (RobotMode.POWER_OFF, RobotMode.BOOTING):
            reason = arm.life.power_on(arm.timestamp)
            if reason is None:
                self._release_when_idle = True
            return reason
        return arm.life.brake_release(arm.timestamp)

    def play_urcap(self) -> None:
        """What the External Control program does on play: fetch the script from the daemon's script
        sender (``urcap``), then run it; nothing without a script sender."""
        if self.urcap is not None:
            self.connections.spawn(self.programs.play_urcap(self.urcap, self.programs.submit))

    # ---- dashboard (29999) ------------------------------------------------------------------------------

    def _dashboard_shell(self) -> ServiceShell:
        """A dashboard client: the banner, then one reply per command line, one command per loop turn."""

        def opened(shell: ServiceShell) -> None:
            shell.send(dash.Banner())
            self._wake()

        return self.connections.shell(
            "dashboard", dash.DashboardConnection(Side.ROBOT), self._on_dashboard, on_open=opened, paced=True
        )

    def _on_dashboard(self, shell: ServiceShell, event: Any) -> Awaitable[None] | None:
        if isinstance(event, dash.CommandReceived | dash.UnknownCommand):
            return self._answer(shell, event)
        return None  # the robot side receives nothing else

    async def _answer(self, shell: ServiceShell, event: dash.CommandReceived | dash.UnknownCommand) -> None:
        if isinstance(event, dash.CommandReceived):
            reply = await dashboard_answer(self, event.command)
        else:
            reply = dash.unknown_command_text(event.line)
        shell.send(dash.ReplyLine(reply))
        self._wake()
        await asyncio.sleep(0)  # one command per turn: a flood of them delays no cycle
        if isinstance(event, dash.CommandReceived) and isinstance(event.command, dash.Quit | dash.Shutdown):
            await shell.drain()
            shell.close()
