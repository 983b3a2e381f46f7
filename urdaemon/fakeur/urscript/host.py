"""What URScript builtins act on: one ``ScriptHost`` per running program, made by the controller."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from urdaemon.fakeur.arm import FakeArm

__all__ = ["ScriptHost"]


class ScriptHost:
    """The fake controller as a program's builtins see it.

    ``message(kind, text)``: kind ``"text"`` (textmsg), ``"popup"`` or ``"runtime"``; the controller turns
    these into primary-interface robot messages. ``thread`` is the handle of the thread the scheduler is
    running (0 = the main program). ``motion`` and ``sockets`` belong to lib_motion and lib_sockets, which
    create them on first use.
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
    ) -> None:
        self.arm = arm
        self.step_time = step_time
        self.series = series
        self.version = version
        self.local_address = local_address
        self.message = message
        self.thread = 0
        self.motion: Any = None
        self.sockets: Any = None

    @property
    def now(self) -> float:
        """Controller time (s): the arm's clock."""
        return self.arm.timestamp
