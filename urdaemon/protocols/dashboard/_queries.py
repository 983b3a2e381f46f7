"""Dashboard commands that ask (§3.2): one class per query with its typed reply, ``Raw`` for any other
line, and the reply texts a real G5 server gives (for the fake controller and for tests)."""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Final

from urdaemon.model import RobotMode, SafetyMode
from urdaemon.protocols.dashboard._actions import BaseCommand
from urdaemon.protocols.dashboard._wire import OperationalMode, ProgramState, UserRole

__all__ = [
    "GetLoadedProgram",
    "GetOperationalMode",
    "GetPolyscopeVersion",
    "GetProgramState",
    "GetRobotMode",
    "GetRobotModel",
    "GetSafetyMode",
    "GetSafetyStatus",
    "GetSerialNumber",
    "GetUserRole",
    "GetVersion",
    "IsInRemoteControl",
    "IsProgramSaved",
    "IsRunning",
    "LoadedProgramReply",
    "OperationalModeReply",
    "PolyscopeVersionReply",
    "ProgramSavedReply",
    "ProgramStateReply",
    "Raw",
    "RawReply",
    "RemoteControlReply",
    "RobotModeReply",
    "RobotModelReply",
    "RunningReply",
    "SafetyModeReply",
    "SafetyStatusReply",
    "SerialNumberReply",
    "UserRoleReply",
    "VersionReply",
    "loaded_program_text",
    "operational_mode_text",
    "polyscope_version_text",
    "program_saved_text",
    "program_state_text",
    "remote_control_text",
    "robot_mode_text",
    "running_text",
    "safety_mode_text",
    "safety_status_text",
    "user_role_text",
    "version_text",
]

_NUMBER: Final = "[0-9]{1,18}"  # ASCII digits only (\d would take other scripts); 18 fits any build number


@dataclass(frozen=True, slots=True)
class RobotModeReply:
    """Reply to ``robotmode``: ``Robotmode: <MODE>``; ``mode`` is None if the text is anything else."""

    mode: RobotMode | None
    text: str


@dataclass(frozen=True, slots=True)
class SafetyModeReply:
    """Reply to ``safetymode``: ``Safetymode: <MODE>``; ``mode`` is None if the text is anything else."""

    mode: SafetyMode | None
    text: str


@dataclass(frozen=True, slots=True)
class SafetyStatusReply:
    """Reply to ``safetystatus``: ``Safetystatus: <STATUS>`` (words of the safety-mode list, §6.1)."""

    status: SafetyMode | None
    text: str


@dataclass(frozen=True, slots=True)
class ProgramStateReply:
    """Reply to ``programState``: ``<STATE> <program>``; ``state`` is None if the text is anything else."""

    state: ProgramState | None
    program: str | None
    """The program's file name as the server words it, or None if it names none."""
    text: str


@dataclass(frozen=True, slots=True)
class RunningReply:
    """Reply to ``running``: ``Program running: true|false``; ``running`` is None otherwise."""

    running: bool | None
    text: str


@dataclass(frozen=True, slots=True)
class LoadedProgramReply:
    """Reply to ``get loaded program``: ``Loaded program: <path>``; ``path`` is None otherwise."""

    path: str | None
    text: str


@dataclass(frozen=True, slots=True)
class ProgramSavedReply:
    """Reply to ``isProgramSaved``: ``true|false <name>.urp``; ``saved`` is None otherwise."""

    saved: bool | None
    program: str | None
    text: str


@dataclass(frozen=True, slots=True)
class RemoteControlReply:
    """Reply to ``is in remote control``: ``true`` or ``false``; ``remote`` is None otherwise."""

    remote: bool | None
    text: str


@dataclass(frozen=True, slots=True)
class PolyscopeVersionReply:
    """Reply to ``PolyscopeVersion``: ``URSoftware <a.b.c.d> (<date>)``; ``version`` is None otherwise."""

    version: tuple[int, ...] | None
    text: str


@dataclass(frozen=True, slots=True)
class VersionReply:
    """Reply to ``version``: ``a.b.c.d``; ``version`` is None otherwise."""

    version: tuple[int, ...] | None
    text: str


@dataclass(frozen=True, slots=True)
class RobotModelReply:
    """Reply to ``get robot model``: the model if the text starts with ``UR``, else None."""

    model: str | None
    text: str


@dataclass(frozen=True, slots=True)
class SerialNumberReply:
    """Reply to ``get serial number``: the serial if the text starts with ``20``, else None."""

    serial: str | None
    text: str


@dataclass(frozen=True, slots=True)
class OperationalModeReply:
    """Reply to ``get operational mode``: ``NONE|MANUAL|AUTOMATIC``; ``mode`` is None otherwise."""

    mode: OperationalMode | None
    text: str


@dataclass(frozen=True, slots=True)
class UserRoleReply:
    """Reply to ``getUserRole``: one ``UserRole`` word; ``role`` is None otherwise."""

    role: UserRole | None
    text: str


@dataclass(frozen=True, slots=True)
class RawReply:
    """The reply to a ``Raw`` command, undecoded."""

    command: Raw
    text: str


def _match(pattern: str, text: str) -> re.Match[str] | None:
    return re.fullmatch(pattern, text, re.DOTALL)


def _version(dotted: str) -> tuple[int, ...]:
    return tuple(int(part) for part in dotted.split("."))


def _bool(word: str | None) -> bool | None:
    return None if word is None else word == "true"


@dataclass(frozen=True, slots=True)
class GetRobotMode(BaseCommand):
    """``robotmode``: ask the robot mode (§6.1 words)."""

    KEYWORD = "robotmode"

    def decode_reply(self, text: str) -> RobotModeReply:
        """The typed reply for the reply line ``text``."""
        match = _match("Robotmode: ([A-Z0-9_]+)", text)
        return RobotModeReply(RobotMode.__members__.get(match[1]) if match else None, text)


@dataclass(frozen=True, slots=True)
class GetSafetyMode(BaseCommand):
    """``safetymode``: ask the safety mode (§6.1 words)."""

    KEYWORD = "safetymode"

    def decode_reply(self, text: str) -> SafetyModeReply:
        """The typed reply for the reply line ``text``."""
        match = _match("Safetymode: ([A-Z0-9_]+)", text)
        return SafetyModeReply(SafetyMode.__members__.get(match[1]) if match else None, text)


@dataclass(frozen=True, slots=True)
class GetSafetyStatus(BaseCommand):
    """``safetystatus``: ask the safety status (e-Series 5.4+)."""

    KEYWORD = "safetystatus"

    def decode_reply(self, text: str) -> SafetyStatusReply:
        """The typed reply for the reply line ``text``."""
        match = _match("Safetystatus: ([A-Z0-9_]+)", text)
        return SafetyStatusReply(SafetyMode.__members__.get(match[1]) if match else None, text)


@dataclass(frozen=True, slots=True)
class GetProgramState(BaseCommand):
    """``programState``: ask whether the loaded program is stopped, playing or paused."""

    KEYWORD = "programState"

    def decode_reply(self, text: str) -> ProgramStateReply:
        """The typed reply for the reply line ``text``."""
        # urcl wants "<STATE> <program>"; a bare "<STATE>" (empty name, its space stripped) is accepted.
        match = _match("(STOPPED|PLAYING|PAUSED)(?: (.*))?", text)
        if match is None:
            return ProgramStateReply(None, None, text)
        return ProgramStateReply(ProgramState(match[1]), match[2] or None, text)


@dataclass(frozen=True, slots=True)
class IsRunning(BaseCommand):
    """``running``: ask whether a program is running."""

    KEYWORD = "running"

    def decode_reply(self, text: str) -> RunningReply:
        """The typed reply for the reply line ``text``."""
        match = _match("Program running: (true|false)", text)
        return RunningReply(_bool(match[1] if match else None), text)


@dataclass(frozen=True, slots=True)
class GetLoadedProgram(BaseCommand):
    """``get loaded program``: ask the path of the loaded program."""

    KEYWORD = "get loaded program"

    def decode_reply(self, text: str) -> LoadedProgramReply:
        """The typed reply for the reply line ``text``."""
        match = _match("Loaded program: (.+)", text)
        return LoadedProgramReply(match[1] if match else None, text)


@dataclass(frozen=True, slots=True)
class IsProgramSaved(BaseCommand):
    """``isProgramSaved``: ask whether the loaded program has unsaved changes."""

    KEYWORD = "isProgramSaved"

    def decode_reply(self, text: str) -> ProgramSavedReply:
        """The typed reply for the reply line ``text``."""
        match = _match("(true|false)(?: (.*))?", text)
        if match is None:
            return ProgramSavedReply(None, None, text)
        return ProgramSavedReply(_bool(match[1]), match[2] or None, text)


@dataclass(frozen=True, slots=True)
class IsInRemoteControl(BaseCommand):
    """``is in remote control``: ask whether the pendant is in remote mode (e-Series 5.6+)."""

    KEYWORD = "is in remote control"

    def decode_reply(self, text: str) -> RemoteControlReply:
        """The typed reply for the reply line ``text``."""
        match = _match("(true|false)", text)
        return RemoteControlReply(_bool(match[1] if match else None), text)


@dataclass(frozen=True, slots=True)
class GetPolyscopeVersion(BaseCommand):
    """``PolyscopeVersion``: ask the PolyScope version (urcl asks it right after the banner)."""

    KEYWORD = "PolyscopeVersion"

    def decode_reply(self, text: str) -> PolyscopeVersionReply:
        """The typed reply for the reply line ``text``."""
        # urcl cuts between the first space and " ("; the date in parentheses is optional here.
        match = _match(rf"URSoftware ({_NUMBER}(?:\.{_NUMBER})*)(?: \(.*\))?", text)
        return PolyscopeVersionReply(_version(match[1]) if match else None, text)


@dataclass(frozen=True, slots=True)
class GetVersion(BaseCommand):
    """``version``: ask the software version as four dotted numbers."""

    KEYWORD = "version"

    def decode_reply(self, text: str) -> VersionReply:
        """The typed reply for the reply line ``text``."""
        # §3.2 quotes urcl's \d.\d.\d.\d, which would refuse 5.15.0.0; any digit count is accepted.
        match = _match(rf"{_NUMBER}(?:\.{_NUMBER}){{3}}", text)
        return VersionReply(_version(text) if match else None, text)


@dataclass(frozen=True, slots=True)
class GetRobotModel(BaseCommand):
    """``get robot model``: ask the arm model (``UR5``, ``UR10e``, …)."""

    KEYWORD = "get robot model"

    def decode_reply(self, text: str) -> RobotModelReply:
        """The typed reply for the reply line ``text``."""
        return RobotModelReply(text if text.startswith("UR") else None, text)


@dataclass(frozen=True, slots=True)
class GetSerialNumber(BaseCommand):
    """``get serial number``: ask the arm's serial number."""

    KEYWORD = "get serial number"

    def decode_reply(self, text: str) -> SerialNumberReply:
        """The typed reply for the reply line ``text``."""
        return SerialNumberReply(text if text.startswith("20") else None, text)


@dataclass(frozen=True, slots=True)
class GetOperationalMode(BaseCommand):
    """``get operational mode``: ask the operational mode (e-Series 5.6+)."""

    KEYWORD = "get operational mode"

    def decode_reply(self, text: str) -> OperationalModeReply:
        """The typed reply for the reply line ``text``."""
        match = _match("NONE|MANUAL|AUTOMATIC", text)
        return OperationalModeReply(OperationalMode(text) if match else None, text)


@dataclass(frozen=True, slots=True)
class GetUserRole(BaseCommand):
    """``getUserRole``: ask the pendant's user role (CB3 only)."""

    KEYWORD = "getUserRole"

    def decode_reply(self, text: str) -> UserRoleReply:
        """The typed reply for the reply line ``text``."""
        return UserRoleReply(UserRole.__members__.get(text), text)


@dataclass(frozen=True, slots=True)
class Raw:
    """Any other line, sent as given; its reply comes back undecoded as ``RawReply``."""

    line: str

    def decode_reply(self, text: str) -> RawReply:
        """The typed reply for the reply line ``text``."""
        return RawReply(self, text)


# --- reply texts a real G5 server gives (for the fake controller and for tests) -------------------


def robot_mode_text(mode: RobotMode) -> str:
    """Reply to ``robotmode``."""
    return f"Robotmode: {mode.name}"


def safety_mode_text(mode: SafetyMode) -> str:
    """Reply to ``safetymode``."""
    return f"Safetymode: {mode.name}"


def safety_status_text(status: SafetyMode) -> str:
    """Reply to ``safetystatus``."""
    return f"Safetystatus: {status.name}"


def program_state_text(state: ProgramState, program: str | None) -> str:
    """Reply to ``programState``; ``program`` is the loaded program's file name (urcl waits for it)."""
    return state.value if program is None else f"{state.value} {program}"


def running_text(running: bool) -> str:
    """Reply to ``running``."""
    return f"Program running: {'true' if running else 'false'}"


def loaded_program_text(path: str | None) -> str:
    """Reply to ``get loaded program``; None gives the no-program answer seen from real servers."""
    return "No program loaded" if path is None else f"Loaded program: {path}"


def program_saved_text(saved: bool, program: str | None) -> str:
    """Reply to ``isProgramSaved``."""
    word = "true" if saved else "false"
    return word if program is None else f"{word} {program}"


def remote_control_text(remote: bool) -> str:
    """Reply to ``is in remote control``."""
    return "true" if remote else "false"


def polyscope_version_text(version: tuple[int, ...], date: str) -> str:
    """Reply to ``PolyscopeVersion``, e.g. ``URSoftware 5.15.0.0 (Jan 01 2024)``."""
    return f"URSoftware {'.'.join(str(part) for part in version)} ({date})"


def version_text(version: tuple[int, int, int, int]) -> str:
    """Reply to ``version``."""
    return ".".join(str(part) for part in version)


def operational_mode_text(mode: OperationalMode) -> str:
    """Reply to ``get operational mode``."""
    return mode.value


def user_role_text(role: UserRole) -> str:
    """Reply to ``getUserRole``."""
    return role.value
