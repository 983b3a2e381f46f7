"""What URScript builtins act on: one ``ScriptHost`` per running program, made by the controller."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Final

from urdaemon.fakeur.fake_arm import FakeArm

__all__ = ["WATCHDOG_ACTIONS", "InputRegisters", "ScriptHost", "Watchdog"]

WATCHDOG_ACTIONS: Final = ("ignore", "pause", "stop")
"""What ``rtde_set_watchdog`` may do when an input stops arriving often enough."""


@dataclass
class InputRegisters:
    """The RTDE input registers a client writes and a program reads (``read_input_*_register``).

    Kept apart from the output registers (``arm.io.registers_*``, written by ``write_output_*_register``
    and published as RTDE ``output_*_register_X``): on a controller ``input_int_register_0`` and
    ``output_int_register_0`` are two different registers. The controller keeps one of these for the
    robot's life and hands it to every program's host. Keys: int/double 0..47, bit 0..127."""

    ints: dict[int, int] = field(default_factory=dict)
    doubles: dict[int, float] = field(default_factory=dict)
    bits: dict[int, bool] = field(default_factory=dict)


@dataclass(frozen=True, slots=True)
class Watchdog:
    """A running program's ``rtde_set_watchdog(variable_name, min_frequency, action)`` request.

    The controller checks it each cycle: if no RTDE input package setting ``variable`` arrived for
    longer than ``1 / min_frequency`` seconds (counted from ``since``, the controller time the watchdog
    was set, until the first package), it takes ``action``: ``"ignore"``, ``"pause"`` or ``"stop"``."""

    variable: str
    min_frequency: float
    action: str
    since: float


class ScriptHost:
    """The fake controller as a program's builtins see it.

    ``message(kind, text)``: kind ``"text"`` (textmsg), ``"popup"`` or ``"runtime"``; the controller turns
    these into primary-interface robot messages. ``thread`` is the handle of the thread the scheduler is
    running (0 = the main program). ``motion`` and ``sockets`` belong to lib_motion and lib_sockets, which
    create them on first use; ``config`` to lib_config (force mode parameters and the like).

    ``input_registers``: the robot's RTDE input registers (the controller passes its own; a fresh empty
    set by default). ``watchdogs``: the program's RTDE watchdogs by input variable name, for the
    controller to check each cycle. The controller calls :meth:`close` when the program ends, however it
    ends: the program's sockets are closed then.
    """

    def __init__(
        self,
        arm: FakeArm,
        *,
        step_time: float,
        series: str = "e",
        version: tuple[int, int] = (5, 12),
        local_address: str = "127.0.0.1",
        message: Callable[[str, str], None] = lambda kind, text: None,
        input_registers: InputRegisters | None = None,
    ) -> None:
        self.arm = arm
        self.step_time = step_time
        self.series = series
        self.version = version
        self.local_address = local_address
        self.message = message
        self.input_registers = input_registers if input_registers is not None else InputRegisters()
        self.watchdogs: dict[str, Watchdog] = {}
        self.thread = 0
        self.motion: Any = None
        self.sockets: Any = None
        self.config: Any = None

    @property
    def now(self) -> float:
        """Controller time (s): the arm's clock."""
        return self.arm.timestamp

    def close(self) -> None:
        """The program has ended: close its sockets (idempotent) and drop its watchdogs."""
        sockets = self.sockets
        if sockets is not None:
            sockets.close_all()
        self.watchdogs.clear()
