"""The daemon's RTDE link: handshake, then every output package clocks one robot cycle.

The shell (``urdaemon.shell``) around the sans-IO ``RtdeConnection``: during the handshake each request
waits on a future for its reply; once streaming, ``data_received`` decodes each DATA_PACKAGE and
calls ``on_package(values)`` synchronously, in the same turn of the loop (the robot is the clock).
When one read brings several packages (the loop was held up and they queued in the socket), the
older ones are delivered with ``catching_up`` set: the controller keeps the robot's time with them,
but only the newest sends a command and publishes. Commands for states the robot has already left
would be useless to it, and a full cycle for every package of every robot's backlog would hold the
loop up further (docs/protocols.md §4.2: the program's read waits only the frame's timeout,
``ur.receive_timeout``).
``StateMapper`` copies a package's values into ``RobotState`` through indices computed once.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

from urdaemon.errors import ConnectionLostError, RemoteProtocolError, UrTimeoutError
from urdaemon.model import (
    CONFIGURABLE_IO_SHIFT,
    IO_SIZES,
    STANDARD_IO_SHIFT,
    TOOL_IO_SHIFT,
    Lifecycle,
    RobotMode,
    RobotState,
    SafetyMode,
    analog_output_level,
)
from urdaemon.paths import resource_path
from urdaemon.protocols import rtde
from urdaemon.protocols._buffer import Side
from urdaemon.protocols.rtde_variables import PROGRAM_RUNNING_BIT, RuntimeState
from urdaemon.shell import Shell, connect

__all__ = [
    "RTDE_PORT",
    "RTDE_REPLY_TIMEOUT_S",
    "RtdeLink",
    "StateMapper",
    "input_recipe",
    "output_recipe",
]

_R = TypeVar("_R")

RTDE_PORT = rtde.RTDE_PORT
RTDE_REPLY_TIMEOUT_S = 5.0
"""How long a handshake request may wait for its reply (urcl waits up to 5 s for PAUSE)."""
RUNTIME_PAUSED = int(RuntimeState.PAUSED)
RUNTIME_RESUMING = int(RuntimeState.RESUMING)
_RUNTIME_PLAYING = int(RuntimeState.PLAYING)
"""What a recipe without ``runtime_state`` is taken to report."""


def output_recipe() -> tuple[str, ...]:
    """The standard driver output recipe shipped in resources/rtde."""
    return tuple(resource_path("rtde", "output_recipe.txt").read_text().split())


def input_recipe() -> tuple[str, ...]:
    """The standard driver input recipe shipped in resources/rtde."""
    return tuple(resource_path("rtde", "input_recipe.txt").read_text().split())


class RtdeLink(Shell):
    """One RTDE connection of the daemon to a controller (the shell around ``RtdeConnection``)."""

    def __init__(self, on_package: Callable[[tuple[Any, ...]], None]) -> None:
        super().__init__(rtde.RtdeConnection(Side.DAEMON), "rtde")
        self.conn: rtde.RtdeConnection = self.codec
        self.on_package = on_package
        self.controller_version: rtde.ControllerVersion | None = None
        self.frequency = 0.0
        self._waiter: asyncio.Future[Any] | None = None
        self._waiting_for: tuple[type[Any], ...] = ()
        self._streaming = False
        self.packages = 0
        self.superseded = 0
        """Packages delivered with ``catching_up``: a newer one came in the same read."""
        self.catching_up = False
        """True while ``on_package`` is called with a package that a newer one of the same read follows."""
        self.received_ns = 0
        """``time.perf_counter_ns()`` when the bytes of the latest package reached ``data_received``."""
        self.text_messages: list[rtde.TextMessage] = []

    # ---- connection ------------------------------------------------------------------------------

    @classmethod
    async def connect(
        cls,
        host: str,
        on_package: Callable[[tuple[Any, ...]], None],
        *,
        port: int = RTDE_PORT,
        timeout: float = 5.0,
    ) -> RtdeLink:
        """Open the TCP connection (TCP_NODELAY)."""
        return await connect(lambda: cls(on_package), host, port, timeout=timeout, name="rtde")

    def end(self, reason: Exception) -> None:
        super().end(reason)
        if self._waiter is not None and not self._waiter.done():
            self._waiter.set_exception(reason)

    # ---- handshake ----------------------------------------------------------------------------------

    async def handshake(
        self,
        outputs: Sequence[str],
        inputs: Sequence[str] | None,
        *,
        frequency: float | None = None,
    ) -> rtde.OutputsConfigured:
        """Negotiate v2 (v1 if refused), learn the version, set up outputs (and inputs); not started yet.

        Under v1 ``frequency`` is ignored: the controller streams at its full rate (§1.4)."""
        reply = await self._request(rtde.RequestProtocolVersion(2), rtde.ProtocolVersionReply)
        if not reply.accepted:
            reply = await self._request(rtde.RequestProtocolVersion(1), rtde.ProtocolVersionReply)
            if not reply.accepted:
                raise RemoteProtocolError("rtde: the controller accepts neither protocol version 2 nor 1")
        self.controller_version = await self._request(rtde.GetControllerVersion(), rtde.ControllerVersion)
        top = rtde.max_frequency(self.controller_version.major)
        if self.conn.protocol_version == 1:
            # v1's SETUP_OUTPUTS carries no frequency: the controller streams at its own rate
            self.frequency = top
            request = rtde.SetupOutputs(None, tuple(outputs))
        else:
            self.frequency = top if frequency is None else min(frequency, top)
            request = rtde.SetupOutputs(self.frequency, tuple(outputs))
        configured = await self._request(request, rtde.OutputsConfigured)
        if configured.not_found:
            raise RemoteProtocolError(
                f"rtde: the controller does not know output(s) {', '.join(configured.not_found)}"
            )
        if inputs:
            setup = await self._request(rtde.SetupInputs(tuple(inputs)), rtde.InputsConfigured)
            if setup.not_found:
                raise RemoteProtocolError(
                    f"rtde: the controller does not know input(s) {', '.join(setup.not_found)}"
                )
            if setup.in_use:
                raise RemoteProtocolError(
                    f"rtde: input(s) owned by another client: {', '.join(setup.in_use)}"
                )
        return configured

    async def start(self) -> None:
        """Start the output stream; from now on every package goes to ``on_package``."""
        self._streaming = True
        reply = await self._request(rtde.Start(), rtde.StartReply)
        if not reply.accepted:
            self._streaming = False
            raise RemoteProtocolError("rtde: the controller refused to start the output stream")

    def send_inputs(self, values: Sequence[Any]) -> None:
        """Send one input package (every field of the input recipe, in order)."""
        self.conn.send(rtde.InputData(tuple(values)))
        self.flush()

    async def _request(self, message: Any, reply: type[_R]) -> _R:
        loop = asyncio.get_running_loop()
        if self.closed.done():
            raise self.closed.result() or ConnectionLostError("rtde: closed")
        self._waiter = loop.create_future()
        self._waiting_for = (reply,)
        self.conn.send(message)
        self.flush()
        try:
            answer = await asyncio.wait_for(asyncio.shield(self._waiter), RTDE_REPLY_TIMEOUT_S)
        except TimeoutError as err:
            raise UrTimeoutError(
                f"rtde: no reply to {type(message).__name__} within {RTDE_REPLY_TIMEOUT_S} s"
            ) from err
        finally:
            self._waiter = None
        assert isinstance(answer, reply)
        return answer

    # ---- receiving ------------------------------------------------------------------------------------

    def data_received(self, data: bytes) -> None:
        self.received_ns = time.perf_counter_ns()  # the cycle's turnaround starts here
        if self._streaming and self._waiter is None:  # the 500 Hz path: one whole package, no request
            values = self.conn.receive_output(data)
            if values is not None:
                self.packages += 1
                self.on_package(values)
                return
        super().data_received(data)

    def handle(self, events: list[Any]) -> None:
        """One read's events: replies to the waiting request, and the packages (older ones catching up)."""
        packages: list[tuple[Any, ...]] = []
        for event in events:
            if isinstance(event, rtde.DataPackage):
                self.packages += 1
                if self._streaming:
                    packages.append(event.values)
                if (
                    self._waiter is not None
                    and not self._waiter.done()
                    and rtde.StartReply in self._waiting_for
                ):
                    # a data package before the START reply counts as started (urcl does the same)
                    self._waiter.set_result(rtde.StartReply(True))
            elif isinstance(event, rtde.TextMessage):
                self.text_messages = [*self.text_messages[-19:], event]
            elif (
                self._waiter is not None and not self._waiter.done() and isinstance(event, self._waiting_for)
            ):
                self._waiter.set_result(event)
        if packages:
            newest = packages.pop()
            if packages:
                self.superseded += len(packages)
                self.catching_up = True
                try:
                    for values in packages:
                        self.on_package(values)
                finally:
                    self.catching_up = False
            self.on_package(newest)


class StateMapper:
    """Copies the standard output recipe's values into a ``RobotState`` (indices computed once)."""

    def __init__(self, names: Sequence[str]) -> None:
        index = {name: i for i, name in enumerate(names)}

        def at(name: str) -> int:
            return index.get(name, -1)

        self._timestamp = at("timestamp")
        self._q = at("actual_q")
        self._qd = at("actual_qd")
        self._current = at("actual_current")
        self._scaling = at("speed_scaling")
        self._slider = at("target_speed_fraction")
        self._runtime = at("runtime_state")
        self._robot_mode = at("robot_mode")
        self._safety_mode = at("safety_mode")
        self._status_bits = at("robot_status_bits")
        self._din = at("actual_digital_input_bits")
        self._dout = at("actual_digital_output_bits")
        self._ain = (at("standard_analog_input0"), at("standard_analog_input1"))
        self._aout = (at("standard_analog_output0"), at("standard_analog_output1"))
        self._aio_types = at("analog_io_types")
        if self._aout[0] >= 0 and self._aio_types < 0:
            raise ValueError("a recipe with the analog outputs needs analog_io_types (their domains)")
        self._tool_voltage = at("tool_output_voltage")
        self._payload = at("payload")
        self._payload_cog = at("payload_cog")
        if min(self._timestamp, self._q, self._qd) < 0:
            raise ValueError("the output recipe needs timestamp, actual_q and actual_qd")
        self.runtime_state = int(RuntimeState.STOPPING)
        self._lifecycle = Lifecycle.DISCONNECTED
        self._last_modes: tuple[Any, ...] | None = None
        self._last_dout = -1
        self._last_din = -1

    def apply(self, values: Sequence[Any], state: RobotState) -> None:
        """Write one package's values into ``state`` (in place; also the host receive times).

        The 500 Hz path, kept in one function (a helper call costs ~10 %): the joint vectors are copied
        every time; modes, IO bits and the lifecycle are decoded again only when their raw values change.
        """
        state.controller_time = values[self._timestamp]
        state.positions[:] = values[self._q]
        state.velocities[:] = values[self._qd]
        if self._current >= 0:
            state.efforts[:] = values[self._current]
        state.host_time_ns = time.time_ns()
        state.monotonic_ns = time.monotonic_ns()
        state.cycle += 1
        slider = values[self._slider] if self._slider >= 0 else 1.0
        scaling = values[self._scaling] if self._scaling >= 0 else 1.0
        runtime = values[self._runtime] if self._runtime >= 0 else _RUNTIME_PLAYING
        self.runtime_state = runtime
        state.speed_slider = slider
        # docs/protocols.md §6.2: slider × controller scaling; nothing moves while resuming
        state.speed_scaling = 0.0 if runtime == RUNTIME_RESUMING else slider * scaling
        robot_mode = values[self._robot_mode] if self._robot_mode >= 0 else None
        safety_mode = values[self._safety_mode] if self._safety_mode >= 0 else None
        modes = (robot_mode, safety_mode, runtime)
        if modes != self._last_modes:
            self._last_modes = modes
            if robot_mode is not None:
                state.robot_mode = _robot_mode(robot_mode)
            if safety_mode is not None:
                state.safety_mode = _safety_mode(safety_mode)
            self._lifecycle = _lifecycle(state, runtime)
        if self._status_bits >= 0:
            state.program_running = bool(values[self._status_bits] & PROGRAM_RUNNING_BIT)
        if self._dout >= 0:
            bits = values[self._dout]
            if bits != self._last_dout:
                self._last_dout = bits
                _split_io_bits(bits, state.digital_out, state.configurable_out, state.tool_out)
        if self._din >= 0:
            bits = values[self._din]
            if bits != self._last_din:
                self._last_din = bits
                _split_io_bits(bits, state.digital_in, state.configurable_in, state.tool_in)
        if self._aout[0] >= 0:  # V or A as reported -> the level 0..1 set_io takes, by the domain
            out0, out1, types = values[self._aout[0]], values[self._aout[1]], values[self._aio_types]
            state.analog_out[0] = analog_output_level(out0, bool(types & 0b0100))
            state.analog_out[1] = analog_output_level(out1, bool(types & 0b1000))
        if self._ain[0] >= 0:
            state.analog_in[0] = values[self._ain[0]]
            state.analog_in[1] = values[self._ain[1]]
        if self._tool_voltage >= 0:
            state.tool_voltage = int(values[self._tool_voltage])
        if self._payload >= 0:
            state.payload_mass = values[self._payload]
        if self._payload_cog >= 0:
            cog = values[self._payload_cog]
            if cog != state.payload_cog:
                state.payload_cog = (cog[0], cog[1], cog[2])
        # assigned every time: run() sets CONNECTING / RECOVERING / DISCONNECTED between packages
        state.lifecycle = self._lifecycle

    def forget(self) -> None:
        """Decode everything again from the next package (after a reconnect)."""
        self._last_modes = None
        self._last_dout = self._last_din = -1


def _robot_mode(value: int) -> RobotMode:
    try:
        return RobotMode(value)
    except ValueError:
        return RobotMode.DISCONNECTED


def _safety_mode(value: int) -> SafetyMode:
    try:
        return SafetyMode(value)
    except ValueError:
        return SafetyMode.UNDEFINED_SAFETY_MODE


def _split_io_bits(bits: int, standard: list[bool], configurable: list[bool], tool: list[bool]) -> None:
    """RTDE's digital IO bit field (bits 0-7 standard, 8-15 configurable, 16-17 tool) into the lists."""
    standard[:] = [bool(bits >> i & 1) for i in _STANDARD_BITS]
    configurable[:] = [bool(bits >> i & 1) for i in _CONFIGURABLE_BITS]
    tool[:] = [bool(bits >> i & 1) for i in _TOOL_BITS]


_STANDARD_BITS = range(STANDARD_IO_SHIFT, STANDARD_IO_SHIFT + IO_SIZES["digital"])
_CONFIGURABLE_BITS = range(CONFIGURABLE_IO_SHIFT, CONFIGURABLE_IO_SHIFT + IO_SIZES["configurable"])
_TOOL_BITS = range(TOOL_IO_SHIFT, TOOL_IO_SHIFT + IO_SIZES["tool"])


def _lifecycle(state: RobotState, runtime: int) -> Lifecycle:
    """The daemon's lifecycle state from what RTDE reports."""
    safety = state.safety_mode
    if safety in (
        SafetyMode.ROBOT_EMERGENCY_STOP,
        SafetyMode.SYSTEM_EMERGENCY_STOP,
        SafetyMode.IMMI_EMERGENCY_STOP,
        SafetyMode.PROFISAFE_EMERGENCY_STOP,
    ):
        return Lifecycle.EMERGENCY_STOP
    if safety not in (SafetyMode.NORMAL, SafetyMode.REDUCED):
        return Lifecycle.PROTECTIVE_STOP
    if state.robot_mode is not RobotMode.RUNNING:
        return Lifecycle.IDLE
    if runtime == RUNTIME_PAUSED:
        return Lifecycle.PAUSED
    return Lifecycle.RUNNING
