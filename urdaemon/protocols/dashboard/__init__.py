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

The codec is cut by job: ``_wire`` (port, banner, line rules, the words lines carry), ``_actions`` (commands
that do something and their ``CommandReply``), ``_queries`` (commands that ask, each with its typed reply,
and the texts a server answers), ``_events`` (banner, reply line, what the robot side read; the unions),
``_parsing`` (how a server reads a line) and ``_connection`` (``DashboardConnection``, either side). How a
refusal reads is ``dashboard_refusal``'s, outside this package so that it loads without the codec. This
module states the public API.
"""

from __future__ import annotations

from urdaemon.protocols.dashboard._actions import (
    ActionCommand,
    AddToLog,
    BrakeRelease,
    ClearOperationalMode,
    ClosePopup,
    CloseSafetyPopup,
    CommandReply,
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
from urdaemon.protocols.dashboard._connection import (
    DashboardConnection,
)
from urdaemon.protocols.dashboard._events import (
    Banner,
    Command,
    CommandReceived,
    Event,
    Reply,
    ReplyLine,
    UnknownCommand,
)
from urdaemon.protocols.dashboard._parsing import (
    parse_command,
    unknown_command_text,
)
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
    loaded_program_text,
    operational_mode_text,
    polyscope_version_text,
    program_saved_text,
    program_state_text,
    remote_control_text,
    robot_mode_text,
    running_text,
    safety_mode_text,
    safety_status_text,
    user_role_text,
    version_text,
)
from urdaemon.protocols.dashboard._wire import (
    DASHBOARD_BANNER,
    DASHBOARD_PORT,
    MAX_LINE_BYTES,
    OperationalMode,
    ProgramState,
    UserRole,
)
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
