"""The one hardware interface every backend implements.

A backend owns the robot's clock. ``run`` connects and then, once per robot cycle: updates
``self.state`` in place from the robot, calls ``on_cycle()`` (where the controller writes
``self.command`` and the state is published), then sends ``self.command`` to the robot.
Everything happens on the event loop thread; ``on_cycle`` must not block.
"""

from __future__ import annotations

import abc
import logging
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

from urdaemon.backends.timing import Histogram, LagLimits, LagLog, lag_limits
from urdaemon.errors import BackendError
from urdaemon.model import IO_SIZES, JointCommand, RobotState

PassthroughResult = Callable[[str, int, str | None], None]
"""How a passthrough goal's end is told: (goal id, the trajectory result code, why the daemon's side
ended it, or None for the robot's own result)."""

__all__ = ["IO_KINDS", "Backend", "BackendStatistics", "Diagnoser"]

log = logging.getLogger("urdaemon.backends")

IO_KINDS = tuple(IO_SIZES)
"""Output kinds a ``set_io`` request may name."""


@dataclass(frozen=True, slots=True)
class BackendStatistics:
    """Counters of one backend since start."""

    cycles: int
    missed_cycles: int
    late_cycles: int
    max_lateness_s: float
    reconnects: int


class Diagnoser(Protocol):
    """Gathers what the doctor learns of a robot's controller (backends/ur/diagnosis.py)."""

    async def gather(self) -> dict[str, Any]:
        """The controller's facts, as doctor/checks.py reads them; bounded in time."""
        ...


class Backend(abc.ABC):
    """Reads state and writes commands for one robot at the robot's rate."""

    kind: str = ""

    def __init__(
        self, name: str, joint_names: Sequence[str], rate_hz: float, *, lag: LagLimits | None = None
    ) -> None:
        self.name = name
        self.rate_hz = rate_hz
        self.period = 1.0 / rate_hz
        self.state = RobotState.zeros(tuple(joint_names))
        self.command = JointCommand.idle(len(joint_names))
        self._cycles = 0
        self._missed = 0
        self._late = 0
        self._max_lateness = 0.0
        self._reconnects = 0
        self.lag_log = LagLog(
            f"robot {name!r} ({self.kind} backend)",
            log,
            period=self.period,
            limits=lag or lag_limits(self.kind),
        )
        """Warns when missed and late cycles cross the backend's limits (``lag``, default its kind's;
        rate-limited, naming the likely cause); ``report_lag`` feeds it once per cycle. Below the
        limits they are only counted."""
        self.turnaround = Histogram()
        """Per cycle, from the robot's state arriving to the command leaving (filled by backends that
        receive their clock from the robot: ``ur``); read and reset with the ``cycle_stats`` service."""
        self.on_change: Callable[[], None] | None = None
        """Set by the runtime: called when the backend changes the state outside a cycle (lifecycle)."""
        self.on_notice: Callable[[str, str], None] | None = None
        """Set by the runtime: ``(kind, text)`` of what the robot or the backend wants users to know."""
        self.diagnosis: Diagnoser | None = None
        """What gathers the doctor's facts of the robot's controller (``ur``: backends/ur/diagnosis.py)."""
        self.tcp: tuple[float, ...] = (0.0,) * 6
        """The TCP offset (x, y, z m, rx, ry, rz rad: the TCP in the tool flange frame) last set with
        ``set_tcp``; the ``ur`` backend starts from the cell file's and keeps its controller's equal."""

    @property
    def catching_up(self) -> bool:
        """True while the cycle runs for a package a newer one already follows (``ur``, after the loop
        was held up): the runtime then ticks the controller only, sends and publishes nothing."""
        return False

    @abc.abstractmethod
    async def run(self, on_cycle: Callable[[], None]) -> None:
        """Connect and run until cancelled, calling ``on_cycle`` once per robot cycle."""

    async def set_io(self, kind: str, pin: int, value: float | bool) -> None:
        """Set one output: ``digital``/``configurable``/``tool`` (bool) or ``analog`` (0..1)."""
        raise BackendError(f"{self.kind} backend has no IO")

    async def set_payload(self, mass: float, cog: tuple[float, float, float]) -> None:
        """Set the payload mass (kg) and centre of gravity (m, tool flange frame)."""
        raise BackendError(f"{self.kind} backend has no payload")

    async def set_tcp(self, pose: Sequence[float]) -> None:
        """Make ``pose`` the TCP offset (``tcp``). A backend whose robot has no controller of its own
        (mock, servo) keeps it; ``ur`` also sets its controller's TCP."""
        self.tcp = self.check_tcp(pose)

    async def set_speed_slider(self, fraction: float) -> None:
        """Set the speed slider (0..1)."""
        raise BackendError(f"{self.kind} backend has no speed slider")

    async def dashboard(self, line: str) -> tuple[bool, str]:
        """Send a dashboard command line; (success, the robot's reply)."""
        raise BackendError(f"{self.kind} backend has no dashboard server")

    async def startup(self) -> None:
        """Power on, release the brakes and start the control program."""
        raise BackendError(f"{self.kind} backend has no start-up to do")

    async def resend_program(self) -> None:
        """Send the control program again."""
        raise BackendError(f"{self.kind} backend runs no control program")

    async def hand_back_control(self) -> None:
        """End the control program's loop so the pendant program continues."""
        raise BackendError(f"{self.kind} backend runs no control program")

    async def zero_ft_sensor(self) -> None:
        """Zero the force/torque sensor."""
        raise BackendError(f"{self.kind} backend has no force/torque sensor")

    async def set_tool_voltage(self, volts: int) -> None:
        """Set the tool voltage (0, 12 or 24 V)."""
        raise BackendError(f"{self.kind} backend has no tool voltage")

    async def doctor_facts(self) -> dict[str, Any] | None:
        """What the doctor learns of the robot's controller (``diagnosis``); None for a backend whose
        robot has none (mock, servo: the daemon's own clock drives it)."""
        return None if self.diagnosis is None else await self.diagnosis.gather()

    def output_reports(self) -> list[dict[str, Any]] | None:
        """Each output device's condition and counters (``servo``: its boards and serial ports), as the
        status message's ``outputs`` carries them; None for a backend whose robot has no such outputs."""
        return None

    def passthrough_problem(self) -> str | None:
        """Why a passthrough trajectory cannot start now (None when it can)."""
        return f"the {self.kind} backend has no robot-side interpolation (passthrough)"

    def encode_passthrough_point(
        self,
        positions: tuple[float, ...],
        velocities: tuple[float, ...],
        accelerations: tuple[float, ...] | None,
        segment_time: float,
    ) -> bytes:
        """One passthrough point as the robot receives it (a few µs: the runtime encodes a goal's
        points in slices before accepting it); BackendError if the robot cannot carry it."""
        raise BackendError(self.passthrough_problem() or "passthrough unavailable")

    def start_encoded_passthrough(
        self, goal_id: str, frames: bytes, count: int, on_result: PassthroughResult
    ) -> None:
        """Send ``count`` points encoded by ``encode_passthrough_point`` (joined) for the robot to run;
        nothing is encoded here, so this costs one write whatever the goal's length."""
        raise BackendError(self.passthrough_problem() or "passthrough unavailable")

    def send_command(self) -> None:
        """Send this cycle's command now, if the backend sends commands itself (``ur``: the reverse
        frame). The runtime calls it right after the controller's tick, before publishing the state;
        backends that apply the command in their own step (mock, servo) do nothing here."""
        return

    @property
    def passthrough_goal(self) -> str | None:
        """The id of the passthrough goal the robot runs itself (None: none runs)."""
        return None

    def cancel_passthrough(self) -> None:
        """Cancel the passthrough trajectory the robot runs (no-op when none runs)."""
        return  # backends without passthrough never have one running

    @property
    def freedrive_active(self) -> bool:
        """True while the robot is in freedrive (hand guiding)."""
        return False

    def freedrive(self, active: bool, timeout: float) -> None:
        """Keep freedrive on for ``timeout`` s more (deadman), or end it now."""
        raise BackendError(f"the {self.kind} backend has no freedrive")

    async def force_mode(self, start: object | None) -> None:
        """Start force mode with a ``StartForceMode`` message, or end it (None)."""
        raise BackendError(f"the {self.kind} backend has no force mode")

    async def tool_contact(self, start: bool) -> None:
        """Arm tool-contact detection, or end it; the outcome arrives as a ``tool_contact`` notice."""
        raise BackendError(f"the {self.kind} backend has no tool contact detection")

    def notice(self, kind: str, text: str) -> None:
        """Tell users something (a robot message, a calibration mismatch)."""
        if self.on_notice is not None:
            self.on_notice(kind, text)

    async def close(self) -> None:
        """Release what outlives one ``run`` (listening sockets); the daemon is stopping."""
        return  # nothing by default: mock and servo hold nothing between runs

    def report_lag(self) -> None:
        """Feed the counts of missed and late cycles to ``lag_log`` (which warns only when they cross the
        backend's limits); call once per cycle after updating them."""
        self.lag_log.update(self._missed, self._late)

    def statistics(self) -> BackendStatistics:
        """Counters since start."""
        return BackendStatistics(self._cycles, self._missed, self._late, self._max_lateness, self._reconnects)

    @staticmethod
    def check_tcp(pose: Sequence[float]) -> tuple[float, ...]:
        """``pose`` as six floats, or ``BackendError`` if it is not six finite numbers (the ranges are
        the service's: cell/robot_options.py ``check_tcp``)."""
        try:
            values = tuple(float(v) for v in pose)
        except (TypeError, ValueError):
            values = ()
        if len(values) != 6 or not all(math.isfinite(v) for v in values):
            raise BackendError(f"a TCP offset is six finite numbers [x, y, z, rx, ry, rz], got {pose!r}")
        return values

    @staticmethod
    def check_io(kind: str, pin: int, value: float | bool, sizes: dict[str, int]) -> None:
        """Raise ``BackendError`` naming what is wrong with an IO request."""
        if kind not in sizes:
            raise BackendError(f"unknown IO kind {kind!r}; expected one of {', '.join(sizes)}")
        if not 0 <= pin < sizes[kind]:
            raise BackendError(f"{kind} output pin {pin} out of range 0..{sizes[kind] - 1}")
        if kind == "analog":
            if (
                isinstance(value, bool)
                or not isinstance(value, int | float)
                or not 0.0 <= float(value) <= 1.0
            ):
                raise BackendError(f"analog output value must be a number in 0..1, got {value!r}")
        elif not isinstance(value, bool):
            raise BackendError(f"{kind} output value must be true or false, got {value!r}")
