"""Dashboard commands that do something (§3.2): one class per command, and ``CommandReply``, their reply.

``BaseCommand`` is what every typed command shares (keyword, argument, the line they make); an action adds
the text a real server answers on success and reads its reply as succeeded or not.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import ClassVar, Self, TypeAlias, cast

from urdaemon.protocols.dashboard._wire import ASCII_UPPER, OperationalMode, UserRole

__all__ = [
    "ActionCommand",
    "AddToLog",
    "BaseCommand",
    "BrakeRelease",
    "ClearOperationalMode",
    "ClosePopup",
    "CloseSafetyPopup",
    "CommandReply",
    "GenerateFlightReport",
    "GenerateSupportFile",
    "Load",
    "LoadInstallation",
    "Pause",
    "Play",
    "Popup",
    "PowerOff",
    "PowerOn",
    "Quit",
    "RestartSafety",
    "SaveLog",
    "SetOperationalMode",
    "SetUserRole",
    "Shutdown",
    "Stop",
    "UnlockProtectiveStop",
]


@dataclass(frozen=True, slots=True)
class CommandReply:
    """The reply to an action command; ``success`` is a full match of its §3.2 success pattern."""

    command: ActionCommand
    success: bool
    text: str


# --- commands -------------------------------------------------------------------------------------


class BaseCommand:
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


class _Action(BaseCommand):
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
        mode = OperationalMode.__members__.get(text.translate(ASCII_UPPER))
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
        role = UserRole.__members__.get(text.translate(ASCII_UPPER))
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


ActionCommand: TypeAlias = (
    PowerOn | PowerOff | BrakeRelease | Load | Play | Pause | Stop | UnlockProtectiveStop
    | CloseSafetyPopup | ClosePopup | Popup | RestartSafety | SetOperationalMode | ClearOperationalMode
    | AddToLog | LoadInstallation | SetUserRole | GenerateFlightReport | GenerateSupportFile | SaveLog
    | Shutdown | Quit
)  # fmt: skip
"""Commands answered by a ``CommandReply``."""
