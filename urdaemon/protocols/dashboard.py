"""Dashboard server (robot port 29999), PolyScope 3.x/5.x ("G5"): a text line protocol (docs/protocols.md §3).

Wire layout (§3.1); every line is text ended by one ``\\n``::

    robot  → daemon   Connected: Universal Robots Dashboard Server\\n    once, right after connect
    daemon → robot    <keyword>[ <argument>]\\n                          one command per line
    robot  → daemon   <reply>\\n                                         exactly one line per command

    → power on\\n                 ← Powering on\\n
    → robotmode\\n                ← Robotmode: IDLE\\n
    → load /programs/ec.urp\\n    ← Loading program: /programs/ec.urp\\n
    → programState\\n             ← STOPPED ec.urp\\n
    → PolyscopeVersion\\n         ← URSoftware 5.15.0.0 (Jan 01 2024)\\n

Lines carry no ids: the n-th reply answers the n-th command. The daemon side keeps a FIFO of the
commands it sent, so several may be in flight (urcl sends one at a time under a mutex, §3.1).

Decisions where the reference is silent or unverified:

* **Whitespace.** The receiver strips trailing ``" \\t\\n\\v\\f\\r"`` from every line, the set urcl strips
  (§3.1); leading whitespace is kept. ``send`` therefore refuses a line that would not survive this:
  one that contains CR or LF (a Java ``readLine`` server also splits at a bare CR) or ends in
  whitespace (this also refuses empty arguments, ``"load "``).
* **Encoding.** The reference says ASCII, but program paths and popup texts are user text, and the
  controller's file system is UTF-8. We send UTF-8 and decode received lines as UTF-8 with U+FFFD
  for undecodable bytes, as Java's default ``InputStreamReader`` does (unverified for PolyScope).
  Odd bytes inside a line are therefore not a protocol error; an over-long line is.
* **Line cap.** ``MAX_LINE_BYTES``: urcl reads without a limit; real replies are a path plus a short
  prefix, so 4 KiB is generous and still bounds what a broken peer can make us buffer.
* **Banner.** The first received line is reported as ``Banner`` whatever it says, because other
  PolyScope versions word it differently; ``Banner.is_standard`` tells whether it is the G5 text.
* **Refusals are replies, not errors.** A reply that does not match its command's success pattern
  ("Failed to execute: play", "could not understand…") is decoded into the typed reply with
  ``success=False`` or value ``None``, keeping the text (§3.2: failure texts are not enumerated).
  Only a reply with no command waiting for it breaks the protocol. Query values are read as urcl
  reads them, with three widenings noted at the code: ``STOPPED``/``true`` without a program name,
  ``PolyscopeVersion`` without a date, and ``version`` components of more than one digit.
* **Robot side parsing.** Keywords match case-insensitively (``POWER ON``, ``programstate``);
  arguments keep their case (paths are case-sensitive). Whether the real server is case-insensitive
  is unverified: the daemon's typed commands always carry the exact keywords of §3.2, so this
  leniency can only hide a miscased ``Raw`` line. A line that names no known command, or a known
  one with an invalid argument, becomes ``UnknownCommand``; ``unknown_command_text`` gives the
  answer our fake sends, ``could not understand: '<line>'`` (§3.2 quotes "could not understand…";
  the quoted line after it is unverified).
* **Ambiguous commands.** ``load installation x`` is ``LoadInstallation("x")`` on the server, so
  ``send(Load("installation x"))`` is refused: ``send`` refuses every typed command whose line the
  server would read as a different command.
* **Quit.** The server answers ``Disconnected`` and closes (§3.2), so nothing may be sent after ``Quit``.
"""

from __future__ import annotations

import enum
import re
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import ClassVar, Final, Self, TypeAlias, cast

from urdaemon.errors import LocalProtocolError, RemoteProtocolError
from urdaemon.model import RobotMode, SafetyMode
from urdaemon.protocols._buffer import Side
from urdaemon.protocols._codec import Codec
from urdaemon.protocols.dashboard_refusal import REFUSAL_PREFIXES, is_refusal

__all__ = [
    "DASHBOARD_BANNER", "DASHBOARD_PORT", "MAX_LINE_BYTES", "REFUSAL_PREFIXES", "ActionCommand", "AddToLog",
    "Banner",
    "BrakeRelease", "ClearOperationalMode", "ClosePopup", "CloseSafetyPopup", "Command", "CommandReceived",
    "CommandReply", "DashboardConnection", "Event", "GenerateFlightReport", "GenerateSupportFile",
    "GetLoadedProgram", "GetOperationalMode", "GetPolyscopeVersion", "GetProgramState", "GetRobotMode",
    "GetRobotModel", "GetSafetyMode", "GetSafetyStatus", "GetSerialNumber", "GetUserRole", "GetVersion",
    "IsInRemoteControl", "IsProgramSaved", "IsRunning", "Load", "LoadInstallation", "LoadedProgramReply",
    "OperationalMode", "OperationalModeReply", "Pause", "Play", "PolyscopeVersionReply", "Popup",
    "PowerOff", "PowerOn", "ProgramSavedReply", "ProgramState", "ProgramStateReply", "Quit", "Raw",
    "RawReply", "RemoteControlReply", "Reply", "ReplyLine", "RestartSafety", "RobotModeReply",
    "RobotModelReply", "RunningReply", "SafetyModeReply", "SafetyStatusReply", "SaveLog",
    "SerialNumberReply", "SetOperationalMode", "SetUserRole", "Shutdown", "Stop", "UnknownCommand",
    "UnlockProtectiveStop", "UserRole", "UserRoleReply", "VersionReply", "is_refusal", "loaded_program_text",
    "operational_mode_text", "parse_command", "polyscope_version_text", "program_saved_text",
    "program_state_text", "remote_control_text", "robot_mode_text", "running_text", "safety_mode_text",
    "safety_status_text", "unknown_command_text", "user_role_text", "version_text",
]  # fmt: skip

PROTOCOL: Final = "dashboard"
DASHBOARD_PORT: Final = 29999
"""TCP port of the dashboard server on the robot (§0)."""
DASHBOARD_BANNER: Final = "Connected: Universal Robots Dashboard Server"
"""The first line a G5 server sends after connect (§3.1)."""
MAX_LINE_BYTES: Final = 4096
"""Longest line accepted or sent, in bytes without the ``\\n``; our own cap (urcl reads unbounded)."""

_TRAILING_WHITESPACE: Final = " \t\n\v\f\r"  # what urcl's rtrim removes (§3.1)
_TRAILING_WHITESPACE_BYTES: Final = _TRAILING_WHITESPACE.encode("ascii")
_NUMBER: Final = "[0-9]{1,18}"  # ASCII digits only (\d would take other scripts); 18 fits any build number
# Case folding of keywords and mode words is ASCII-only, so it never changes a line's length and
# never maps a non-ASCII letter (KELVIN SIGN, dotless i) onto a keyword.
_ASCII_LOWER: Final = str.maketrans("ABCDEFGHIJKLMNOPQRSTUVWXYZ", "abcdefghijklmnopqrstuvwxyz")
_ASCII_UPPER: Final = str.maketrans("abcdefghijklmnopqrstuvwxyz", "ABCDEFGHIJKLMNOPQRSTUVWXYZ")


class ProgramState(enum.StrEnum):
    """The state word of a ``programState`` reply (§3.2)."""

    STOPPED = "STOPPED"
    PLAYING = "PLAYING"
    PAUSED = "PAUSED"


class OperationalMode(enum.StrEnum):
    """Operational mode words of ``get``/``set operational mode`` (§3.2, e-Series)."""

    NONE = "NONE"
    MANUAL = "MANUAL"
    AUTOMATIC = "AUTOMATIC"


class UserRole(enum.StrEnum):
    """User role words of ``setUserRole``/``getUserRole`` (§3.2, CB3 only)."""

    PROGRAMMER = "PROGRAMMER"
    OPERATOR = "OPERATOR"
    NONE = "NONE"
    LOCKED = "LOCKED"
    RESTRICTED = "RESTRICTED"


# --- events and messages that are not commands ----------------------------------------------------


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


@dataclass(frozen=True, slots=True)
class CommandReply:
    """The reply to an action command; ``success`` is a full match of its §3.2 success pattern."""

    command: ActionCommand
    success: bool
    text: str


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


# --- commands -------------------------------------------------------------------------------------


class _Command:
    """What every typed command shares: a keyword, an optional argument, and the line they make."""

    __slots__ = ()
    KEYWORD: ClassVar[str]

    @property
    def argument(self) -> str | None:
        """The text after the keyword, or None if the command takes none."""
        return None

    @property
    def line(self) -> str:
        """The command as sent, without the newline."""
        argument = self.argument
        return self.KEYWORD if argument is None else f"{self.KEYWORD} {argument}"


class _Action(_Command):
    """A command that does something; its reply is a ``CommandReply``."""

    __slots__ = ()
    SUCCESS: ClassVar[str]
    """What a real server answers on success; ``{argument}`` stands for the argument."""
    PATTERN: ClassVar[str | None] = None
    """Regex the reply must fully match, ``{argument}`` the escaped argument; None = exactly SUCCESS."""

    @property
    def success_text(self) -> str:
        """The reply a real G5 server gives when this command succeeds."""
        return self.SUCCESS.format(argument=self.argument or "")

    def reply_succeeded(self, text: str) -> bool:
        """Whether ``text`` fully matches this command's §3.2 success pattern."""
        if self.PATTERN is None:
            return text == self.success_text
        pattern = self.PATTERN.format(argument=re.escape(self.argument or ""))
        return re.fullmatch(pattern, text, re.DOTALL) is not None

    def decode_reply(self, text: str) -> CommandReply:
        """The typed reply for the reply line ``text``."""
        return CommandReply(cast("ActionCommand", self), self.reply_succeeded(text), text)


@dataclass(frozen=True, slots=True)
class PowerOn(_Action):
    """``power on``: power the arm; it goes to IDLE with brakes engaged."""

    KEYWORD = "power on"
    SUCCESS = "Powering on"


@dataclass(frozen=True, slots=True)
class PowerOff(_Action):
    """``power off``: cut arm power (robot mode POWER_OFF)."""

    KEYWORD = "power off"
    SUCCESS = "Powering off"


@dataclass(frozen=True, slots=True)
class BrakeRelease(_Action):
    """``brake release``: release the brakes (robot mode RUNNING)."""

    KEYWORD = "brake release"
    SUCCESS = "Brake releasing"


@dataclass(frozen=True, slots=True)
class Load(_Action):
    """``load <path>``: load a ``.urp`` program; success names the (possibly resolved) path."""

    path: str
    KEYWORD = "load"
    SUCCESS = "Loading program: {argument}"
    PATTERN = "Loading program: .*{argument}.*"

    @property
    def argument(self) -> str:
        """The program path."""
        return self.path


@dataclass(frozen=True, slots=True)
class Play(_Action):
    """``play``: start (or resume) the loaded program."""

    KEYWORD = "play"
    SUCCESS = "Starting program"


@dataclass(frozen=True, slots=True)
class Pause(_Action):
    """``pause``: pause the running program."""

    KEYWORD = "pause"
    SUCCESS = "Pausing program"


@dataclass(frozen=True, slots=True)
class Stop(_Action):
    """``stop``: stop the running program."""

    KEYWORD = "stop"
    SUCCESS = "Stopped"


@dataclass(frozen=True, slots=True)
class UnlockProtectiveStop(_Action):
    """``unlock protective stop``: clear a protective stop."""

    KEYWORD = "unlock protective stop"
    SUCCESS = "Protective stop releasing"


@dataclass(frozen=True, slots=True)
class CloseSafetyPopup(_Action):
    """``close safety popup``: dismiss the safety popup on the teach pendant."""

    KEYWORD = "close safety popup"
    SUCCESS = "closing safety popup"


@dataclass(frozen=True, slots=True)
class ClosePopup(_Action):
    """``close popup``: dismiss an ordinary popup."""

    KEYWORD = "close popup"
    SUCCESS = "closing popup"


@dataclass(frozen=True, slots=True)
class Popup(_Action):
    """``popup <text>``: show a popup on the teach pendant."""

    text: str
    KEYWORD = "popup"
    SUCCESS = "showing popup"

    @property
    def argument(self) -> str:
        """The popup text."""
        return self.text


@dataclass(frozen=True, slots=True)
class RestartSafety(_Action):
    """``restart safety``: restart the safety system after a fault (robot ends in POWER_OFF)."""

    KEYWORD = "restart safety"
    SUCCESS = "Restarting safety"


@dataclass(frozen=True, slots=True)
class SetOperationalMode(_Action):
    """``set operational mode <MANUAL|AUTOMATIC>``: take control of the operational mode (e-Series)."""

    mode: OperationalMode
    KEYWORD = "set operational mode"
    # urcl's command table expects exactly "Operational mode <m> is set"; §3.2 allows text around <m>.
    SUCCESS = "Operational mode {argument} is set"
    PATTERN = "Operational mode .*{argument}.* is set"

    @property
    def argument(self) -> str:
        """The mode word."""
        return self.mode.value

    @classmethod
    def parse_argument(cls, text: str) -> Self | None:
        """The command for the text after the keyword, or None if that text is not valid."""
        mode = OperationalMode.__members__.get(text.translate(_ASCII_UPPER))
        # NONE cannot be set: urcl's success pattern names MANUAL|AUTOMATIC; ClearOperationalMode does that
        return None if mode is None or mode is OperationalMode.NONE else cls(mode)


@dataclass(frozen=True, slots=True)
class ClearOperationalMode(_Action):
    """``clear operational mode``: hand the operational mode back to the teach pendant."""

    KEYWORD = "clear operational mode"
    SUCCESS = "No longer controlling the operational mode."
    PATTERN = r"No longer controlling the operational mode\..*"


@dataclass(frozen=True, slots=True)
class AddToLog(_Action):
    """``addToLog <text>``: write a line to the controller's log."""

    text: str
    KEYWORD = "addToLog"
    SUCCESS = "Added log message"

    @property
    def argument(self) -> str:
        """The log text."""
        return self.text


@dataclass(frozen=True, slots=True)
class LoadInstallation(_Action):
    """``load installation <path>``: load an installation file."""

    path: str
    KEYWORD = "load installation"
    SUCCESS = "Loading installation: {argument}"
    PATTERN = "Loading installation: .*{argument}.*"

    @property
    def argument(self) -> str:
        """The installation path."""
        return self.path


@dataclass(frozen=True, slots=True)
class SetUserRole(_Action):
    """``setUserRole <role>``: restrict the teach pendant (CB3 only)."""

    role: UserRole
    KEYWORD = "setUserRole"
    SUCCESS = "Setting user role: {argument}"

    @property
    def argument(self) -> str:
        """The role word."""
        return self.role.value

    @classmethod
    def parse_argument(cls, text: str) -> Self | None:
        """The command for the text after the keyword, or None if that text is not valid."""
        role = UserRole.__members__.get(text.translate(_ASCII_UPPER))
        return None if role is None else cls(role)


@dataclass(frozen=True, slots=True)
class GenerateFlightReport(_Action):
    """``generate flight report [<type>]``: write a flight report (takes minutes, §3.1)."""

    report_type: str = ""
    """``controller``, ``software`` or ``system``; empty for the server's default."""
    KEYWORD = "generate flight report"
    # The id is the controller's; a fake answers a fixed placeholder.
    SUCCESS = "Flight Report generated with id: 0"
    PATTERN = "Flight Report generated with id:.*"

    @property
    def argument(self) -> str | None:
        """The report type, or None for the default."""
        return self.report_type or None


@dataclass(frozen=True, slots=True)
class GenerateSupportFile(_Action):
    """``generate support file <directory>``: write a support file (takes minutes, §3.1)."""

    directory: str
    KEYWORD = "generate support file"
    SUCCESS = "Completed successfully: {argument}"
    PATTERN = "Completed successfully:.*"

    @property
    def argument(self) -> str:
        """The target directory on the controller."""
        return self.directory


@dataclass(frozen=True, slots=True)
class SaveLog(_Action):
    """``saveLog``: flush the controller's log to disk."""

    KEYWORD = "saveLog"
    SUCCESS = "Log saved to disk"


@dataclass(frozen=True, slots=True)
class Shutdown(_Action):
    """``shutdown``: shut the controller down."""

    KEYWORD = "shutdown"
    SUCCESS = "Shutting down"


@dataclass(frozen=True, slots=True)
class Quit(_Action):
    """``quit``: the server answers ``Disconnected`` and closes the connection."""

    KEYWORD = "quit"
    SUCCESS = "Disconnected"


def _match(pattern: str, text: str) -> re.Match[str] | None:
    return re.fullmatch(pattern, text, re.DOTALL)


def _version(dotted: str) -> tuple[int, ...]:
    return tuple(int(part) for part in dotted.split("."))


def _bool(word: str | None) -> bool | None:
    return None if word is None else word == "true"


@dataclass(frozen=True, slots=True)
class GetRobotMode(_Command):
    """``robotmode``: ask the robot mode (§6.1 words)."""

    KEYWORD = "robotmode"

    def decode_reply(self, text: str) -> RobotModeReply:
        """The typed reply for the reply line ``text``."""
        match = _match("Robotmode: ([A-Z0-9_]+)", text)
        return RobotModeReply(RobotMode.__members__.get(match[1]) if match else None, text)


@dataclass(frozen=True, slots=True)
class GetSafetyMode(_Command):
    """``safetymode``: ask the safety mode (§6.1 words)."""

    KEYWORD = "safetymode"

    def decode_reply(self, text: str) -> SafetyModeReply:
        """The typed reply for the reply line ``text``."""
        match = _match("Safetymode: ([A-Z0-9_]+)", text)
        return SafetyModeReply(SafetyMode.__members__.get(match[1]) if match else None, text)


@dataclass(frozen=True, slots=True)
class GetSafetyStatus(_Command):
    """``safetystatus``: ask the safety status (e-Series 5.4+)."""

    KEYWORD = "safetystatus"

    def decode_reply(self, text: str) -> SafetyStatusReply:
        """The typed reply for the reply line ``text``."""
        match = _match("Safetystatus: ([A-Z0-9_]+)", text)
        return SafetyStatusReply(SafetyMode.__members__.get(match[1]) if match else None, text)


@dataclass(frozen=True, slots=True)
class GetProgramState(_Command):
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
class IsRunning(_Command):
    """``running``: ask whether a program is running."""

    KEYWORD = "running"

    def decode_reply(self, text: str) -> RunningReply:
        """The typed reply for the reply line ``text``."""
        match = _match("Program running: (true|false)", text)
        return RunningReply(_bool(match[1] if match else None), text)


@dataclass(frozen=True, slots=True)
class GetLoadedProgram(_Command):
    """``get loaded program``: ask the path of the loaded program."""

    KEYWORD = "get loaded program"

    def decode_reply(self, text: str) -> LoadedProgramReply:
        """The typed reply for the reply line ``text``."""
        match = _match("Loaded program: (.+)", text)
        return LoadedProgramReply(match[1] if match else None, text)


@dataclass(frozen=True, slots=True)
class IsProgramSaved(_Command):
    """``isProgramSaved``: ask whether the loaded program has unsaved changes."""

    KEYWORD = "isProgramSaved"

    def decode_reply(self, text: str) -> ProgramSavedReply:
        """The typed reply for the reply line ``text``."""
        match = _match("(true|false)(?: (.*))?", text)
        if match is None:
            return ProgramSavedReply(None, None, text)
        return ProgramSavedReply(_bool(match[1]), match[2] or None, text)


@dataclass(frozen=True, slots=True)
class IsInRemoteControl(_Command):
    """``is in remote control``: ask whether the pendant is in remote mode (e-Series 5.6+)."""

    KEYWORD = "is in remote control"

    def decode_reply(self, text: str) -> RemoteControlReply:
        """The typed reply for the reply line ``text``."""
        match = _match("(true|false)", text)
        return RemoteControlReply(_bool(match[1] if match else None), text)


@dataclass(frozen=True, slots=True)
class GetPolyscopeVersion(_Command):
    """``PolyscopeVersion``: ask the PolyScope version (urcl asks it right after the banner)."""

    KEYWORD = "PolyscopeVersion"

    def decode_reply(self, text: str) -> PolyscopeVersionReply:
        """The typed reply for the reply line ``text``."""
        # urcl cuts between the first space and " ("; the date in parentheses is optional here.
        match = _match(rf"URSoftware ({_NUMBER}(?:\.{_NUMBER})*)(?: \(.*\))?", text)
        return PolyscopeVersionReply(_version(match[1]) if match else None, text)


@dataclass(frozen=True, slots=True)
class GetVersion(_Command):
    """``version``: ask the software version as four dotted numbers."""

    KEYWORD = "version"

    def decode_reply(self, text: str) -> VersionReply:
        """The typed reply for the reply line ``text``."""
        # §3.2 quotes urcl's \d.\d.\d.\d, which would refuse 5.15.0.0; any digit count is accepted.
        match = _match(rf"{_NUMBER}(?:\.{_NUMBER}){{3}}", text)
        return VersionReply(_version(text) if match else None, text)


@dataclass(frozen=True, slots=True)
class GetRobotModel(_Command):
    """``get robot model``: ask the arm model (``UR5``, ``UR10e``, …)."""

    KEYWORD = "get robot model"

    def decode_reply(self, text: str) -> RobotModelReply:
        """The typed reply for the reply line ``text``."""
        return RobotModelReply(text if text.startswith("UR") else None, text)


@dataclass(frozen=True, slots=True)
class GetSerialNumber(_Command):
    """``get serial number``: ask the arm's serial number."""

    KEYWORD = "get serial number"

    def decode_reply(self, text: str) -> SerialNumberReply:
        """The typed reply for the reply line ``text``."""
        return SerialNumberReply(text if text.startswith("20") else None, text)


@dataclass(frozen=True, slots=True)
class GetOperationalMode(_Command):
    """``get operational mode``: ask the operational mode (e-Series 5.6+)."""

    KEYWORD = "get operational mode"

    def decode_reply(self, text: str) -> OperationalModeReply:
        """The typed reply for the reply line ``text``."""
        match = _match("NONE|MANUAL|AUTOMATIC", text)
        return OperationalModeReply(OperationalMode(text) if match else None, text)


@dataclass(frozen=True, slots=True)
class GetUserRole(_Command):
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


ActionCommand: TypeAlias = (
    PowerOn | PowerOff | BrakeRelease | Load | Play | Pause | Stop | UnlockProtectiveStop
    | CloseSafetyPopup | ClosePopup | Popup | RestartSafety | SetOperationalMode | ClearOperationalMode
    | AddToLog | LoadInstallation | SetUserRole | GenerateFlightReport | GenerateSupportFile | SaveLog
    | Shutdown | Quit
)  # fmt: skip
"""Commands answered by a ``CommandReply``."""

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


# --- robot side parsing ---------------------------------------------------------------------------

_WITHOUT_ARGUMENT: Final[tuple[Callable[[], Command], ...]] = (
    PowerOn, PowerOff, BrakeRelease, Play, Pause, Stop, UnlockProtectiveStop, CloseSafetyPopup,
    ClosePopup, RestartSafety, ClearOperationalMode, GenerateFlightReport, SaveLog, Shutdown, Quit,
    GetRobotMode, GetSafetyMode, GetSafetyStatus, GetProgramState, IsRunning, GetLoadedProgram,
    IsProgramSaved, IsInRemoteControl, GetPolyscopeVersion, GetVersion, GetRobotModel,
    GetSerialNumber, GetOperationalMode, GetUserRole,
)  # fmt: skip
_BY_LINE: Final[dict[str, Callable[[], Command]]] = {
    make().line.translate(_ASCII_LOWER): make for make in _WITHOUT_ARGUMENT
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
    lowered = line.translate(_ASCII_LOWER)
    make = _BY_LINE.get(lowered)
    if make is not None:
        return make()
    for keyword, parse in _WITH_ARGUMENT:
        if lowered.startswith(keyword.translate(_ASCII_LOWER) + " ") and len(line) > len(keyword) + 1:
            return parse(line[len(keyword) + 1 :])
    return None


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


def unknown_command_text(line: str) -> str:
    """What a server answers to a line it does not understand: ``could not understand: '<line>'``,
    lower-case as §3.2 quotes it (the daemon reads any reply that starts so as a refusal)."""
    return f"could not understand: '{line}'"


# --- the connection -------------------------------------------------------------------------------


def _encode_line(text: str, *, allow_empty: bool) -> bytes:
    """``text`` as one wire line; LocalProtocolError if the receiver could not read it back as sent."""
    if not text and not allow_empty:
        raise LocalProtocolError(f"{PROTOCOL}: an empty line is not a command", protocol=PROTOCOL)
    if "\n" in text or "\r" in text:
        raise LocalProtocolError(f"{PROTOCOL}: line break inside {text!r}", protocol=PROTOCOL)
    if text != text.rstrip(_TRAILING_WHITESPACE):
        raise LocalProtocolError(
            f"{PROTOCOL}: {text!r} ends in whitespace, which the receiver strips (§3.1)", protocol=PROTOCOL
        )
    try:
        data = text.encode("utf-8")
    except UnicodeEncodeError as err:
        raise LocalProtocolError(f"{PROTOCOL}: {text!r} is not encodable: {err}", protocol=PROTOCOL) from err
    if len(data) > MAX_LINE_BYTES:
        raise LocalProtocolError(
            f"{PROTOCOL}: line of {len(data)} bytes exceeds {MAX_LINE_BYTES}", protocol=PROTOCOL
        )
    return data + b"\n"


class DashboardConnection(Codec["Command | Banner | ReplyLine", "Event"]):
    """One dashboard connection (§3), for either party: lines in, typed events out.

    Daemon side: ``send(Command)``; events ``Banner`` (first line) then one ``Reply`` per command, in
    order. Robot side: ``send(Banner())`` first, then one ``send(ReplyLine(text))`` per received
    command; events ``CommandReceived`` or ``UnknownCommand``.
    """

    PROTOCOL = PROTOCOL

    def __init__(self, side: Side) -> None:
        # One line plus its newline is the most that may wait undecoded.
        super().__init__(side, MAX_LINE_BYTES + 1)
        self._pending: deque[Command] = deque()  # daemon: sent, not yet answered
        self._owed = 0  # robot: received, not yet answered
        self._banner_done = False  # daemon: banner received; robot: banner sent
        self._quit_sent = False

    @property
    def pending(self) -> tuple[Command, ...]:
        """Daemon side: the commands sent and not yet answered, oldest first."""
        return tuple(self._pending)

    @property
    def replies_owed(self) -> int:
        """Robot side: how many received lines still wait for a reply."""
        return self._owed

    def _encode(self, message: Command | Banner | ReplyLine) -> None:
        """Queue a command (daemon side) or a banner/reply (robot side); LocalProtocolError if not allowed."""
        if self.side is Side.DAEMON:
            if isinstance(message, Banner | ReplyLine):
                raise LocalProtocolError(
                    f"{PROTOCOL}: the daemon side sends commands only", protocol=PROTOCOL
                )
            self._send_command(message)
        elif isinstance(message, Banner):
            self._send_banner(message)
        elif isinstance(message, ReplyLine):
            self._send_reply(message)
        else:
            raise LocalProtocolError(f"{PROTOCOL}: the robot side sends replies only", protocol=PROTOCOL)

    def _send_command(self, command: Command) -> None:
        if self._quit_sent:
            raise LocalProtocolError(f"{PROTOCOL}: quit was sent; the server closes", protocol=PROTOCOL)
        data = _encode_line(command.line, allow_empty=False)
        if not isinstance(command, Raw) and parse_command(command.line) != command:
            raise LocalProtocolError(
                f"{PROTOCOL}: the server would not read {command.line!r} as {command!r}", protocol=PROTOCOL
            )
        self._out += data
        self._pending.append(command)
        self._quit_sent = isinstance(command, Quit)

    def _send_banner(self, banner: Banner) -> None:
        if self._banner_done:
            raise LocalProtocolError(f"{PROTOCOL}: the banner was already sent", protocol=PROTOCOL)
        self._out += _encode_line(banner.text, allow_empty=True)
        self._banner_done = True

    def _send_reply(self, reply: ReplyLine) -> None:
        if not self._banner_done:
            raise LocalProtocolError(f"{PROTOCOL}: send the Banner before any reply", protocol=PROTOCOL)
        if not self._owed:
            raise LocalProtocolError(f"{PROTOCOL}: no command is waiting for a reply", protocol=PROTOCOL)
        self._out += _encode_line(reply.text, allow_empty=True)
        self._owed -= 1

    def _parse(self, events: list[Event]) -> None:
        while (raw := self._buffer.take_line(MAX_LINE_BYTES)) is not None:
            text = raw.rstrip(_TRAILING_WHITESPACE_BYTES).decode("utf-8", errors="replace")
            events.append(self._on_line(text))
            self._consumed += len(raw)

    def _on_line(self, text: str) -> Event:
        if self.side is Side.ROBOT:
            self._owed += 1
            command = parse_command(text)
            return UnknownCommand(text) if command is None else CommandReceived(command, text)
        if not self._banner_done:
            self._banner_done = True
            return Banner(text)
        if not self._pending:
            raise RemoteProtocolError(
                f"{PROTOCOL}: reply {text[:80]!r} with no command waiting for one",
                protocol=PROTOCOL,
                offset=self._consumed,
            )
        return self._pending.popleft().decode_reply(text)
