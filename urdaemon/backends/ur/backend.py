"""The ``ur`` backend: one UR controller over RTDE, the primary interface, the dashboard and the four
callback servers, with the RTDE output stream as the clock.

Each RTDE package: the state is mapped in place, ``on_cycle()`` runs the controller, and the
command goes out on the reverse socket in the same turn of the loop (servoj / speedj / idle
keepalive, as the reverse channel's state machine says). ``run()`` returns only by raising: when any
link drops, the runtime above aborts the motion and calls ``run()`` again after its backoff, so every
reconnect starts from scratch and motion resumes only from a new command, seeded from the measured pose.

This module supervises the links (connect, watch, close), runs the cycle and routes the links' events;
the jobs it composes have their own modules: ``links`` (``UrLinks``: the RTDE, primary and dashboard
links, sending the program headless), ``reverse_channel`` (what the program does with the reverse
socket), ``reverse_writer`` (the bytes written to it), ``program`` (the control program, and the
address it connects back to), ``route`` (where the callback servers listen: the interface that reaches
the robot), ``startup`` (power, brakes, play), ``robot_commands`` (script commands, RTDE inputs, the
dashboard), ``diagnosis`` (the doctor's facts), ``readiness`` (the status's reason). Each is given the
collaborators it uses (``UrLinks``, the program, the servers), never the backend. The logic takes
``now`` (the reverse channel, the program's windows); only the asyncio parts read the clock: this
module, start-up's waits and the servers' admission window.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import Callable, Sequence
from typing import Any

from urdaemon.backends.base import Backend, PassthroughResult
from urdaemon.backends.timing import LagLimits, ur_lag_limits
from urdaemon.backends.ur.diagnosis import Diagnosis
from urdaemon.backends.ur.links import UrLinks
from urdaemon.backends.ur.primary_link import PrimaryLink
from urdaemon.backends.ur.program import ControlProgram, ProgramBuilder
from urdaemon.backends.ur.recovery import auto_recovery
from urdaemon.backends.ur.reverse_channel import READING_FRAMES, Action, Frame, ReverseChannel, Step
from urdaemon.backends.ur.reverse_writer import ReverseWriter, encode_passthrough_point
from urdaemon.backends.ur.robot_commands import UrRobotCommands
from urdaemon.backends.ur.robot_messages import RobotMessages
from urdaemon.backends.ur.rtde_link import RtdeLink, StateMapper, output_recipe
from urdaemon.backends.ur.servers import CallbackServers
from urdaemon.backends.ur.startup import StartUp
from urdaemon.cell.robot_options import Robot, UrOptions
from urdaemon.description.urmodels import load_ur_model
from urdaemon.errors import BackendError, ConnectionLostError, RobotFaultError, UrDaemonError
from urdaemon.model import CommandMode, Lifecycle, RobotMode, RobotState, SafetyMode
from urdaemon.protocols import reverse, script_command, script_sender, trajectory_point

__all__ = ["RTDE_WATCHDOG_S", "UrBackend"]

log = logging.getLogger("urdaemon.ur")

_NO_FRAME, _RUNNING = Frame.NONE, Lifecycle.RUNNING
"""(the 500 Hz path: an enum's attribute lookup costs ~0.1 µs, a module alias a fifth of that)"""
RTDE_WATCHDOG_S = 0.5
"""No output package for this long is a lost link (a pulled cable closes no socket); urcl waits 1 s.
A longer window (``ur.receive_timeout_ms``) stretches it: a silence the program rides through is no
lost link either."""


class UrBackend(Backend):
    """Drives one UR controller."""

    kind = "ur"

    def __init__(
        self,
        robot: Robot,
        joint_names: Sequence[str],
        *,
        expected_hash: str | None,
        program: ProgramBuilder | None = None,
    ) -> None:
        rate_hz = float(load_ur_model(robot.model).control_rate_hz)  # the model's: known up front
        super().__init__(robot.name, joint_names, rate_hz, lag=_lag_limits(robot.ur or UrOptions(), rate_hz))
        assert robot.address is not None
        self.robot = robot
        self.address = robot.address
        self.options = robot.ur or UrOptions()
        self.ports = robot.ports.as_dict()
        self.expected_hash = expected_hash
        self.servers = CallbackServers(self.address, self.ports, self)
        self._mapper = StateMapper(output_recipe())
        self._on_cycle: Callable[[], None] = lambda: None
        self._channel = ReverseChannel()
        """What the program does with the reverse socket: the one owner of the passthrough goal."""
        self._on_result: PassthroughResult | None = None
        """Who hears the running passthrough goal's result."""
        self._writer = ReverseWriter(self.servers, self.options.receive_timeout_ms)
        self._program = ControlProgram(robot, self.options, self.ports, self.servers, program)
        self.links = UrLinks(self.address, read_only=self.options.read_only, program=self._program)
        """The RTDE, primary and dashboard links (``links.UrLinks``)."""
        self.messages = RobotMessages(self.name, self.notice, self._program)
        self._commands = UrRobotCommands(
            self.links, self.servers.script_command, notice=self.notice, name=self.name
        )
        self._recovery = auto_recovery(  # ur.auto_recover: looks at the robot with the link watch
            self.name, self.options, self.state, self._commands.dashboard, self.resend_program, self.notice
        )
        self.tcp = self.check_tcp(robot.tcp)  # the cell file's until set_tcp; sent as the program connects
        self._first_package = asyncio.Event()
        """Set by each RTDE package; cleared before a new link streams (start-up waits on it)."""
        self._start_up = StartUp(
            robot,
            links=self.links,
            program=self._program,
            channel=self._channel,
            reverse_link=self.servers.reverse,
            state=self.state,
            first_package=self._first_package,
        )
        self.diagnosis: Diagnosis = Diagnosis(  # the doctor's: what it learns of the controller
            self.links,
            self.state,
            period=self.period,
            headless=robot.headless,
            servers=self.servers,
            program=self._program,
        )
        self._package_at = 0.0
        """``time.monotonic()`` when the latest RTDE package was handled (the cycle's ``now``)."""
        self._cycle_error_logged = False
        self._command_sent = True
        self._runs = 0

    # ---- link supervision ------------------------------------------------------------------------------

    async def run(self, on_cycle: Callable[[], None]) -> None:
        """Connect every link, start streaming, keep the program running; raise when a link drops."""
        self._on_cycle = on_cycle
        self._begin_run()
        if not self.options.read_only:  # before RTDE: a URCap may fetch the program as soon as it plays
            await self._program.listen(self.address)
        try:
            rtde = await self._connect_rtde()
            primary = await self.links.connect_primary(self.messages.on_message)
            primary_task = asyncio.get_running_loop().create_task(primary.run())
            try:
                await self._serve(primary, primary_task, rtde)
            finally:
                primary_task.cancel()
                with contextlib.suppress(BaseException):
                    await primary_task
        finally:
            self._recovery.close()
            self._close_links()
            state = self.state
            _forget_robot(state)  # the last package's RUNNING/NORMAL say nothing about the robot now
            if state.lifecycle not in (Lifecycle.CONNECTING, Lifecycle.RECOVERING):
                state.lifecycle = Lifecycle.DISCONNECTED

    def _begin_run(self) -> None:
        """Say the robot is (re)connecting and nothing is known about it until RTDE streams again."""
        state = self.state
        self._runs += 1
        self._mapper.forget()
        if self._runs == 1:
            state.lifecycle = Lifecycle.CONNECTING
            state.lifecycle_reason = f"connecting to {self.address}"
        else:  # a link was lost: reconnecting, motion resumes only from a new command
            state.lifecycle = Lifecycle.RECOVERING
            state.lifecycle_reason = f"reconnecting to {self.address}"
        _forget_robot(state)
        if self.on_change is not None:
            self.on_change()  # no cycle runs until RTDE streams again: say it now

    async def _connect_rtde(self) -> RtdeLink:
        """Connect and handshake RTDE; learn the controller's version and the address it reaches us at."""
        rtde = await self.links.connect_rtde(self._on_package)
        if abs(rtde.frequency - self.rate_hz) > 1e-6:
            raise RobotFaultError(
                f"the controller streams at {rtde.frequency:g} Hz but a {self.robot.model} runs at "
                f"{self.rate_hz:g} Hz: is the cell file's model right?"
            )
        step_time = reverse.step_time_for_frequency(rtde.frequency)
        self._writer.use_step(step_time)
        if rtde.controller_version is not None:
            version = rtde.controller_version
            self._program.controller_version = (version.major, version.minor, version.bugfix)
        peer = rtde.transport.get_extra_info("peername") if rtde.transport else None
        sockname = rtde.transport.get_extra_info("sockname") if rtde.transport else None
        await self._program.rtde_connected(str(peer[0]) if peer else "", str(sockname[0]) if sockname else "")
        return rtde

    async def _serve(self, primary: PrimaryLink, primary_task: asyncio.Task[None], rtde: RtdeLink) -> None:
        """With RTDE and the primary link up: the dashboard, the calibration check, streaming, start-up;
        then watch the links until one drops."""
        try:
            await self.links.dashboard_link()
        except UrDaemonError as err:  # PolyScope X has none; services will say so when asked
            log.warning("[%s] no dashboard: %s", self.name, err)
        await self.messages.check_calibration(primary, self.expected_hash, self.options.calibration_check)
        self._first_package.clear()
        await rtde.start()
        if self.options.startup:
            try:
                await self.startup()
            except UrDaemonError as err:
                # e.g. an emergency stop: report it and keep the links; the status shows why
                log.warning("[%s] start-up failed: %s", self.name, err)
                self.notice("startup_failed", str(err))
        await self._watch(primary_task, rtde)

    async def _watch(self, primary_task: asyncio.Task[None], rtde: RtdeLink) -> None:
        """Return never; raise when the primary link ends, RTDE closes, or RTDE falls silent."""
        watched: set[asyncio.Future[Any]] = {primary_task, rtde.closed}
        while True:
            done, _ = await asyncio.wait(
                watched, timeout=RTDE_WATCHDOG_S / 2, return_when=asyncio.FIRST_COMPLETED
            )
            if rtde.closed in done:
                raise rtde.closed.result() or ConnectionLostError("rtde: closed")
            if primary_task in done:
                primary_task.result()
                raise ConnectionLostError("primary: link ended")
            self.diagnosis.watch()  # the clocks' reference pair, once per RTDE link
            self._recovery.look()
            silent = time.monotonic() - self._package_at
            if self._first_package.is_set() and silent > max(RTDE_WATCHDOG_S, self._writer.window):
                raise ConnectionLostError(f"rtde: no data for {silent:.2f} s")

    async def close(self) -> None:
        """Hand control back (STOPPED), close the links and the callback servers (the daemon stops)."""
        self._act(self._channel.stop())
        self._close_links()
        await self.servers.close()

    def _close_links(self) -> None:
        self.links.close()
        for server in self.servers.all:
            if server.link is not None:
                server.link.close()
        self._program.lost_link = ""

    # ---- commands (``robot_commands.py``), start-up (``startup.py``) ----------------------------------

    async def set_io(self, kind: str, pin: int, value: float | bool) -> None:
        """Set an output through RTDE inputs."""
        self._commands.set_io(kind, pin, value)

    async def set_speed_slider(self, fraction: float) -> None:
        """Set the speed slider through RTDE inputs."""
        self._commands.set_speed_slider(fraction)

    async def set_payload(self, mass: float, cog: tuple[float, float, float]) -> None:
        """Set the payload through the script command socket (or a secondary program without one)."""
        self._commands.set_payload(mass, cog)

    async def set_tcp(self, pose: Sequence[float]) -> None:
        """Make ``pose`` the TCP offset, the controller's too (``UrRobotCommands.set_tcp``); kept only
        once the controller could be told (or will be, as the program connects)."""
        checked = self.check_tcp(pose)
        self._commands.set_tcp(checked)
        self.tcp = checked

    async def dashboard(self, line: str) -> tuple[bool, str]:
        """Send a dashboard command line; (success, the robot's reply)."""
        return await self._commands.dashboard(line)

    async def zero_ft_sensor(self) -> None:
        """Zero the force/torque sensor (script command)."""
        self._commands.script_command(script_command.ZeroFtSensor(), "zero_ft_sensor")

    async def set_tool_voltage(self, volts: int) -> None:
        """Set the tool voltage (script command)."""
        self._commands.set_tool_voltage(volts)

    async def force_mode(self, start: object | None) -> None:
        """Start force mode (a ``StartForceMode`` script command) or end it (None)."""
        self._commands.script_command(script_command.EndForceMode() if start is None else start, "force mode")

    async def tool_contact(self, start: bool) -> None:
        """Arm tool-contact detection, or end it; the result comes back as a ``tool_contact`` notice."""
        self._commands.tool_contact(start)

    async def startup(self) -> None:
        """Power on, release the brakes, and start the control program (headless) or play it (URCap);
        refused while a start-up or program restart is under way (``startup.StartUp``)."""
        await self._start_up.startup()

    async def resend_program(self) -> None:
        """Send the control program again (headless) or play the loaded one (URCap); refused while one
        is still connecting back (``startup.StartUp``)."""
        await self._start_up.resend_program()

    # ---- the reverse channel: passthrough, freedrive, hand back ----------------------------------------

    async def hand_back_control(self) -> None:
        """End the control program's loop (a STOPPED frame); in URCap mode the pendant program continues."""
        self._act(self._channel.hand_back())

    @property
    def passthrough_goal(self) -> str | None:
        """The id of the passthrough goal the robot runs itself, or None (the reverse channel's)."""
        return self._channel.passthrough_goal

    def passthrough_problem(self) -> str | None:
        """Why a passthrough trajectory cannot start now (None when it can)."""
        return self._channel.passthrough_problem(self.servers.trajectory.connected)

    encode_passthrough_point = staticmethod(encode_passthrough_point)
    """One spline point's 84-byte frame (``frames.encode_passthrough_point``)."""

    def start_encoded_passthrough(
        self, goal_id: str, frames: bytes, count: int, on_result: PassthroughResult
    ) -> None:
        """START(count) on the reverse socket, then the pre-encoded points on the trajectory socket.

        Every point was encoded before (``encode_passthrough_point``): a value the wire cannot carry is
        refused before the robot waits for points that would never come, and this is one write."""
        problem = self.passthrough_problem()
        if problem is not None:
            raise BackendError(problem)
        if count <= 0 or len(frames) != count * trajectory_point.FRAME_BYTES:
            raise BackendError(f"{len(frames)} bytes are not {count} encoded trajectory points")
        self._writer.start(frames, count)  # sent first: a goal that could not be sent never runs
        self._channel.start_passthrough(goal_id, self.servers.trajectory.connected)
        self._on_result = on_result

    def cancel_passthrough(self) -> None:
        """CANCEL on the reverse socket; the robot's answer is owed and dropped (the goal ended here)."""
        step = self._channel.cancel_passthrough()
        if step.action is Action.SEND_CANCEL:
            self._on_result = None
        self._act(step)

    @property
    def freedrive_active(self) -> bool:
        """True while freedrive is on."""
        return self._channel.freedrive_on

    def freedrive(self, active: bool, timeout: float) -> None:
        """Keep freedrive on for ``timeout`` s more (a deadman: it ends when commands stop), or end it now."""
        self._act(self._channel.freedrive(active, time.monotonic(), timeout))

    def _act(self, step: Step) -> None:
        """Do what a reverse-channel event asks: send its frame, then end its goal (if any)."""
        if step.action is Action.NOTHING or step.action is Action.SWALLOW:
            return
        self._writer.act(step)
        if step.goal is not None:
            on_result, self._on_result = self._on_result, None
            if on_result is not None:
                on_result(step.goal, step.code, step.reason)

    # ---- the cycle ---------------------------------------------------------------------------------------

    def _on_package(self, values: tuple[Any, ...]) -> None:
        state = self.state
        previous = state.controller_time
        self._mapper.apply(values, state)
        # the controller's own clock shows missed packages: a gap of k steps means k - 1 never arrived
        gap = state.controller_time - previous
        if gap > 1.5 * self.period and previous > 0.0:
            self._missed += round(gap / self.period) - 1
            self._late += 1
        servers = self.servers
        links_up = (
            servers.reverse.link is not None
            and servers.trajectory.link is not None
            and servers.script_command.link is not None
        )
        # ready only while the program holds every link it uses (reverse, trajectory, script command)
        state.program_running = state.program_running and links_up
        if state.program_running and state.lifecycle is _RUNNING:
            state.lifecycle_reason = ""
        else:  # worded again only when something it depends on changed
            state.lifecycle_reason = self._program.reason_cached(state, self._channel.handed_back)
        self._cycles += 1
        now = self._package_at = time.monotonic()
        self._first_package.set()
        self.report_lag()  # packages missed or late since the last warning, at most every few seconds
        self._command_sent = False
        try:
            # the runtime's tick calls send_command() before it publishes anything; while catching up
            # (a newer package of the same read follows) it only keeps the controller's time
            self._on_cycle()
        except Exception:  # a bug above must not cost the RTDE link: hold still this cycle, say so once
            self.command.mode = CommandMode.IDLE
            if not self._cycle_error_logged:
                self._cycle_error_logged = True
                log.exception("[%s] the cycle failed; holding still", self.name)
        if self.catching_up:
            self._late += 1
            return
        if not self._command_sent:
            self.send_command()
        if not links_up and self._program.wanted(state, self._mapper.runtime_state, self._channel):
            self.links.send_program(now, force=False)

    @property
    def catching_up(self) -> bool:
        """The RTDE link is delivering a package that a newer one of the same read follows."""
        rtde = self.links.rtde
        return rtde is not None and rtde.catching_up

    def send_command(self) -> None:
        """This cycle's frame on the reverse socket, at once: publishing the state can wait, the robot
        cannot. Called by the runtime right after the controller's tick (or by the cycle itself)."""
        if self._command_sent:
            return
        self._command_sent = True
        playing = self._mapper.runtime_state in READING_FRAMES
        frame = self._channel.frame(self.command.mode, playing, self._package_at)
        if frame is _NO_FRAME:
            return
        self._writer.write(frame, self.command)
        rtde = self.links.rtde
        if rtde is not None:  # package in → command out (issue 5's turnaround)
            self.turnaround.record(time.perf_counter_ns() - rtde.received_ns)

    # ---- callbacks from the links and servers --------------------------------------------------------------

    def on_link(self, name: str, connected: bool, reason: str) -> None:
        """A callback server's connection came or went."""
        log.info("[%s] %s", self.name, reason)
        program = self._program
        if connected:
            if name == "reverse":
                self._act(self._channel.program_connected())
            elif name == "script_command":
                self._commands.send_tcp(self.tcp)  # the controller's TCP is the daemon's from its start
            program.link_up(time.monotonic())
            return
        if name == "reverse":
            self._act(self._channel.program_lost())  # its freedrive and trajectory end with it
            program.lost_link = ""  # the whole program ended (its other links close with it)
        elif name == "trajectory":
            self._act(self._channel.trajectory_lost())
        elif name == "script_command":
            self._commands.script_link_lost()  # an armed tool contact's result can no longer come
        if program.replaced_or_closing(name, reason, self.links.rtde is not None):
            return
        program.link_lost(name, self._channel.handed_back)
        state = self.state
        state.program_running = False
        state.lifecycle_reason = self._program.reason(state, self._channel.handed_back)
        if self.on_change is not None:
            self.on_change()  # say it now, not at the next cycle or status tick

    def on_event(self, name: str, event: Any) -> None:
        """Something arrived on a callback connection."""
        if isinstance(event, trajectory_point.TrajectoryResult):
            self._act(self._channel.passthrough_result(int(event.result)))
        elif isinstance(event, script_command.ToolContactResult):
            self._commands.tool_contact_result(event)
        elif isinstance(event, script_sender.ProgramRequested):
            self._program.send_requested(time.monotonic())

    # ---- helpers ------------------------------------------------------------------------------------

    @property
    def robot_messages(self) -> list[str]:
        """The robot's last messages (``robot_messages.KEPT_MESSAGES``)."""
        return self.messages.recent

    @property
    def calibration_ok(self) -> bool | None:
        """Whether the robot's kinematics are the configured calibration's (None: not checked yet)."""
        return self.messages.calibration_ok


def _forget_robot(state: RobotState) -> None:
    """Say nothing is known about the robot (its link is down): modes unknown, no program."""
    state.robot_mode = RobotMode.DISCONNECTED
    state.safety_mode = SafetyMode.UNDEFINED_SAFETY_MODE
    state.program_running = False


def _lag_limits(options: UrOptions, rate_hz: float) -> LagLimits:
    """A gap warns at half of what the program rides through before it stops the arm: its hold
    (``keepalive_cycles``) or its window (``receive_timeout_ms``), whichever ends first."""
    return ur_lag_limits(min(options.keepalive_cycles / rate_hz, options.receive_timeout_ms / 1000))
