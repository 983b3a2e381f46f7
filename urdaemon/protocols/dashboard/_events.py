"""What each dashboard party receives, besides the typed commands and replies: the banner, a reply line,
a command the robot side read or did not; and the unions ``Command``, ``Reply`` and ``Event``."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TypeAlias

from urdaemon.protocols.dashboard._actions import ActionCommand, CommandReply
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
    LoadedProgramReply,
    OperationalModeReply,
    PolyscopeVersionReply,
    ProgramSavedReply,
    ProgramStateReply,
    Raw,
    RawReply,
    RemoteControlReply,
    RobotModelReply,
    RobotModeReply,
    RunningReply,
    SafetyModeReply,
    SafetyStatusReply,
    SerialNumberReply,
    UserRoleReply,
    VersionReply,
)
from urdaemon.protocols.dashboard._wire import DASHBOARD_BANNER

__all__ = ["Banner", "Command", "CommandReceived", "Event", "Reply", "ReplyLine", "UnknownCommand"]


@dataclass(frozen=True, slots=True)
class Banner:
    """The server's first line (§3.1); the robot side sends it, the daemon side receives it."""

    text: str = DASHBOARD_BANNER
    """The line as received; other PolyScope versions word it differently."""

    @property
    def is_standard(self) -> bool:
        """Whether this is the exact G5 banner."""
        return self.text == DASHBOARD_BANNER


@dataclass(frozen=True, slots=True)
class ReplyLine:
    """One reply line the robot side sends; it answers the oldest unanswered command."""

    text: str


@dataclass(frozen=True, slots=True)
class CommandReceived:
    """Robot side: the daemon sent a command we recognise."""

    command: Command
    line: str
    """The line as received, trailing whitespace stripped."""


@dataclass(frozen=True, slots=True)
class UnknownCommand:
    """Robot side: the daemon sent a line that names no known command (a real server still answers it)."""

    line: str


Command: TypeAlias = (
    ActionCommand | GetRobotMode | GetSafetyMode | GetSafetyStatus | GetProgramState | IsRunning
    | GetLoadedProgram | IsProgramSaved | IsInRemoteControl | GetPolyscopeVersion | GetVersion
    | GetRobotModel | GetSerialNumber | GetOperationalMode | GetUserRole | Raw
)  # fmt: skip
"""Everything the daemon side may send."""

Reply: TypeAlias = (
    CommandReply | RobotModeReply | SafetyModeReply | SafetyStatusReply | ProgramStateReply | RunningReply
    | LoadedProgramReply | ProgramSavedReply | RemoteControlReply | PolyscopeVersionReply | VersionReply
    | RobotModelReply | SerialNumberReply | OperationalModeReply | UserRoleReply | RawReply
)  # fmt: skip
"""What the daemon side receives for a command."""

Event: TypeAlias = Banner | Reply | CommandReceived | UnknownCommand
"""Everything ``receive_data`` returns: Banner and Reply on the daemon side, the rest on the robot side."""
