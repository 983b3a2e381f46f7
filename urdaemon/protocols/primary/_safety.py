"""The robot side's safety reports: the robot messages a controller sends when its safety mode changes.

A controller sends SAFETY_MODE (§2.3) only when the safety mode changes (urcl's ``getSafetyMode`` stays
UNDEFINED until the first one, and its ``sendScriptBlocking`` accepts UNDEFINED for that reason), and
one ERROR_CODE per protective stop: C209 "A protective stop was triggered", argument 0, at WARNING
level (urcl's URSim test ``read_error_code`` expects exactly that one code after ``protective_stop()``;
its ``sendScriptBlocking`` fails on it unless told to ignore warnings).

:class:`SafetyReports` is pure: it is told the safety mode (each controller cycle, say) and returns the
messages to send, in order; the caller owns the sockets and the clock.
"""

from __future__ import annotations

from typing import Final

from urdaemon.model import SafetyMode
from urdaemon.protocols.primary._events import ErrorCodeMessage, RobotMessage, SafetyModeMessage
from urdaemon.protocols.primary._wire import ReportLevel

__all__ = ["PROTECTIVE_STOP_TRIGGERED", "SafetyReports", "protective_stop_error"]

PROTECTIVE_STOP_TRIGGERED: Final = 209
"""ERROR_CODE C209: "A protective stop was triggered" (UR's error code list; urcl's URSim tests)."""
_PROTECTIVE_STOP_TEXT: Final = "A protective stop was triggered"


def protective_stop_error(*, timestamp: int = 0) -> ErrorCodeMessage:
    """The ERROR_CODE a controller sends once per protective stop (C209A0, a warning)."""
    return ErrorCodeMessage(
        PROTECTIVE_STOP_TRIGGERED, 0, ReportLevel.WARNING, 0, 0, _PROTECTIVE_STOP_TEXT, timestamp=timestamp
    )


class SafetyReports:
    """What a controller reports of its safety mode's changes: SAFETY_MODE on every change, and the
    protective stop's ERROR_CODE before it when the new mode is PROTECTIVE_STOP."""

    __slots__ = ("_mode",)

    def __init__(self, mode: SafetyMode = SafetyMode.NORMAL) -> None:
        self._mode = mode
        """The safety mode last reported (or the one the controller started in: not reported)."""

    @property
    def mode(self) -> SafetyMode:
        return self._mode

    def observe(self, mode: SafetyMode, *, timestamp: int = 0) -> tuple[RobotMessage, ...]:
        """The messages to send now that the safety mode is ``mode``: none if it did not change."""
        if mode is self._mode:
            return ()
        self._mode = mode
        report = SafetyModeMessage(0, 0, int(mode), 0, 0, timestamp=timestamp)
        if mode is SafetyMode.PROTECTIVE_STOP:
            return (protective_stop_error(timestamp=timestamp), report)
        return (report,)
