"""The ``ur`` backend: one UR controller over RTDE, the primary interface, the dashboard and the four
callback servers, with the RTDE output stream as the clock.

Each RTDE package: the state is mapped in place, ``on_cycle()`` runs the controller, and the
command goes out on the reverse socket in the same turn of the loop (servoj / speedj / idle
keepalive). ``run()`` returns only by raising: when any link drops, the runtime above aborts the
motion and calls ``run()`` again after its backoff, so every reconnect starts from scratch and
motion resumes only from a new command, seeded from the measured pose.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time
from collections.abc import AsyncIterator, Callable, Sequence
from typing import Any

from urdaemon.backends.base import Backend
from urdaemon.backends.ur.dashboard_link import DashboardLink
from urdaemon.backends.ur.primary_link import PrimaryLink
from urdaemon.backends.ur.readiness import ProgramFacts, not_ready_reason
from urdaemon.backends.ur.rtde_link import RtdeLink, StateMapper, input_recipe, output_recipe
from urdaemon.backends.ur.servers import REPLACED, CallbackServers
from urdaemon.cell.config import Robot, UrOptions
from urdaemon.description.urmodels import load_ur_model
from urdaemon.errors import (
    BackendError,
    ConnectionLostError,
    LocalProtocolError,
    RobotFaultError,
    UrDaemonError,
    UrTimeoutError,
)
from urdaemon.model import CommandMode, Lifecycle, RobotMode, RobotState, SafetyMode
from urdaemon.protocols import dashboard as dash
from urdaemon.protocols import primary as prim
from urdaemon.protocols import reverse, script_command, script_sender, trajectory_point

__all__ = ["UR_IO_SIZES", "UrBackend"]

log = logging.getLogger("urdaemon.ur")

UR_IO_SIZES = {"digital": 8, "configurable": 8, "tool": 2, "analog": 2}
KINEMATICS_TIMEOUT_S = 10.0
"""urcl waits up to 10 s for the first state package after connecting (ur-protocols.md §6.7)."""
PROGRAM_RESEND_S = 2.0
"""Headless: after sending the program, wait this long for it to connect back before sending again."""
IDLE_TIMEOUT_S = 1.0
"""Read timeout sent with a keepalive (urcl's default, ur-protocols.md §4.2)."""
RUNTIME_PLAYING = 2
RUNTIME_PAUSING = 3
RTDE_WATCHDOG_S = 0.5
"""No output package for this long is a lost link (a pulled cable closes no socket); urcl waits 1 s."""
PASSTHROUGH_TIMEOUT_S = 0.2
"""Read timeout sent with trajectory control frames (urcl's default for non-realtime control, §4.2)."""
STARTUP_TIMEOUT_S = 30.0
"""How long power-on and brake release may take (urcl polls for 30 s)."""


class UrBackend(Backend):
    """Drives one UR controller."""

    kind = "ur"

    def __init__(
        self,
        robot: Robot,
        joint_names: Sequence[str],
        *,
        expected_hash: str | None,
        program: Callable[[str, UrOptions, dict[str, int]], str] | None = None,
    ) -> None:
        # the controller's rate is fixed by the model; the motion controller is built with it up front
        super().__init__(robot.name, joint_names, float(load_ur_model(robot.model).control_rate_hz))
        assert robot.address is not None
        self.robot = robot
        self.address = robot.address
        self.options = robot.ur or UrOptions()
        self.ports = robot.ports.as_dict()
        self.expected_hash = expected_hash
        self._program_builder = program
        self.servers = CallbackServers(self.address, self.ports, self)
        self._servers_started = False
        self._mapper = StateMapper(output_recipe())
        self._inputs = input_recipe()
        self._rtde: RtdeLink | None = None
        self._primary: PrimaryLink | None = None
        self._dashboard: DashboardLink | None = None
        self._on_cycle: Callable[[], None] = lambda: None
        self._program_sent_at = -1e9
        self._host_ip = ""
        self.robot_messages: list[str] = []
        self.calibration_ok: bool | None = None
        self._passthrough: tuple[str, Callable[[str, int], None]] | None = None
        self._freedrive_until = 0.0
        self._freedrive_on = False
        self._controller_version = (5, 10, 0)
        self._step_time = reverse.step_time_for_frequency(self.rate_hz)
        self._servo_timeout = self._clamped_timeout()
        self._program_cache: tuple[tuple[Any, ...], str] | None = None
        self._first_package = asyncio.Event()
        self._last_package = 0.0
        self._swallow_result = False
        self._cycle_error_logged = False
        self._command_sent = True
        self._dashboard_lock = asyncio.Lock()
        self._handed_back = False
        """After hand_back_control the program is not sent again until resend_program or startup."""
        self._runs = 0
        self._program_lock = asyncio.Lock()
        """Held by startup and resend_program: a second call while one is under way is refused."""
        self._program_links_up_at = -1e9
        """When the program last held all its links (a program sent after this is still connecting)."""
        self._tool_contact_armed = False
        self._startup_problem = ""
        """Why the last start-up failed (kept in the status until one succeeds)."""
        self._program_ended = ""
        """What the controller said when our program last ended (a runtime error, a stop)."""
        self._lost_link = ""
        """The program link that dropped while the others stayed up (the program is being restarted)."""
        self._program_started_at = -1e9
        self._reason_key: tuple[Any, ...] = ()
        self._reason = ""

    # ---- Backend interface ---------------------------------------------------------------------------

    async def run(self, on_cycle: Callable[[], None]) -> None:
        """Connect every link, start streaming, keep the program running; raise when a link drops."""
        self._on_cycle = on_cycle
        state = self.state
        self._runs += 1
        self._mapper.forget()
        if self._runs == 1:
            state.lifecycle = Lifecycle.CONNECTING
            state.lifecycle_reason = f"connecting to {self.address}"
        else:  # a link was lost: reconnecting, motion resumes only from a new command
            state.lifecycle = Lifecycle.RECOVERING
            state.lifecycle_reason = f"reconnecting to {self.address}"
        _forget_robot(state)  # nothing is known about the robot until RTDE streams again
        if self.on_change is not None:
            self.on_change()  # no cycle runs until RTDE streams again: say it now
        read_only = self.options.read_only
        if not self._servers_started and not read_only:
            await self.servers.start(self.options.listen_address)
            self._servers_started = True
        try:
            rtde = self._rtde = await RtdeLink.connect(self.address, self._on_package)
            await rtde.handshake(output_recipe(), None if read_only else self._inputs)
            if abs(rtde.frequency - self.rate_hz) > 1e-6:
                raise RobotFaultError(
                    f"the controller streams at {rtde.frequency:g} Hz but a {self.robot.model} runs at "
                    f"{self.rate_hz:g} Hz: is the cell file's model right?"
                )
            self._step_time = reverse.step_time_for_frequency(rtde.frequency)
            self._servo_timeout = self._clamped_timeout()
            if rtde.controller_version is not None:
                version = rtde.controller_version
                self._controller_version = (version.major, version.minor, version.bugfix)
            sockname = rtde.transport.get_extra_info("sockname") if rtde.transport else None
            self._host_ip = self.options.reverse_ip or (str(sockname[0]) if sockname else "127.0.0.1")
            peer = rtde.transport.get_extra_info("peername") if rtde.transport else None
            if peer:  # a host name in the cell file: the robot's connections come from its IP
                self.servers.set_robot_address(str(peer[0]))
            primary = self._primary = await PrimaryLink.connect(self.address, self._on_robot_message)
            primary_task = asyncio.get_running_loop().create_task(primary.run())
            try:
                try:
                    await self._dashboard_link()
                except UrDaemonError as err:  # PolyScope X has none; services will say so when asked
                    log.warning("[%s] no dashboard: %s", self.name, err)
                await self._check_calibration(primary)
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
            finally:
                primary_task.cancel()
                with contextlib.suppress(BaseException):
                    await primary_task
        finally:
            self._close_links()
            _forget_robot(state)  # the last package's RUNNING/NORMAL say nothing about the robot now
            if state.lifecycle not in (Lifecycle.CONNECTING, Lifecycle.RECOVERING):
                state.lifecycle = Lifecycle.DISCONNECTED

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
            silent = time.monotonic() - self._last_package
            if self._first_package.is_set() and silent > RTDE_WATCHDOG_S:
                raise ConnectionLostError(f"rtde: no data for {silent:.2f} s")

    async def close(self) -> None:
        """Hand control back (STOPPED), close the links and the callback servers (the daemon stops)."""
        if self.servers.reverse.connected:
            self.servers.reverse.send(reverse.Stopped())  # urcl does the same on shutdown (§6.7)
        self._close_links()
        if self._servers_started:
            await self.servers.close()
            self._servers_started = False

    async def set_io(self, kind: str, pin: int, value: float | bool) -> None:
        """Set an output through RTDE inputs."""
        self.check_io(kind, pin, value, UR_IO_SIZES)
        fields: dict[str, Any] = {}
        if kind == "analog":
            fields = {
                "standard_analog_output_mask": 1 << pin,
                "standard_analog_output_type": 1 << pin,  # voltage
                f"standard_analog_output_{pin}": float(value),
            }
        else:
            prefix = {"digital": "standard", "configurable": "configurable", "tool": "tool"}[kind]
            fields = {
                f"{prefix}_digital_output_mask": 1 << pin,
                f"{prefix}_digital_output": 0xFF if value else 0x00,
            }
        self._send_inputs(fields)

    async def set_speed_slider(self, fraction: float) -> None:
        """Set the speed slider through RTDE inputs."""
        if not 0.0 <= fraction <= 1.0:
            raise BackendError(f"speed slider must be within 0..1, got {fraction!r}")
        self._send_inputs({"speed_slider_mask": 1, "speed_slider_fraction": float(fraction)})

    async def set_payload(self, mass: float, cog: tuple[float, float, float]) -> None:
        """Set the payload through the script command socket (or a secondary program without one)."""
        self._check_commanding()
        if not all(math.isfinite(v) for v in (mass, *cog)):
            raise BackendError(f"payload mass and centre of gravity must be finite, got {mass!r}, {cog!r}")
        if self.servers.script_command.connected:
            self._script_command(script_command.SetPayload(mass, cog), "the payload")
            return
        if self._primary is None:
            raise BackendError("not connected to the robot")
        x, y, z = cog
        self._primary.send_script(prim.sec_program("setup", f"set_payload({mass!r}, [{x!r}, {y!r}, {z!r}])"))

    # ---- services --------------------------------------------------------------------------------------

    async def dashboard(self, line: str) -> tuple[bool, str]:
        """Send a dashboard command line; (success, the robot's reply)."""
        command = dash.parse_command(line) or dash.Raw(line)
        try:
            reply = await (await self._dashboard_link()).command(command)
        except ConnectionLostError:
            self._drop_dashboard()  # the dashboard dropped: connect once more
            reply = await (await self._dashboard_link()).command(command)
        except UrTimeoutError:
            self._drop_dashboard()  # its late reply would be read as the next command's answer
            raise
        text = str(getattr(reply, "text", ""))
        success = getattr(reply, "success", None)
        if isinstance(reply, dash.RawReply):  # a line the codec does not type: the robot's words decide
            success = not _is_refusal(text)
        elif success is None:  # a query: it succeeded if it could be read
            success = all(getattr(reply, f, "") is not None for f in ("mode", "state", "running", "remote"))
        return bool(success), text

    async def zero_ft_sensor(self) -> None:
        """Zero the force/torque sensor (script command)."""
        self._script_command(script_command.ZeroFtSensor(), "zero_ft_sensor")

    async def set_tool_voltage(self, volts: int) -> None:
        """Set the tool voltage (script command)."""
        if volts not in (0, 12, 24):
            raise BackendError(f"tool voltage must be 0, 12 or 24 V, got {volts!r}")
        self._script_command(script_command.SetToolVoltage(volts), "the tool voltage")

    async def startup(self) -> None:
        """Power on, release the brakes, and start the control program (headless) or play it (URCap).

        Without a dashboard (PolyScope X, or it refused the connection) power-on and brake release go
        over the primary interface as controller commands, as urcl does; a URCap program can then only
        be started on the pendant. Refused while a start-up or program restart is under way.
        """
        self._check_commanding()
        async with self._exclusive("start-up"):
            try:
                await self._startup()
            except UrDaemonError as err:
                self._startup_problem = f"start-up failed: {err}"
                raise
            self._startup_problem = ""

    async def _startup(self) -> None:
        board: DashboardLink | None
        try:
            board = await self._dashboard_link()
        except UrDaemonError as err:
            board = None
            log.info("[%s] start-up without the dashboard (%s): using the primary interface", self.name, err)
        self._handed_back = False
        deadline = time.monotonic() + STARTUP_TIMEOUT_S
        try:  # decide on fresh state, not on what the last connection left behind
            await asyncio.wait_for(self._first_package.wait(), STARTUP_TIMEOUT_S)
        except TimeoutError as err:
            raise UrTimeoutError("no RTDE data to start up from") from err
        if self.state.robot_mode not in (RobotMode.IDLE, RobotMode.RUNNING):
            await self._power_step(board, dash.PowerOn(), prim.ControllerCommand.POWER_ON, "power on")
            await self._wait_mode((RobotMode.IDLE, RobotMode.RUNNING), deadline)
        if self.state.robot_mode is not RobotMode.RUNNING:
            await self._power_step(
                board, dash.BrakeRelease(), prim.ControllerCommand.BRAKE_RELEASE, "brake release"
            )
            await self._wait_mode((RobotMode.RUNNING,), deadline)
        if self.robot.headless:
            # the cycle may already have sent it the moment the brakes came off: a second program
            # would replace the first while it is still connecting back
            self._send_program(force=False)
        elif not self.servers.reverse.connected:
            if board is None:
                raise BackendError(
                    "no dashboard to play the External Control program (PolyScope X, or the dashboard "
                    "refused the connection): press play on the pendant, or run headless"
                )
            self._expect_program()
            reply = await board.command(dash.Play())
            if not reply.success:
                raise RobotFaultError(f"play refused: {reply.text}")

    async def _power_step(
        self, board: DashboardLink | None, command: Any, fallback: prim.ControllerCommand, what: str
    ) -> None:
        """One power-on step: on the dashboard, or as a controller command on the primary interface."""
        if board is not None:
            reply = await board.command(command)
            if not reply.success:
                raise RobotFaultError(f"{what} refused: {reply.text}")
            return
        if self._primary is None:
            raise BackendError("not connected to the robot")
        self._primary.send_script(str(fallback))

    async def resend_program(self) -> None:
        """Send the control program again (headless) or play the loaded one (URCap).

        Refused while a start-up or restart is under way, and while the program sent last is still
        connecting back (a second program would only replace it)."""
        self._check_commanding()
        async with self._exclusive("program restart"):
            if self.robot.headless:
                if self._primary is None:
                    raise BackendError("not connected to the robot")
                pending = time.monotonic() - self._program_sent_at
                if self._program_sent_at > self._program_links_up_at and pending < PROGRAM_RESEND_S:
                    raise BackendError(
                        f"the control program sent {pending:.2f} s ago is still connecting back: "
                        "not sending another"
                    )
                self._handed_back = False
                self._send_program(force=True)
            else:
                self._handed_back = False
                self._expect_program()
                reply = await (await self._dashboard_link()).command(dash.Play())
                if not reply.success:
                    raise BackendError(f"play refused: {reply.text}")

    @contextlib.asynccontextmanager
    async def _exclusive(self, what: str) -> AsyncIterator[None]:
        """Run a start-up or program restart alone: refuse (BackendError) while one is under way."""
        if self._program_lock.locked():
            raise BackendError(f"a start-up or program restart is already under way: {what} refused")
        async with self._program_lock:
            yield

    async def hand_back_control(self) -> None:
        """End the control program's loop (a STOPPED frame); in URCap mode the pendant program continues."""
        if not self.servers.reverse.send(reverse.Stopped()):
            raise BackendError("the control program is not connected")
        self._handed_back = True

    # ---- passthrough: the robot interpolates -----------------------------------------------------------

    def passthrough_problem(self) -> str | None:
        """Why a passthrough trajectory cannot start now (None when it can)."""
        if not (self.servers.reverse.connected and self.servers.trajectory.connected):
            return "the control program is not connected (no reverse or trajectory connection)"
        if self._passthrough is not None:
            return f"passthrough goal {self._passthrough[0]} is still running on the robot"
        return None

    def encode_passthrough_point(
        self,
        positions: tuple[float, ...],
        velocities: tuple[float, ...],
        accelerations: tuple[float, ...] | None,
        segment_time: float,
    ) -> bytes:
        """One spline point's 84-byte frame; BackendError for a value the wire cannot carry (a segment
        longer than trajectory_point.MAX_DURATION_S, a non-finite or too large value)."""
        if segment_time > trajectory_point.MAX_DURATION_S:
            raise BackendError(
                f"a segment of {segment_time:.6g} s is longer than the robot can take"
                f" (at most {trajectory_point.MAX_DURATION_S:g} s between two points)"
            )
        try:
            return trajectory_point.encode_point(
                trajectory_point.SplinePoint(positions, velocities, accelerations, segment_time)
            )
        except LocalProtocolError as err:
            raise BackendError(f"cannot send the trajectory to the robot: {err}") from None

    def start_encoded_passthrough(
        self, goal_id: str, frames: bytes, count: int, on_result: Callable[[str, int], None]
    ) -> None:
        """START(count) on the reverse socket, then the pre-encoded points on the trajectory socket.

        Every point was encoded before (``encode_passthrough_point``): a value the wire cannot carry is
        refused before the robot waits for points that would never come, and this is one write."""
        problem = self.passthrough_problem()
        if problem is not None:
            raise BackendError(problem)
        if count <= 0 or len(frames) != count * trajectory_point.FRAME_BYTES:
            raise BackendError(f"{len(frames)} bytes are not {count} encoded trajectory points")
        self._passthrough = (goal_id, on_result)
        self.servers.reverse.send(
            reverse.TrajectoryControl(reverse.TrajectoryAction.START, count, PASSTHROUGH_TIMEOUT_S)
        )
        self.servers.trajectory.write(frames)

    def cancel_passthrough(self) -> None:
        """CANCEL on the reverse socket; the robot answers CANCELED on the trajectory socket."""
        if self._passthrough is not None:
            self._passthrough = None
            self._swallow_result = True  # the robot answers CANCELED (or its SUCCESS crossed our CANCEL)
            self.servers.reverse.send(
                reverse.TrajectoryControl(reverse.TrajectoryAction.CANCEL, 0, PASSTHROUGH_TIMEOUT_S)
            )

    # ---- freedrive, force mode, tool contact -------------------------------------------------------------

    @property
    def freedrive_active(self) -> bool:
        """True while freedrive is on."""
        return self._freedrive_on

    def freedrive(self, active: bool, timeout: float) -> None:
        """Keep freedrive on for ``timeout`` s more (a deadman: it ends when commands stop), or end it now."""
        if not self.servers.reverse.connected:
            raise BackendError("the control program is not connected")
        if active:
            self._freedrive_until = time.monotonic() + timeout
            if not self._freedrive_on:
                self._freedrive_on = True
                self.servers.reverse.send(
                    reverse.FreedriveControl(reverse.FreedriveAction.START, PASSTHROUGH_TIMEOUT_S)
                )
        else:
            self._end_freedrive()

    def _end_freedrive(self) -> None:
        if self._freedrive_on:
            self._freedrive_on = False
            self.servers.reverse.send(
                reverse.FreedriveControl(reverse.FreedriveAction.STOP, PASSTHROUGH_TIMEOUT_S)
            )

    async def force_mode(self, start: object | None) -> None:
        """Start force mode (a ``StartForceMode`` script command) or end it (None)."""
        message = script_command.EndForceMode() if start is None else start
        self._script_command(message, "force mode")

    async def tool_contact(self, start: bool) -> None:
        """Arm tool-contact detection, or end it; the result comes back as a ``tool_contact`` notice."""
        message = script_command.StartToolContact() if start else script_command.EndToolContact()
        self._script_command(message, "tool contact")
        if start:  # ending it leaves it armed: the robot answers CANCELED (or a contact crossed the end)
            self._tool_contact_armed = True

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
        if state.program_running and state.lifecycle is Lifecycle.RUNNING:
            state.lifecycle_reason = ""
        else:  # worded again only when something it depends on changed
            key = (
                state.lifecycle,
                state.robot_mode,
                state.safety_mode,
                servers.reverse.link,
                servers.trajectory.link,
                servers.script_command.link,
                self._handed_back,
                self._lost_link,
                self._program_ended,
                self._startup_problem,
            )
            if key != self._reason_key:
                self._reason_key = key
                self._reason = self._not_running_reason(state)
            state.lifecycle_reason = self._reason
        self._cycles += 1
        self._last_package = time.monotonic()
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
        if (
            not links_up
            and self.robot.headless
            and not self.options.read_only
            and not self._handed_back
            and state.robot_mode is RobotMode.RUNNING
            and state.lifecycle is Lifecycle.RUNNING
            and (
                # no program: send one
                (
                    not self._program_reads_frames()
                    and not servers.trajectory.connected
                    and not servers.script_command.connected
                )
                # the program runs but lost a link: a new program brings every link back
                or (servers.reverse.connected and self._lost_link)
            )
        ):
            self._send_program(force=False)

    @property
    def catching_up(self) -> bool:
        """The RTDE link is delivering a package that a newer one of the same read follows."""
        rtde = self._rtde
        return rtde is not None and rtde.catching_up

    def send_command(self) -> None:
        """This cycle's frame on the reverse socket, at once: publishing the state can wait, the robot
        cannot. Called by the runtime right after the controller's tick (or by the cycle itself)."""
        if self._command_sent:
            return
        self._command_sent = True
        if not self._program_reads_frames():
            return
        reverse_server = self.servers.reverse
        command = self.command
        timeout = self._servo_timeout
        if command.mode is CommandMode.POSITION:
            reverse_server.write(reverse.encode_servoj(command.positions, timeout))
        elif command.mode is CommandMode.VELOCITY:
            reverse_server.send(reverse.SpeedJ(tuple(command.velocities), timeout))
        elif self._freedrive_on:  # hand guiding: keep it alive while the deadman holds
            if time.monotonic() > self._freedrive_until:
                self._end_freedrive()
            else:
                reverse_server.send(
                    reverse.FreedriveControl(reverse.FreedriveAction.NOOP, PASSTHROUGH_TIMEOUT_S)
                )
        elif self._passthrough is not None:  # the robot runs the trajectory: keep it alive
            reverse_server.send(
                reverse.TrajectoryControl(reverse.TrajectoryAction.NOOP, 0, PASSTHROUGH_TIMEOUT_S)
            )
        else:
            reverse_server.send(reverse.Idle(IDLE_TIMEOUT_S))
        rtde = self._rtde
        if rtde is not None:  # package in → command out (issue 5's turnaround)
            self.turnaround.record(time.perf_counter_ns() - rtde.received_ns)

    def _program_reads_frames(self) -> bool:
        """Frames go out only while the program reads them (ur-protocols.md §6.2.5): a paused program
        does not, and frames queued meanwhile would be replayed on play."""
        return self.servers.reverse.connected and self._mapper.runtime_state in (
            RUNTIME_PLAYING,
            RUNTIME_PAUSING,
        )

    def _send_program(self, *, force: bool) -> None:
        now = time.monotonic()
        if self._primary is None or (not force and now - self._program_sent_at < PROGRAM_RESEND_S):
            return
        self._program_sent_at = now
        self._expect_program()
        self._primary.send_script(prim.headless_program(self._program_text()))
        log.info("[%s] control program sent (headless, connecting back to %s)", self.name, self._host_ip)

    def _program_text(self) -> str:
        key = (self._host_ip, self._controller_version)
        if self._program_cache is not None and self._program_cache[0] == key:
            return self._program_cache[1]
        text = self._build_program()
        self._program_cache = (key, text)
        return text

    def _build_program(self) -> str:
        if self._program_builder is not None:
            return self._program_builder(self._host_ip, self.options, self.ports)
        from urdaemon.urscript import ScriptParameters, render_control_script

        return render_control_script(
            ScriptParameters(
                server_ip=self._host_ip,
                reverse_port=self.ports["reverse"],
                trajectory_port=self.ports["trajectory"],
                script_command_port=self.ports["script_command"],
                servoj_lookahead=self.options.servoj_lookahead,
                servoj_gain=self.options.servoj_gain,
                controller_version=self._controller_version,
            )
        )

    # ---- callbacks from the links and servers --------------------------------------------------------------

    def on_link(self, name: str, connected: bool, reason: str) -> None:
        """A callback server's connection came or went."""
        log.info("[%s] %s", self.name, reason)
        if connected:
            started = self._program_started_at
            if all(s.link is not None and s.connected_at >= started for s in self.servers.program_links):
                # the program started last holds every link (not a mix of the old one's and the new one's)
                self._program_links_up_at = time.monotonic()
                self._lost_link = ""
                self._program_ended = ""
                self.servers.program_connected()  # from now on a second connection is a stray
            return
        if name == "reverse":
            self._freedrive_on = False  # the program ended: so did its freedrive
            self._swallow_result = False
            self._lost_link = ""  # the whole program ended (its other links close with it)
        if name in ("reverse", "trajectory"):
            self._end_passthrough(int(trajectory_point.TrajectoryResultCode.FAILURE))
        if name == "script_command":
            self._tool_contact_armed = False  # its result can no longer come
        if (
            name == "script_sender"
            or reason.endswith(REPLACED)
            or self._rtde is None
            or any(s.connected_at < self._program_started_at for s in self.servers.program_links)
        ):
            # a new program's link takes this one's place (the old program's links close while the
            # new one connects), or the daemon closes them
            return
        others = [s.name for s in self.servers.program_links if s.name != name and s.link is not None]
        # (a lost reverse link ends the program: it closes the others itself and is sent again)
        if name != "reverse" and others and not self._lost_link and not self._handed_back:
            # the program runs on without this link: not ready from now, and repaired (headless)
            self._lost_link = name
            log.warning(
                "[%s] the control program lost its %s link (%s still connected): %s",
                self.name,
                name,
                ", ".join(others),
                "restarting the program" if self.robot.headless else "not ready until it is restarted",
            )
        state = self.state
        state.program_running = False
        state.lifecycle_reason = self._not_running_reason(state)
        if self.on_change is not None:
            self.on_change()  # say it now, not at the next cycle or status tick

    def _end_passthrough(self, code: int) -> None:
        """The running passthrough goal (if any) ends with this trajectory result code."""
        if self._passthrough is not None:
            goal_id, on_result = self._passthrough
            self._passthrough = None
            on_result(goal_id, code)

    def on_event(self, name: str, event: Any) -> None:
        """Something arrived on a callback connection."""
        if isinstance(event, trajectory_point.TrajectoryResult):
            if self._swallow_result:  # the answer to our CANCEL: that goal has already ended
                self._swallow_result = False
                return
            self._end_passthrough(int(event.result))
            return
        if isinstance(event, script_command.ToolContactResult):
            if not self._tool_contact_armed:  # nobody asked: not a tool-contact event
                log.warning("[%s] ignored a tool-contact result nobody armed: %s", self.name, event)
                return
            self._tool_contact_armed = False
            outcome = "contact" if event.code == script_command.ToolContactResultCode.SUCCESS else "canceled"
            self.notice("tool_contact", outcome)
            return
        if isinstance(event, script_sender.ProgramRequested) and not self._host_ip:
            # asked before RTDE told us our address: the one the robot just reached us at is right
            link = self.servers.script_sender.link
            sockname = link.transport.get_extra_info("sockname") if link and link.transport else None
            self._host_ip = self.options.reverse_ip or (str(sockname[0]) if sockname else "")
        if isinstance(event, script_sender.ProgramRequested):
            if not self.robot.headless and self.servers.reverse.link is None:
                # the URCap runs it next; a request while a program holds the reverse link (or on a
                # headless robot, whose program the daemon sends itself) opens no way to replace links
                self._expect_program()
            self.servers.script_sender.send(script_sender.Program(self._program_text()))
            log.info("[%s] control program sent to the External Control URCap", self.name)

    def _on_robot_message(self, message: Any) -> None:
        text = ""
        if isinstance(message, prim.RuntimeExceptionMessage):
            text = f"runtime exception at {message.line}:{message.column}: {message.text}"
            log.warning("[%s] %s", self.name, text)
            self._program_ended = text
        elif isinstance(message, prim.ErrorCodeMessage):
            text = f"error C{message.code}A{message.argument}: {message.text}"
            log.warning("[%s] %s", self.name, text)
            self._program_ended = text
        elif isinstance(message, prim.TextMessage | prim.KeyMessage):
            text = (
                message.text if isinstance(message, prim.TextMessage) else f"{message.title}: {message.text}"
            )
            log.info("[%s] robot: %s", self.name, text)
        if text:
            self._report("robot_message", text)

    # ---- helpers ------------------------------------------------------------------------------------

    def _report(self, kind: str, text: str) -> None:
        """Keep the text among the last 20 robot messages and publish it as a notice of this kind."""
        self.robot_messages = [*self.robot_messages[-19:], text]
        self.notice(kind, text)

    async def _check_calibration(self, primary: PrimaryLink) -> None:
        kinematics = await primary.wait_kinematics(KINEMATICS_TIMEOUT_S)
        actual = kinematics.kinematics_hash()
        self.calibration_ok = self.expected_hash is None or actual == self.expected_hash
        if not self.calibration_ok:
            text = (
                f"the robot's kinematics hash is {actual}, the configured calibration's is "
                f"{self.expected_hash}: the URDF does not match this robot "
                "(write its calibration with `urdaemon calibration`)"
            )
            if self.options.calibration_check == "error":
                raise RobotFaultError(text)
            log.warning("[%s] %s", self.name, text)
            self._report("calibration_mismatch", text)

    def _send_inputs(self, fields: dict[str, Any]) -> None:
        self._check_commanding()
        rtde = self._rtde
        if rtde is None:
            raise BackendError("not connected to the robot")
        values = []
        for name in self._inputs:
            value = fields.get(name, 0)
            values.append(float(value) if name in _DOUBLE_INPUTS else int(value))
        rtde.send_inputs(values)

    def _expect_program(self) -> None:
        """A new program is starting: its links may replace the old program's, whose closing links
        are not a loss."""
        self._program_started_at = time.monotonic()
        self.servers.expect_program()

    def _script_command(self, message: Any, what: str) -> None:
        """Send a script command; BackendError (never a traceback) if it cannot be sent or encoded."""
        try:
            sent = self.servers.script_command.send(message)
        except LocalProtocolError as err:  # e.g. a value beyond what the wire's int32 can carry
            raise BackendError(f"cannot send {what} to the robot: {err}") from None
        if not sent:
            raise BackendError("the control program is not connected (no script command link)")

    def _not_running_reason(self, state: RobotState) -> str:
        """Why the robot cannot take motion now, and what to do about it (only while not ready)."""
        facts = ProgramFacts(
            read_only=self.options.read_only,
            headless=self.robot.headless,
            handed_back=self._handed_back,
            lost_link=self._lost_link,
            missing=tuple(self.servers.missing()),
            links=len(self.servers.program_links),
            program_ended=self._program_ended,
            startup_problem=self._startup_problem,
        )
        return not_ready_reason(state, facts)

    def _check_commanding(self) -> None:
        if self.options.read_only:
            raise BackendError("read-only robot (ur.read_only: true): it is watched, not commanded")

    async def _dashboard_link(self) -> DashboardLink:
        """The dashboard connection, opened now if there is none (it does not need the other links)."""
        async with self._dashboard_lock:
            if self._dashboard is None:
                self._dashboard = await DashboardLink.connect(self.address)
            return self._dashboard

    def _clamped_timeout(self) -> float:
        """The servoj/speedj read timeout: the configured one within [one step, 200 ms] (§4.2)."""
        return reverse.clamp_timeout(
            reverse.ControlMode.SERVOJ, self.options.receive_timeout, self._step_time
        )

    def _drop_dashboard(self) -> None:
        if self._dashboard is not None:
            self._dashboard.close()
            self._dashboard = None

    async def _wait_mode(self, modes: tuple[RobotMode, ...], deadline: float) -> None:
        while self.state.robot_mode not in modes:
            if time.monotonic() > deadline:
                raise UrTimeoutError(
                    f"robot mode {self.state.robot_mode.name} did not become {modes[0].name}"
                )
            await asyncio.sleep(0.05)

    def _close_links(self) -> None:
        for link in (self._rtde, self._primary, self._dashboard):
            if link is not None:
                link.close()
        for server in self.servers.all:
            if server.link is not None:
                server.link.close()
        self._rtde = self._primary = self._dashboard = None
        self._lost_link = ""


def _forget_robot(state: RobotState) -> None:
    """Say nothing is known about the robot (its link is down): modes unknown, no program."""
    state.robot_mode = RobotMode.DISCONNECTED
    state.safety_mode = SafetyMode.UNDEFINED_SAFETY_MODE
    state.program_running = False


_REFUSALS = ("could not understand", "failed to execute", "error")


def _is_refusal(text: str) -> bool:
    """Whether a dashboard reply to a line the codec does not type says it was refused."""
    lowered = text.strip().lower()
    return not lowered or lowered.startswith(_REFUSALS)


_DOUBLE_INPUTS = {"speed_slider_fraction", "standard_analog_output_0", "standard_analog_output_1"}
