"""How a G5 server reads a line (§3.2): ``parse_command``, and its answer to a line it does not understand.

The robot side reads every received line with it; the daemon side uses it to refuse a typed command the
server would read as a different one.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Final

from urdaemon.protocols.dashboard._actions import (
    AddToLog,
    BrakeRelease,
    ClearOperationalMode,
    ClosePopup,
    CloseSafetyPopup,
    GenerateFlightReport,
    GenerateSupportFile,
    Load,
    LoadInstallation,
    Pause,
    Play,
    Popup,
    PowerOff,
    PowerOn,
    Quit,
    RestartSafety,
    SaveLog,
    SetOperationalMode,
    SetUserRole,
    Shutdown,
    Stop,
    UnlockProtectiveStop,
)
from urdaemon.protocols.dashboard._events import Command
from urdaemon.protocols.dashboard._queries import (
    GetLoadedProgram,
    GetOperationalMode,
    GetPolyscopeVersion,
    GetProgramState,
    GetRobotMode,
    GetRobotModel,
    GetSafetyMode,
    GetSafetyStatus,
    GetSerialNumber,
    GetUserRole,
    GetVersion,
    IsInRemoteControl,
    IsProgramSaved,
    IsRunning,
)
from urdaemon.protocols.dashboard._wire import ASCII_LOWER

__all__ = ["parse_command", "unknown_command_text"]

_WITHOUT_ARGUMENT: Final[tuple[Callable[[], Command], ...]] = (
    PowerOn, PowerOff, BrakeRelease, Play, Pause, Stop, UnlockProtectiveStop, CloseSafetyPopup,
    ClosePopup, RestartSafety, ClearOperationalMode, GenerateFlightReport, SaveLog, Shutdown, Quit,
    GetRobotMode, GetSafetyMode, GetSafetyStatus, GetProgramState, IsRunning, GetLoadedProgram,
    IsProgramSaved, IsInRemoteControl, GetPolyscopeVersion, GetVersion, GetRobotModel,
    GetSerialNumber, GetOperationalMode, GetUserRole,
)  # fmt: skip
_BY_LINE: Final[dict[str, Callable[[], Command]]] = {
    make().line.translate(ASCII_LOWER): make for make in _WITHOUT_ARGUMENT
}

_WITH_ARGUMENT: Final[tuple[tuple[str, Callable[[str], Command | None]], ...]] = tuple(
    sorted(
        (
            (Load.KEYWORD, Load),
            (LoadInstallation.KEYWORD, LoadInstallation),
            (Popup.KEYWORD, Popup),
            (AddToLog.KEYWORD, AddToLog),
            (SetOperationalMode.KEYWORD, SetOperationalMode.parse_argument),
            (SetUserRole.KEYWORD, SetUserRole.parse_argument),
            (GenerateFlightReport.KEYWORD, GenerateFlightReport),
            (GenerateSupportFile.KEYWORD, GenerateSupportFile),
        ),
        key=lambda entry: -len(entry[0]),  # longest first: "load installation x" is not "load"
    )
)


def parse_command(line: str) -> Command | None:
    """The typed command a G5 server reads in ``line`` (keywords case-insensitive), or None."""
    lowered = line.translate(ASCII_LOWER)
    make = _BY_LINE.get(lowered)
    if make is not None:
        return make()
    for keyword, parse in _WITH_ARGUMENT:
        if lowered.startswith(keyword.translate(ASCII_LOWER) + " ") and len(line) > len(keyword) + 1:
            return parse(line[len(keyword) + 1 :])
    return None


def unknown_command_text(line: str) -> str:
    """What a server answers to a line it does not understand: ``could not understand: '<line>'``,
    lower-case as §3.2 quotes it (the daemon reads any reply that starts so as a refusal)."""
    return f"could not understand: '{line}'"
