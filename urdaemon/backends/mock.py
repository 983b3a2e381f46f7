"""The ``mock`` backend: commands mirrored into state, like ros2_control's mock hardware.

Each cycle the previous command becomes the measured state (one cycle of lag, as on a real arm):
positions are copied (POSITION) or integrated from velocities (VELOCITY). The mock reports a
healthy running robot, acknowledges IO, payload and TCP commands and reflects them in its state
(the TCP offset is kept in ``tcp``: the mock has no controller to send it to).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence

from urdaemon.backends.base import Backend
from urdaemon.backends.clock import PeriodicClock
from urdaemon.errors import BackendError, ConfigError
from urdaemon.model import IO_SIZES, TOOL_VOLTAGES, CommandMode, Lifecycle, RobotMode, SafetyMode

__all__ = ["MockBackend"]


class MockBackend(Backend):
    """A simulated robot that follows its commands exactly."""

    kind = "mock"

    def __init__(
        self,
        name: str,
        joint_names: Sequence[str],
        rate_hz: float,
        *,
        initial_positions: Sequence[float] | None = None,
        speed_scaling: float = 1.0,
        clock: PeriodicClock | None = None,
    ) -> None:
        super().__init__(name, joint_names, rate_hz)
        if initial_positions is not None:
            if len(initial_positions) != len(joint_names):
                raise ConfigError(
                    f"robot {name!r}: initial_positions has {len(initial_positions)} values "
                    f"for {len(joint_names)} joints"
                )
            self.state.positions[:] = [float(v) for v in initial_positions]
        self.command.positions[:] = self.state.positions
        self.runtime_scaling = speed_scaling
        """The controller-side scaling the mock reports, multiplied with the speed slider."""
        self._clock = PeriodicClock(self.period) if clock is None else clock
        """What wakes each cycle and counts the missed and late ones (tests pass a simulated one)."""

    async def run(self, on_cycle: Callable[[], None]) -> None:
        """Cycle at ``rate_hz`` forever."""
        state = self.state
        state.lifecycle = Lifecycle.RUNNING
        state.lifecycle_reason = ""
        state.robot_mode = RobotMode.RUNNING
        state.safety_mode = SafetyMode.NORMAL
        state.program_running = True
        self._clock.start()
        while True:
            await self._clock.wait()
            self.step()
            on_cycle()

    def step(self) -> None:
        """Advance the simulated robot one cycle, applying the last command."""
        state, command, dt = self.state, self.command, self.period
        mode = command.mode
        if mode is CommandMode.POSITION:
            state.positions[:] = command.positions
            state.velocities[:] = command.velocities
        elif mode is CommandMode.VELOCITY:
            positions, velocities = state.positions, command.velocities
            for i in range(len(positions)):
                positions[i] += velocities[i] * dt
            state.velocities[:] = velocities
        else:
            velocities = state.velocities
            for i in range(len(velocities)):
                velocities[i] = 0.0
        state.speed_scaling = state.speed_slider * self.runtime_scaling
        state.controller_time += dt
        state.cycle += 1
        state.host_time_ns = time.time_ns()
        state.monotonic_ns = time.monotonic_ns()
        self._cycles += 1
        self._missed = self._clock.missed
        self._late = self._clock.late
        self._max_lateness = self._clock.max_lateness
        self.report_lag()

    async def set_io(self, kind: str, pin: int, value: float | bool) -> None:
        """Set an output; the state shows it from the next cycle on."""
        self.check_io(kind, pin, value, IO_SIZES)  # a UR controller's outputs
        state = self.state
        if kind == "digital":
            state.digital_out[pin] = bool(value)
        elif kind == "configurable":
            state.configurable_out[pin] = bool(value)
        elif kind == "tool":
            state.tool_out[pin] = bool(value)
        else:
            state.analog_out[pin] = float(value)

    async def set_payload(self, mass: float, cog: tuple[float, float, float]) -> None:
        """Store the payload in the state."""
        if not (math.isfinite(mass) and mass >= 0.0):
            raise BackendError(f"payload mass must be a finite number ≥ 0 kg, got {mass!r}")
        if len(cog) != 3 or not all(math.isfinite(c) for c in cog):
            raise BackendError(f"payload cog must be three finite numbers, got {cog!r}")
        self.state.payload_mass = float(mass)
        self.state.payload_cog = (float(cog[0]), float(cog[1]), float(cog[2]))

    async def set_tool_voltage(self, volts: int) -> None:
        """Store the tool voltage."""
        if volts not in TOOL_VOLTAGES:
            raise BackendError(f"tool voltage must be 0, 12 or 24 V, got {volts!r}")
        self.state.tool_voltage = volts

    async def zero_ft_sensor(self) -> None:
        """Acknowledged: the mock's force/torque reading is always zero."""

    async def startup(self) -> None:
        """Nothing to do: the mock is always running."""

    async def set_speed_slider(self, fraction: float) -> None:
        """Store the slider; the reported speed scaling follows from the next cycle on."""
        if not (math.isfinite(fraction) and 0.0 <= fraction <= 1.0):
            raise BackendError(f"speed slider must be within 0..1, got {fraction!r}")
        self.state.speed_slider = float(fraction)
