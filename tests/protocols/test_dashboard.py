"""Dashboard server codec (docs/protocols.md §3): golden lines, both sides, caps, fuzz and a bring-up pair."""

from __future__ import annotations

import typing
from collections.abc import Callable, Sequence

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.protocols.feeding import feed_all_ways
from urdaemon.errors import LocalProtocolError, RemoteProtocolError
from urdaemon.model import RobotMode, SafetyMode
from urdaemon.protocols import Side
from urdaemon.protocols.dashboard import (
    DASHBOARD_BANNER,
    MAX_LINE_BYTES,
    ActionCommand,
    AddToLog,
    Banner,
    BrakeRelease,
    ClearOperationalMode,
    ClosePopup,
    CloseSafetyPopup,
    Command,
    CommandReceived,
    CommandReply,
    DashboardConnection,
    Event,
    GenerateFlightReport,
    GenerateSupportFile,
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
    Load,
    LoadedProgramReply,
    LoadInstallation,
    OperationalMode,
    OperationalModeReply,
    Pause,
    Play,
    PolyscopeVersionReply,
    Popup,
    PowerOff,
    PowerOn,
    ProgramSavedReply,
    ProgramState,
    ProgramStateReply,
    Quit,
    Raw,
    RawReply,
    RemoteControlReply,
    ReplyLine,
    RestartSafety,
    RobotModelReply,
    RobotModeReply,
    RunningReply,
    SafetyModeReply,
    SafetyStatusReply,
    SaveLog,
    SerialNumberReply,
    SetOperationalMode,
    SetUserRole,
    Shutdown,
    Stop,
    UnknownCommand,
    UnlockProtectiveStop,
    UserRole,
    UserRoleReply,
    VersionReply,
    loaded_program_text,
    operational_mode_text,
    parse_command,
    polyscope_version_text,
    program_saved_text,
    program_state_text,
    remote_control_text,
    robot_mode_text,
    running_text,
    safety_mode_text,
    safety_status_text,
    unknown_command_text,
    user_role_text,
    version_text,
)

BANNER_LINE = b"Connected: Universal Robots Dashboard Server\n"  # §3.1

# Every command of the §3.2 table and the exact line a G5 server expects for it.
COMMAND_LINES: list[tuple[Command, bytes]] = [
    (PowerOn(), b"power on\n"),
    (PowerOff(), b"power off\n"),
    (BrakeRelease(), b"brake release\n"),
    (Load("/programs/external_control.urp"), b"load /programs/external_control.urp\n"),
    (Play(), b"play\n"),
    (Pause(), b"pause\n"),
    (Stop(), b"stop\n"),
    (UnlockProtectiveStop(), b"unlock protective stop\n"),
    (CloseSafetyPopup(), b"close safety popup\n"),
    (ClosePopup(), b"close popup\n"),
    (Popup("Test Popup"), b"popup Test Popup\n"),
    (RestartSafety(), b"restart safety\n"),
    (GetRobotMode(), b"robotmode\n"),
    (GetSafetyMode(), b"safetymode\n"),
    (GetSafetyStatus(), b"safetystatus\n"),
    (GetProgramState(), b"programState\n"),
    (IsRunning(), b"running\n"),
    (GetLoadedProgram(), b"get loaded program\n"),
    (IsProgramSaved(), b"isProgramSaved\n"),
    (IsInRemoteControl(), b"is in remote control\n"),
    (GetPolyscopeVersion(), b"PolyscopeVersion\n"),
    (GetVersion(), b"version\n"),
    (GetRobotModel(), b"get robot model\n"),
    (GetSerialNumber(), b"get serial number\n"),
    (GetOperationalMode(), b"get operational mode\n"),
    (SetOperationalMode(OperationalMode.AUTOMATIC), b"set operational mode AUTOMATIC\n"),
    (ClearOperationalMode(), b"clear operational mode\n"),
    (SetUserRole(UserRole.PROGRAMMER), b"setUserRole PROGRAMMER\n"),
    (GetUserRole(), b"getUserRole\n"),
    (AddToLog("Testing Log:"), b"addToLog Testing Log:\n"),
    (LoadInstallation("default.installation"), b"load installation default.installation\n"),
    (GenerateFlightReport(), b"generate flight report\n"),
    (GenerateFlightReport("controller"), b"generate flight report controller\n"),
    (GenerateSupportFile("."), b"generate support file .\n"),
    (SaveLog(), b"saveLog\n"),
    (Shutdown(), b"shutdown\n"),
    (Quit(), b"quit\n"),
    (Raw("generate flight report system"), b"generate flight report system\n"),
]

# Reply lines as real servers word them (§3.2, urcl's tests, UR's dashboard page) and their decoding.
REPLIES: list[tuple[Command, bytes, Event]] = [
    (PowerOn(), b"Powering on\n", CommandReply(PowerOn(), True, "Powering on")),
    (PowerOff(), b"Powering off\n", CommandReply(PowerOff(), True, "Powering off")),
    (BrakeRelease(), b"Brake releasing\n", CommandReply(BrakeRelease(), True, "Brake releasing")),
    (
        Load("wait_program.urp"),  # the server answers with the resolved path
        b"Loading program: /ursim/programs/wait_program.urp\n",
        CommandReply(Load("wait_program.urp"), True, "Loading program: /ursim/programs/wait_program.urp"),
    ),
    (
        Load("/programs/x.urp"),
        b"File not found: /programs/x.urp\n",
        CommandReply(Load("/programs/x.urp"), False, "File not found: /programs/x.urp"),
    ),
    (
        Load("/programs/x.urp"),
        b"Error while loading program: /programs/x.urp\n",
        CommandReply(Load("/programs/x.urp"), False, "Error while loading program: /programs/x.urp"),
    ),
    (Play(), b"Starting program\n", CommandReply(Play(), True, "Starting program")),
    (Play(), b"Failed to execute: play\n", CommandReply(Play(), False, "Failed to execute: play")),
    (Pause(), b"Pausing program\n", CommandReply(Pause(), True, "Pausing program")),
    (Stop(), b"Stopped\n", CommandReply(Stop(), True, "Stopped")),
    (
        UnlockProtectiveStop(),
        b"Protective stop releasing\n",
        CommandReply(UnlockProtectiveStop(), True, "Protective stop releasing"),
    ),
    (
        CloseSafetyPopup(),
        b"closing safety popup\n",
        CommandReply(CloseSafetyPopup(), True, "closing safety popup"),
    ),
    (ClosePopup(), b"closing popup\n", CommandReply(ClosePopup(), True, "closing popup")),
    (Popup("hi"), b"showing popup\n", CommandReply(Popup("hi"), True, "showing popup")),
    (RestartSafety(), b"Restarting safety\n", CommandReply(RestartSafety(), True, "Restarting safety")),
    (GetRobotMode(), b"Robotmode: POWER_OFF\n", RobotModeReply(RobotMode.POWER_OFF, "Robotmode: POWER_OFF")),
    (GetRobotMode(), b"Robotmode: WARP\n", RobotModeReply(None, "Robotmode: WARP")),
    (GetSafetyMode(), b"Safetymode: NORMAL\n", SafetyModeReply(SafetyMode.NORMAL, "Safetymode: NORMAL")),
    (
        GetSafetyStatus(),
        b"Safetystatus: PROTECTIVE_STOP\n",
        SafetyStatusReply(SafetyMode.PROTECTIVE_STOP, "Safetystatus: PROTECTIVE_STOP"),
    ),
    (
        GetProgramState(),
        b"STOPPED wait_program.urp\n",
        ProgramStateReply(ProgramState.STOPPED, "wait_program.urp", "STOPPED wait_program.urp"),
    ),
    (
        GetProgramState(),
        b"PLAYING external_control.urp\n",
        ProgramStateReply(ProgramState.PLAYING, "external_control.urp", "PLAYING external_control.urp"),
    ),
    (
        GetProgramState(),
        b"PAUSED a b.urp\n",
        ProgramStateReply(ProgramState.PAUSED, "a b.urp", "PAUSED a b.urp"),
    ),
    (GetProgramState(), b"STOPPED\n", ProgramStateReply(ProgramState.STOPPED, None, "STOPPED")),
    (GetProgramState(), b"Stopped\n", ProgramStateReply(None, None, "Stopped")),
    (IsRunning(), b"Program running: true\n", RunningReply(True, "Program running: true")),
    (IsRunning(), b"Program running: false\n", RunningReply(False, "Program running: false")),
    (IsRunning(), b"Robot running: True\n", RunningReply(None, "Robot running: True")),  # CB2 wording
    (
        GetLoadedProgram(),
        b"Loaded program: /ursim/programs/wait_program.urp\n",
        LoadedProgramReply(
            "/ursim/programs/wait_program.urp", "Loaded program: /ursim/programs/wait_program.urp"
        ),
    ),
    (GetLoadedProgram(), b"No program loaded\n", LoadedProgramReply(None, "No program loaded")),
    (
        IsProgramSaved(),
        b"true wait_program.urp\n",
        ProgramSavedReply(True, "wait_program.urp", "true wait_program.urp"),
    ),
    (IsProgramSaved(), b"false\n", ProgramSavedReply(False, None, "false")),
    (IsInRemoteControl(), b"true\n", RemoteControlReply(True, "true")),
    (IsInRemoteControl(), b"false\n", RemoteControlReply(False, "false")),
    (
        GetPolyscopeVersion(),
        b"URSoftware 5.12.6.1102099 (Sep 21 2023)\n",
        PolyscopeVersionReply((5, 12, 6, 1102099), "URSoftware 5.12.6.1102099 (Sep 21 2023)"),
    ),
    (
        GetPolyscopeVersion(),
        b"URSoftware 3.15.7.106331 (Mar 31 2021)\n",
        PolyscopeVersionReply((3, 15, 7, 106331), "URSoftware 3.15.7.106331 (Mar 31 2021)"),
    ),
    (GetPolyscopeVersion(), b"URSoftware 5.15.0\n", PolyscopeVersionReply((5, 15, 0), "URSoftware 5.15.0")),
    (GetPolyscopeVersion(), b"URSoftware five\n", PolyscopeVersionReply(None, "URSoftware five")),
    (GetVersion(), b"5.15.0.12345\n", VersionReply((5, 15, 0, 12345), "5.15.0.12345")),
    (GetVersion(), b"5.15\n", VersionReply(None, "5.15")),
    (GetRobotModel(), b"UR10e\n", RobotModelReply("UR10e", "UR10e")),
    (GetRobotModel(), b"unknown\n", RobotModelReply(None, "unknown")),
    (GetSerialNumber(), b"20235212345\n", SerialNumberReply("20235212345", "20235212345")),
    (GetSerialNumber(), b"\n", SerialNumberReply(None, "")),
    (GetOperationalMode(), b"AUTOMATIC\n", OperationalModeReply(OperationalMode.AUTOMATIC, "AUTOMATIC")),
    (GetOperationalMode(), b"automatic\n", OperationalModeReply(None, "automatic")),
    (
        SetOperationalMode(OperationalMode.MANUAL),
        b"Operational mode 'MANUAL' is set\n",
        CommandReply(SetOperationalMode(OperationalMode.MANUAL), True, "Operational mode 'MANUAL' is set"),
    ),
    (
        SetOperationalMode(OperationalMode.MANUAL),
        b"Operational mode AUTOMATIC is set\n",
        CommandReply(SetOperationalMode(OperationalMode.MANUAL), False, "Operational mode AUTOMATIC is set"),
    ),
    (
        ClearOperationalMode(),
        b"No longer controlling the operational mode. Current operational mode: 'AUTOMATIC'.\n",
        CommandReply(
            ClearOperationalMode(),
            True,
            "No longer controlling the operational mode. Current operational mode: 'AUTOMATIC'.",
        ),
    ),
    (
        SetUserRole(UserRole.OPERATOR),
        b"Setting user role: OPERATOR\n",
        CommandReply(SetUserRole(UserRole.OPERATOR), True, "Setting user role: OPERATOR"),
    ),
    (GetUserRole(), b"PROGRAMMER\n", UserRoleReply(UserRole.PROGRAMMER, "PROGRAMMER")),
    (AddToLog("x"), b"Added log message\n", CommandReply(AddToLog("x"), True, "Added log message")),
    (
        LoadInstallation("default.installation"),
        b"Loading installation: /ursim/programs/default.installation\n",
        CommandReply(
            LoadInstallation("default.installation"),
            True,
            "Loading installation: /ursim/programs/default.installation",
        ),
    ),
    (
        GenerateFlightReport(),
        b"Flight Report generated with id: 4f2a\n",
        CommandReply(GenerateFlightReport(), True, "Flight Report generated with id: 4f2a"),
    ),
    (
        GenerateSupportFile("."),
        b"Completed successfully: /programs/support.zip\n",
        CommandReply(GenerateSupportFile("."), True, "Completed successfully: /programs/support.zip"),
    ),
    (SaveLog(), b"Log saved to disk\n", CommandReply(SaveLog(), True, "Log saved to disk")),
    (Shutdown(), b"Shutting down\n", CommandReply(Shutdown(), True, "Shutting down")),
    (Quit(), b"Disconnected\n", CommandReply(Quit(), True, "Disconnected")),
    (
        PowerOn(),  # a real refusal in local mode (Universal_Robots_ROS_Driver issue #262)
        b"Command is not allowed due to safety reasons, please switch robot to Remote Control mode\n",
        CommandReply(
            PowerOn(),
            False,
            "Command is not allowed due to safety reasons, please switch robot to Remote Control mode",
        ),
    ),
    (Raw("fly"), b"could not understand: 'fly'\n", RawReply(Raw("fly"), "could not understand: 'fly'")),
]

ACTIONS = typing.get_args(ActionCommand)
_TRAILING = " \t\n\v\f\r"
ARGUMENTS = st.text(st.characters(codec="utf-8", exclude_characters="\r\n"), min_size=1, max_size=40).filter(
    lambda text: text == text.rstrip(_TRAILING)
)
"""Argument texts that survive the wire: no line break, no trailing whitespace, encodable."""


def daemon(*commands: Command) -> DashboardConnection:
    """A daemon-side connection that has sent ``commands`` (bytes discarded)."""
    conn = DashboardConnection(Side.DAEMON)
    for command in commands:
        conn.send(command)
    conn.data_to_send()
    return conn


def robot(*, banner: bool = True) -> DashboardConnection:
    """A robot-side connection, its banner already sent (bytes discarded)."""
    conn = DashboardConnection(Side.ROBOT)
    if banner:
        conn.send(Banner())
        conn.data_to_send()
    return conn


def feed_chunked(conn: DashboardConnection, data: bytes, sizes: Sequence[int]) -> list[Event]:
    """Feed ``data`` in chunks of the given sizes (the rest in one piece)."""
    events: list[Event] = []
    offset = 0
    for size in sizes:
        events += conn.receive_data(data[offset : offset + size])
        offset += size
    events += conn.receive_data(data[offset:])
    return events


# --- the command table ---------------------------------------------------------------------------


def test_command_table_covers_every_command_type() -> None:
    assert {type(command) for command, _ in COMMAND_LINES} == set(typing.get_args(Command))


@pytest.mark.parametrize(("command", "line"), COMMAND_LINES, ids=lambda x: repr(x)[:40])
def test_daemon_sends_the_exact_line_of_each_command(command: Command, line: bytes) -> None:
    conn = DashboardConnection(Side.DAEMON)
    conn.send(command)
    assert conn.data_to_send() == line
    assert conn.pending == (command,)
    assert conn.data_to_send() == b""


@pytest.mark.parametrize(("command", "line"), COMMAND_LINES, ids=lambda x: repr(x)[:40])
def test_robot_parses_each_command_line_fed_every_way(command: Command, line: bytes) -> None:
    text = line.decode().rstrip("\n")
    expected = CommandReceived(command, text) if not isinstance(command, Raw) else None
    events = feed_all_ways(lambda: robot(), line)
    if expected is None:  # a Raw line is whatever the server makes of it
        parsed = parse_command(text)
        assert events == [CommandReceived(parsed, text) if parsed else UnknownCommand(text)]
    else:
        assert events == [expected]


def test_every_action_success_text_matches_its_own_pattern() -> None:
    actions = [command for command, _ in COMMAND_LINES if isinstance(command, ACTIONS)]
    assert len(actions) == 23
    for command in actions:
        action = typing.cast(ActionCommand, command)
        assert action.reply_succeeded(action.success_text), action
        assert not action.reply_succeeded("x" + action.success_text), action


# --- daemon side: decoding replies ---------------------------------------------------------------


@pytest.mark.parametrize(("command", "line", "expected"), REPLIES, ids=lambda x: repr(x)[:50])
def test_daemon_decodes_real_reply_lines_fed_every_way(
    command: Command, line: bytes, expected: Event
) -> None:
    events = feed_all_ways(lambda: daemon(command), BANNER_LINE + line)
    assert events == [Banner(DASHBOARD_BANNER), expected]


def test_standard_banner_is_flagged() -> None:
    [banner] = daemon().receive_data(BANNER_LINE)
    assert banner == Banner()
    assert isinstance(banner, Banner)
    assert banner.is_standard


def test_other_banner_wording_is_still_a_banner_and_replies_follow() -> None:
    conn = daemon(GetRobotMode())
    events = conn.receive_data(b"Connected: Universal Robots Dashboard Server 3.x\nRobotmode: IDLE\n")
    assert events == [
        Banner("Connected: Universal Robots Dashboard Server 3.x"),
        RobotModeReply(RobotMode.IDLE, "Robotmode: IDLE"),
    ]
    assert isinstance(events[0], Banner)
    assert not events[0].is_standard


def test_commands_sent_before_the_banner_are_answered_after_it() -> None:
    conn = daemon(PowerOn(), GetRobotMode())
    assert conn.receive_data(BANNER_LINE) == [Banner()]
    assert list(conn.pending) == [PowerOn(), GetRobotMode()]
    assert conn.receive_data(b"Powering on\nRobotmode: POWER_ON\n") == [
        CommandReply(PowerOn(), True, "Powering on"),
        RobotModeReply(RobotMode.POWER_ON, "Robotmode: POWER_ON"),
    ]
    assert conn.pending == ()


@pytest.mark.parametrize("ending", [b"\n", b"\r\n", b" \n", b" \t\x0b\x0c\r\n"])
def test_trailing_whitespace_is_stripped(ending: bytes) -> None:
    events = daemon(Play()).receive_data(BANNER_LINE + b"Starting program" + ending)
    assert events[1] == CommandReply(Play(), True, "Starting program")


def test_leading_whitespace_is_kept_so_the_reply_fails() -> None:
    events = daemon(Play()).receive_data(BANNER_LINE + b" Starting program\n")
    assert events[1] == CommandReply(Play(), False, " Starting program")


def test_undecodable_bytes_become_replacement_characters() -> None:
    events = daemon(GetLoadedProgram()).receive_data(
        BANNER_LINE + b"Loaded program: /programs/\xff\xfe.urp\n"
    )
    assert events[1] == LoadedProgramReply(
        "/programs/\ufffd\ufffd.urp", "Loaded program: /programs/\ufffd\ufffd.urp"
    )


def test_utf8_program_names_decode() -> None:
    line = "Loaded program: /programs/Prüfung.urp\n".encode()
    events = daemon(GetLoadedProgram()).receive_data(BANNER_LINE + line)
    assert events[1] == LoadedProgramReply("/programs/Prüfung.urp", "Loaded program: /programs/Prüfung.urp")


def test_version_digits_are_ascii_only() -> None:
    events = daemon(GetVersion()).receive_data(BANNER_LINE + "5.1٥.0.0\n".encode())
    assert events[1] == VersionReply(None, "5.1٥.0.0")


def test_reply_with_no_command_waiting_is_a_remote_error() -> None:
    conn = daemon()
    assert conn.receive_data(BANNER_LINE) == [Banner()]
    with pytest.raises(RemoteProtocolError) as caught:
        conn.receive_data(b"Powering on\n")
    assert caught.value.protocol == "dashboard"
    assert caught.value.offset == len(BANNER_LINE)


def test_more_replies_than_commands_is_a_remote_error() -> None:
    conn = daemon(Play())
    with pytest.raises(RemoteProtocolError):
        conn.receive_data(BANNER_LINE + b"Starting program\nStarting program\n")


def test_after_a_remote_error_every_call_raises() -> None:
    conn = daemon()
    with pytest.raises(RemoteProtocolError):
        conn.receive_data(BANNER_LINE + b"surprise\n")
    with pytest.raises(RemoteProtocolError):
        conn.receive_data(b"")
    with pytest.raises(LocalProtocolError):
        conn.send(Play())


# --- line length cap -----------------------------------------------------------------------------


@pytest.mark.parametrize("side", [Side.DAEMON, Side.ROBOT])
def test_line_of_max_length_is_accepted(side: Side) -> None:
    conn = DashboardConnection(side)
    events = conn.receive_data(b"x" * MAX_LINE_BYTES + b"\n")
    assert len(events) == 1


@pytest.mark.parametrize("side", [Side.DAEMON, Side.ROBOT])
def test_line_over_max_length_is_refused_before_its_newline_arrives(side: Side) -> None:
    conn = DashboardConnection(side)
    assert conn.receive_data(b"x" * MAX_LINE_BYTES) == []
    with pytest.raises(RemoteProtocolError) as caught:
        conn.receive_data(b"x")
    assert caught.value.protocol == "dashboard"
    with pytest.raises(RemoteProtocolError):
        conn.receive_data(b"\n")


@pytest.mark.parametrize("side", [Side.DAEMON, Side.ROBOT])
def test_huge_chunk_without_newline_is_refused(side: Side) -> None:
    with pytest.raises(RemoteProtocolError):
        DashboardConnection(side).receive_data(b"y" * (10 * MAX_LINE_BYTES))


def test_one_chunk_of_many_short_lines_larger_than_the_cap_is_fine() -> None:
    count = 3 * MAX_LINE_BYTES // len(b"play\n")
    events = robot().receive_data(b"play\n" * count)
    assert events == [CommandReceived(Play(), "play")] * count


# --- robot side ----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("line", "expected"),
    [
        (b"POWER ON\n", PowerOn()),
        (b"polyscopeversion\n", GetPolyscopeVersion()),
        (b"ProgramState\n", GetProgramState()),
        (b"LOAD /Programs/X.urp\n", Load("/Programs/X.urp")),
        (b"Load Installation /programs/A.installation\n", LoadInstallation("/programs/A.installation")),
        (b"load  two spaces.urp\n", Load(" two spaces.urp")),
        (b"Set Operational Mode manual\n", SetOperationalMode(OperationalMode.MANUAL)),
        (b"setuserrole locked\n", SetUserRole(UserRole.LOCKED)),
        (b"play \r\n", Play()),
        (b"popup  a  popup\n", Popup(" a  popup")),
    ],
)
def test_robot_matches_keywords_case_insensitively_and_keeps_arguments(
    line: bytes, expected: Command
) -> None:
    text = line.decode().rstrip(_TRAILING)
    assert feed_all_ways(lambda: robot(), line) == [CommandReceived(expected, text)]


@pytest.mark.parametrize(
    "line",
    [
        b"fly\n",
        b"\n",
        b"load\n",
        b"load \n",
        b" play\n",
        b"power  on\n",
        b"set operational mode NONE\n",
        b"set operational mode fast\n",
        b"setUserRole admin\n",
        "bra\u212ae release\n".encode(),  # KELVIN SIGN folds to k only under Unicode rules
        b"\xff\xfe\n",
    ],
)
def test_robot_reports_lines_it_does_not_understand(line: bytes) -> None:
    conn = robot()
    text = line.rstrip(_TRAILING.encode()).decode("utf-8", errors="replace")
    assert conn.receive_data(line) == [UnknownCommand(text)]
    assert conn.replies_owed == 1
    conn.send(ReplyLine(unknown_command_text(text)))
    assert conn.data_to_send() == f"could not understand: '{text}'\n".encode()
    assert conn.replies_owed == 0


def test_robot_must_send_the_banner_first_and_once() -> None:
    conn = robot(banner=False)
    conn.receive_data(b"play\n")
    with pytest.raises(LocalProtocolError):
        conn.send(ReplyLine("Starting program"))
    conn.send(Banner())
    with pytest.raises(LocalProtocolError):
        conn.send(Banner())
    conn.send(ReplyLine("Starting program"))
    assert conn.data_to_send() == BANNER_LINE + b"Starting program\n"


def test_robot_cannot_reply_when_no_command_waits() -> None:
    conn = robot()
    with pytest.raises(LocalProtocolError):
        conn.send(ReplyLine("Stopped"))
    conn.receive_data(b"stop\nstop\n")
    conn.send(ReplyLine("Stopped"))
    conn.send(ReplyLine("Stopped"))
    with pytest.raises(LocalProtocolError):
        conn.send(ReplyLine("Stopped"))
    assert conn.data_to_send() == b"Stopped\nStopped\n"


def test_robot_side_sends_no_commands_and_daemon_side_no_replies() -> None:
    with pytest.raises(LocalProtocolError):
        robot().send(Play())
    with pytest.raises(LocalProtocolError):
        DashboardConnection(Side.DAEMON).send(Banner())
    with pytest.raises(LocalProtocolError):
        DashboardConnection(Side.DAEMON).send(ReplyLine("Powering on"))


def test_robot_may_send_a_nonstandard_banner_and_an_empty_reply() -> None:
    conn = robot(banner=False)
    conn.send(Banner("Connected: Universal Robots Dashboard Server (old)"))
    conn.receive_data(b"get serial number\n")
    conn.send(ReplyLine(""))
    assert conn.data_to_send() == b"Connected: Universal Robots Dashboard Server (old)\n\n"


@pytest.mark.parametrize("text", ["a\nb", "a\rb", "trailing ", "tab\t", "\ud800"])
def test_robot_refuses_reply_text_the_daemon_could_not_read_back(text: str) -> None:
    conn = robot()
    conn.receive_data(b"play\n")
    with pytest.raises(LocalProtocolError):
        conn.send(ReplyLine(text))
    assert conn.data_to_send() == b""
    conn.send(ReplyLine("Starting program"))  # a refused send does not break the connection
    assert conn.data_to_send() == b"Starting program\n"


# --- daemon side: what it may send ---------------------------------------------------------------


@pytest.mark.parametrize(
    "command",
    [
        Popup("two\nlines"),
        Popup("carriage\rreturn"),
        AddToLog("trailing space "),
        Load(""),
        Raw(""),
        Raw("x" * (MAX_LINE_BYTES + 1)),
        Popup("\ud800"),
        Load("installation default.installation"),  # the server would read load installation
        Load("INSTALLATION default.installation"),
        SetOperationalMode(OperationalMode.NONE),  # NONE is reached by clear operational mode
    ],
    ids=repr,
)
def test_daemon_refuses_commands_the_server_would_misread(command: Command) -> None:
    conn = DashboardConnection(Side.DAEMON)
    with pytest.raises(LocalProtocolError) as caught:
        conn.send(command)
    assert caught.value.protocol == "dashboard"
    assert conn.data_to_send() == b""
    assert conn.pending == ()
    conn.send(Play())  # a refused send does not break the connection
    assert conn.data_to_send() == b"play\n"


def test_daemon_sends_a_raw_line_of_max_length() -> None:
    conn = DashboardConnection(Side.DAEMON)
    conn.send(Raw("x" * MAX_LINE_BYTES))
    assert len(conn.data_to_send()) == MAX_LINE_BYTES + 1


def test_nothing_may_follow_quit() -> None:
    conn = DashboardConnection(Side.DAEMON)
    conn.send(Quit())
    with pytest.raises(LocalProtocolError):
        conn.send(Play())
    assert conn.data_to_send() == b"quit\n"
    assert conn.receive_data(BANNER_LINE + b"Disconnected\n")[1] == CommandReply(Quit(), True, "Disconnected")


# --- round trips: what one side writes, the other side reads -------------------------------------

PLAIN_COMMANDS: list[Command] = [
    PowerOn(), PowerOff(), BrakeRelease(), Play(), Pause(), Stop(), UnlockProtectiveStop(),
    CloseSafetyPopup(), ClosePopup(), RestartSafety(), ClearOperationalMode(), SaveLog(), Shutdown(),
    Quit(), GetRobotMode(), GetSafetyMode(), GetSafetyStatus(), GetProgramState(), IsRunning(),
    GetLoadedProgram(), IsProgramSaved(), IsInRemoteControl(), GetPolyscopeVersion(), GetVersion(),
    GetRobotModel(), GetSerialNumber(), GetOperationalMode(), GetUserRole(),
]  # fmt: skip

COMMANDS: st.SearchStrategy[Command] = st.one_of(
    st.sampled_from(PLAIN_COMMANDS),
    st.builds(Load, ARGUMENTS),
    st.builds(LoadInstallation, ARGUMENTS),
    st.builds(Popup, ARGUMENTS),
    st.builds(AddToLog, ARGUMENTS),
    st.builds(GenerateFlightReport, ARGUMENTS | st.just("")),
    st.builds(GenerateSupportFile, ARGUMENTS),
    st.builds(SetOperationalMode, st.sampled_from([OperationalMode.MANUAL, OperationalMode.AUTOMATIC])),
    st.builds(SetUserRole, st.sampled_from(UserRole)),
)


@given(COMMANDS)
def test_every_command_round_trips_and_its_success_reply_decodes(command: Command) -> None:
    daemon_side, robot_side = daemon(), robot()
    daemon_side.receive_data(BANNER_LINE)
    try:
        daemon_side.send(command)
    except LocalProtocolError:
        assert parse_command(command.line) != command  # refused only when the server would misread it
        return
    assert robot_side.receive_data(daemon_side.data_to_send()) == [CommandReceived(command, command.line)]
    if isinstance(command, ACTIONS):
        action = typing.cast(ActionCommand, command)
        robot_side.send(ReplyLine(action.success_text))
        decoded = daemon_side.receive_data(robot_side.data_to_send())
        assert decoded == [CommandReply(action, True, action.success_text)]


@given(ARGUMENTS)
def test_raw_lines_reach_the_robot_as_typed_or_unknown(line: str) -> None:
    daemon_side = daemon()
    daemon_side.send(Raw(line))
    parsed = parse_command(line)
    expected = CommandReceived(parsed, line) if parsed is not None else UnknownCommand(line)
    assert robot().receive_data(daemon_side.data_to_send()) == [expected]


@given(ARGUMENTS)
def test_banner_round_trips(text: str) -> None:
    conn = robot(banner=False)
    conn.send(Banner(text))
    assert daemon().receive_data(conn.data_to_send()) == [Banner(text)]


def _case(command: Command, text: str, expected: Event) -> tuple[Command, str, Event]:
    return command, text, expected


def _versions(size: int) -> st.SearchStrategy[tuple[int, ...]]:
    return st.tuples(*[st.integers(0, 10**9)] * size)


QUERY_CASES: st.SearchStrategy[tuple[Command, str, Event]] = st.one_of(
    st.sampled_from(RobotMode).map(
        lambda m: _case(GetRobotMode(), robot_mode_text(m), RobotModeReply(m, robot_mode_text(m)))
    ),
    st.sampled_from(SafetyMode).map(
        lambda m: _case(GetSafetyMode(), safety_mode_text(m), SafetyModeReply(m, safety_mode_text(m)))
    ),
    st.sampled_from(SafetyMode).map(
        lambda m: _case(GetSafetyStatus(), safety_status_text(m), SafetyStatusReply(m, safety_status_text(m)))
    ),
    st.tuples(st.sampled_from(ProgramState), st.none() | ARGUMENTS).map(
        lambda a: _case(
            GetProgramState(), program_state_text(*a), ProgramStateReply(a[0], a[1], program_state_text(*a))
        )
    ),
    st.booleans().map(lambda b: _case(IsRunning(), running_text(b), RunningReply(b, running_text(b)))),
    st.booleans().map(
        lambda b: _case(
            IsInRemoteControl(), remote_control_text(b), RemoteControlReply(b, remote_control_text(b))
        )
    ),
    (st.none() | ARGUMENTS).map(
        lambda p: _case(
            GetLoadedProgram(), loaded_program_text(p), LoadedProgramReply(p, loaded_program_text(p))
        )
    ),
    st.tuples(st.booleans(), st.none() | ARGUMENTS).map(
        lambda a: _case(
            IsProgramSaved(), program_saved_text(*a), ProgramSavedReply(a[0], a[1], program_saved_text(*a))
        )
    ),
    st.tuples(
        st.integers(1, 5).flatmap(_versions), st.text(st.characters(codec="utf-8", exclude_characters="\r\n"))
    ).map(
        lambda a: _case(
            GetPolyscopeVersion(),
            polyscope_version_text(*a),
            PolyscopeVersionReply(a[0], polyscope_version_text(*a)),
        )
    ),
    st.tuples(*[st.integers(0, 10**9)] * 4).map(
        lambda v: _case(GetVersion(), version_text(v), VersionReply(v, version_text(v)))
    ),
    st.sampled_from(OperationalMode).map(
        lambda m: _case(
            GetOperationalMode(), operational_mode_text(m), OperationalModeReply(m, operational_mode_text(m))
        )
    ),
    st.sampled_from(UserRole).map(
        lambda r: _case(GetUserRole(), user_role_text(r), UserRoleReply(r, r.value))
    ),
    st.from_regex(r"UR[0-9]{1,2}e?", fullmatch=True).map(
        lambda m: _case(GetRobotModel(), m, RobotModelReply(m, m))
    ),
    st.from_regex(r"20[0-9]{9}", fullmatch=True).map(
        lambda s: _case(GetSerialNumber(), s, SerialNumberReply(s, s))
    ),
)


@given(QUERY_CASES)
def test_query_replies_written_by_the_robot_side_decode_on_the_daemon_side(
    case: tuple[Command, str, Event],
) -> None:
    command, text, expected = case
    daemon_side, robot_side = daemon(), robot(banner=False)
    robot_side.send(Banner())
    daemon_side.send(command)
    robot_side.receive_data(daemon_side.data_to_send())
    robot_side.send(ReplyLine(text))
    assert daemon_side.receive_data(robot_side.data_to_send()) == [Banner(), expected]


# --- fuzz: any bytes give events or RemoteProtocolError, nothing else ----------------------------

CHUNKS = st.lists(st.integers(1, 64), max_size=20)


def events_or_error(
    conn: DashboardConnection, data: bytes, sizes: Sequence[int]
) -> list[Event] | RemoteProtocolError:
    """The events of feeding ``data`` in chunks, or the RemoteProtocolError it raised (any other escapes)."""
    try:
        return feed_chunked(conn, data, sizes)
    except RemoteProtocolError as err:
        return err


@settings(max_examples=400)
@given(st.binary(max_size=600), CHUNKS)
def test_fuzz_daemon_side(data: bytes, sizes: list[int]) -> None:
    conn = daemon(GetRobotMode(), PowerOn(), GetProgramState(), GetPolyscopeVersion(), Load("a.urp"))
    outcome = events_or_error(conn, data, sizes)
    if isinstance(outcome, RemoteProtocolError):
        assert outcome.protocol == "dashboard"
    else:
        assert len(outcome) <= 6  # the banner and five replies at most
        assert all(isinstance(event, typing.get_args(Event)) for event in outcome)


@settings(max_examples=400)
@given(st.binary(max_size=600), CHUNKS)
def test_fuzz_robot_side(data: bytes, sizes: list[int]) -> None:
    conn = robot()
    outcome = events_or_error(conn, data, sizes)
    if isinstance(outcome, RemoteProtocolError):
        assert outcome.protocol == "dashboard"
    else:
        assert all(isinstance(event, CommandReceived | UnknownCommand) for event in outcome)
        assert conn.replies_owed == len(outcome)


@settings(max_examples=40)
@given(st.binary(min_size=MAX_LINE_BYTES - 8, max_size=3 * MAX_LINE_BYTES), CHUNKS, st.sampled_from(Side))
def test_fuzz_long_inputs(data: bytes, sizes: list[int], side: Side) -> None:
    conn = DashboardConnection(side)
    outcome = events_or_error(conn, data, sizes)
    if isinstance(outcome, RemoteProtocolError):
        assert outcome.protocol == "dashboard"
    else:
        assert all(len(getattr(event, "line", "")) <= MAX_LINE_BYTES for event in outcome)


# --- a full bring-up conversation, both sides in memory ------------------------------------------


class FakeController:
    """Just enough of a G5 controller to answer the bring-up sequence (§3.2, "Typical bring-up")."""

    def __init__(self) -> None:
        self.mode = RobotMode.POWER_OFF
        self.program: str | None = None
        self.state = ProgramState.STOPPED

    def answer(self, event: Event) -> str:
        match event:
            case CommandReceived(command=GetPolyscopeVersion()):
                return polyscope_version_text((5, 15, 0, 0), "Jan 01 2024")
            case CommandReceived(command=PowerOn() as command):
                self.mode = RobotMode.IDLE
                return command.success_text
            case CommandReceived(command=BrakeRelease() as command) if self.mode is RobotMode.IDLE:
                self.mode = RobotMode.RUNNING
                return command.success_text
            case CommandReceived(command=Load(path=path) as command):
                self.program = path
                return command.success_text
            case CommandReceived(command=Play() as command) if (
                self.program and self.mode is RobotMode.RUNNING
            ):
                self.state = ProgramState.PLAYING
                return command.success_text
            case CommandReceived(command=Play()):
                return "Failed to execute: play"
            case CommandReceived(command=GetRobotMode()):
                return robot_mode_text(self.mode)
            case CommandReceived(command=GetProgramState()):
                name = None if self.program is None else self.program.rsplit("/", 1)[-1]
                return program_state_text(self.state, name)
            case CommandReceived(command=IsRunning()):
                return running_text(self.state is ProgramState.PLAYING)
            case CommandReceived(line=line) | UnknownCommand(line=line):
                return unknown_command_text(line)
        raise AssertionError(f"not a robot-side event: {event!r}")


def converse(
    daemon_side: DashboardConnection, robot_side: DashboardConnection, answer: Callable[[Event], str]
) -> list[Event]:
    """Carry the daemon's bytes to the robot, ``answer`` each event there, carry the replies back."""
    for event in robot_side.receive_data(daemon_side.data_to_send()):
        robot_side.send(ReplyLine(answer(event)))
    return daemon_side.receive_data(robot_side.data_to_send())


def test_bring_up_conversation() -> None:
    fake = FakeController()
    daemon_side, robot_side = DashboardConnection(Side.DAEMON), DashboardConnection(Side.ROBOT)
    robot_side.send(Banner())
    assert daemon_side.receive_data(robot_side.data_to_send()) == [Banner()]

    steps: list[tuple[Command, Event]] = [
        (GetPolyscopeVersion(), PolyscopeVersionReply((5, 15, 0, 0), "URSoftware 5.15.0.0 (Jan 01 2024)")),
        (Play(), CommandReply(Play(), False, "Failed to execute: play")),
        (PowerOn(), CommandReply(PowerOn(), True, "Powering on")),
        (GetRobotMode(), RobotModeReply(RobotMode.IDLE, "Robotmode: IDLE")),
        (BrakeRelease(), CommandReply(BrakeRelease(), True, "Brake releasing")),
        (GetRobotMode(), RobotModeReply(RobotMode.RUNNING, "Robotmode: RUNNING")),
        (
            Load("/programs/external_control.urp"),
            CommandReply(
                Load("/programs/external_control.urp"),
                True,
                "Loading program: /programs/external_control.urp",
            ),
        ),
        (
            GetProgramState(),
            ProgramStateReply(ProgramState.STOPPED, "external_control.urp", "STOPPED external_control.urp"),
        ),
        (Play(), CommandReply(Play(), True, "Starting program")),
        (
            GetProgramState(),
            ProgramStateReply(ProgramState.PLAYING, "external_control.urp", "PLAYING external_control.urp"),
        ),
        (IsRunning(), RunningReply(True, "Program running: true")),
        (Raw("get robot color"), RawReply(Raw("get robot color"), "could not understand: 'get robot color'")),
    ]
    for command, expected in steps:
        daemon_side.send(command)
        assert list(daemon_side.pending) == [command]
        assert converse(daemon_side, robot_side, fake.answer) == [expected]
        assert daemon_side.pending == ()
        assert robot_side.replies_owed == 0


def test_pipelined_commands_are_answered_in_order() -> None:
    fake = FakeController()
    daemon_side, robot_side = DashboardConnection(Side.DAEMON), DashboardConnection(Side.ROBOT)
    robot_side.send(Banner())
    for command in (PowerOn(), BrakeRelease(), Load("/programs/a.urp"), Play(), IsRunning()):
        daemon_side.send(command)
    assert converse(daemon_side, robot_side, fake.answer) == [
        Banner(),
        CommandReply(PowerOn(), True, "Powering on"),
        CommandReply(BrakeRelease(), True, "Brake releasing"),
        CommandReply(Load("/programs/a.urp"), True, "Loading program: /programs/a.urp"),
        CommandReply(Play(), True, "Starting program"),
        RunningReply(True, "Program running: true"),
    ]
