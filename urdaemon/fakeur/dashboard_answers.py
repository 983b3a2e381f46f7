"""A fake controller's dashboard server answers (29999): one reply line per command.

``dashboard_reply`` answers from the controller's state (and acts on it: power, brakes, load, play,
pause, stop); ``play`` starts the loaded program (the default External Control program fetches its
script from the daemon, a URScript file runs as it is, a ``.urp`` runs as the URScript ``fakeur.urp``
translates it to when it is loaded) or resumes a paused one. While a program is
pausing (its speed scaling ramping to 0) it is reported as PLAYING until it is PAUSED, and ``play``
is refused meanwhile: it neither resumes it nor starts the loaded program anew.

``dashboard_answer`` is the same answer with ``load`` of a ``.urp`` read and translated in the
compiler thread (up to ~12 ms of pure Python within the file's bounds): that connection's reply waits
for it, every fake's clock and every other connection go on. ``dashboard_reply`` still translates on
the calling thread, for callers that cannot wait.

The answers see the controller through :class:`DashboardController`: its arm, the programs it runs,
the loaded program, what it is, and its two commands that are more than one collaborator's (brake
release, which powers on first; the External Control program's play). ``FakeController`` is one.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from urdaemon.fakeur.life import UNLOCK_TOO_SOON
from urdaemon.fakeur.urp import MAX_URP_BYTES, UrpProgram, UrpRefused, translate
from urdaemon.protocols import dashboard as dash
from urdaemon.protocols import primary as prim
from urdaemon.protocols.rtde_variables import RuntimeState

if TYPE_CHECKING:
    from urdaemon.description.urmodels import UrModel
    from urdaemon.fakeur.fake_arm import FakeArm
    from urdaemon.fakeur.programs import Programs

__all__ = [
    "PROGRAMS_DIR",
    "REMOTE_CONTROL_SINCE",
    "SCRIPT_SUFFIXES",
    "URP_SUFFIX",
    "DashboardController",
    "dashboard_answer",
    "dashboard_reply",
    "play",
    "program_path",
]

log = logging.getLogger("urdaemon.fakeur")

PROGRAMS_DIR = "/programs"
"""Where programs live when no directory is given (as on URSim); only the default program exists there."""
SCRIPT_SUFFIXES = (".script", ".urscript")
"""Program files the fake plays by running their text as URScript."""
URP_SUFFIX = ".urp"
"""PolyScope program files: translated to URScript when loaded (``fakeur.urp``); one the fake cannot
translate is refused at ``load`` with the dashboard's "Error while loading program"."""
SERIAL_NUMBER = "20235500001"
REMOTE_CONTROL_SINCE = (5, 6)
"""The first version whose dashboard answers ``is in remote control`` (docs/protocols.md §3.2: not on
CB3, e-Series from 5.6); older ones do not understand it."""
_PROGRAM_STATES = {
    RuntimeState.PLAYING: dash.ProgramState.PLAYING,
    RuntimeState.PAUSING: dash.ProgramState.PLAYING,  # playing until paused, as a controller says
    RuntimeState.PAUSED: dash.ProgramState.PAUSED,
}


class DashboardController(Protocol):
    """What the dashboard's answers need of a controller (``FakeController`` is one)."""

    arm: FakeArm
    programs: Programs
    """The programs it runs: started, stopped, compiled, the loaded ``.urp``, its robot messages."""
    loaded_program: str | None
    """The program ``load`` loaded (and ``play`` plays); None: none."""
    address: str
    model: UrModel
    controller_version: tuple[int, int, int, int]
    programs_dir: Path | None
    """Where ``load`` finds program files; None: URSim's default directory."""
    default_program: str
    """The External Control program, which always exists."""
    operational_mode: dash.OperationalMode
    """What ``get operational mode`` says: NONE (no mode password set) until ``set operational mode``
    takes control of it, NONE again after ``clear operational mode``."""

    def brake_release(self) -> str | None:
        """Release the brakes (powering on first from POWER_OFF); a reason if refused."""
        ...

    def play_urcap(self) -> None:
        """What the External Control program does on play: fetch the script from the daemon, run it."""
        ...


def dashboard_reply(fake: DashboardController, command: Any) -> str:
    """The dashboard's answer to ``command`` (and what it does to ``fake``)."""
    reply = _action_reply(fake, command)
    if reply is None:
        reply = _query_reply(fake, command)
    if reply is not None:
        return reply
    success = getattr(command, "success_text", None)
    return success if isinstance(success, str) else dash.unknown_command_text(getattr(command, "line", ""))


def _action_reply(fake: DashboardController, command: Any) -> str | None:
    """The answer to a command that changes the arm or the program; None for any other command."""
    arm = fake.arm
    if isinstance(command, dash.PowerOn):
        return "Powering on" if arm.life.power_on(arm.timestamp) is None else "Failed to execute: power on"
    if isinstance(command, dash.PowerOff):
        fake.programs.stop()
        arm.power_off()
        return "Powering off"
    if isinstance(command, dash.BrakeRelease):
        return "Brake releasing" if fake.brake_release() is None else "Failed to execute: brake release"
    if isinstance(command, dash.UnlockProtectiveStop):
        refused = arm.unlock_protective_stop()
        if refused is None:
            return "Protective stop releasing"
        if refused == UNLOCK_TOO_SOON:  # UR's guide gives this text for an unlock within 5 s
            return UNLOCK_TOO_SOON
        return "Cannot unlock protective stop: the robot is not in protective stop or still moving"
    if isinstance(command, dash.Load):
        path = program_path(fake, command.path)
        if path is None:
            return f"File not found: {command.path}"
        translated = _read_urp(fake, path) if _is_urp(fake, path) else None
        return _load(fake, path, translated)
    if isinstance(command, dash.Play):
        return "Starting program" if play(fake) is None else "Failed to execute: play"
    if isinstance(command, dash.RestartSafety):
        fake.programs.stop()
        arm.power_off()
        arm.life.restart_safety()
        return "Restarting safety"
    if isinstance(command, dash.Pause):
        if arm.runtime_state is not RuntimeState.PLAYING:
            return "Failed to execute: pause"
        arm.pause_program()
        return "Pausing program"
    if isinstance(command, dash.Stop):  # with nothing playing too: clients stop "if one runs" blindly
        fake.programs.stop()
        return "Stopped"
    if isinstance(command, dash.SetOperationalMode | dash.ClearOperationalMode):
        return _operational_mode(fake, command)
    if isinstance(command, dash.Quit):
        return "Disconnected"
    if isinstance(command, dash.Shutdown):
        arm.power_off()
        return "Shutting down"
    return None


def _operational_mode(
    fake: DashboardController, command: dash.SetOperationalMode | dash.ClearOperationalMode
) -> str:
    """``set`` / ``clear operational mode`` (e-Series only): the dashboard takes control of the mode,
    which ``get operational mode`` then reports, or hands it back (NONE: the fake sets no password)."""
    if fake.controller_version[0] < 5:
        return dash.unknown_command_text(command.KEYWORD)
    if isinstance(command, dash.SetOperationalMode):
        fake.operational_mode = command.mode
    else:
        fake.operational_mode = dash.OperationalMode.NONE
    return command.success_text


def _query_reply(fake: DashboardController, command: Any) -> str | None:
    """The answer to a command that only reads the fake's state; None for any other command."""
    arm = fake.arm
    program = fake.loaded_program
    if isinstance(command, dash.IsProgramSaved):
        return dash.program_saved_text(program is not None, _basename(program))
    if isinstance(command, dash.GetOperationalMode) and fake.controller_version[0] >= 5:
        return dash.operational_mode_text(fake.operational_mode)
    if isinstance(command, dash.GetUserRole) and fake.controller_version[0] < 5:
        return dash.user_role_text(dash.UserRole.PROGRAMMER)  # no user password set
    if isinstance(command, dash.GetRobotMode):
        return dash.robot_mode_text(arm.robot_mode)
    if isinstance(command, dash.GetSafetyMode):
        return dash.safety_mode_text(arm.safety_mode)
    if isinstance(command, dash.GetSafetyStatus):
        return dash.safety_status_text(arm.safety_mode)
    if isinstance(command, dash.GetProgramState):
        state = _PROGRAM_STATES.get(arm.runtime_state, dash.ProgramState.STOPPED)
        return dash.program_state_text(state, _basename(program))
    if isinstance(command, dash.IsRunning):
        return dash.running_text(arm.program_running)
    if isinstance(command, dash.GetLoadedProgram):
        return dash.loaded_program_text(program)
    if isinstance(command, dash.IsInRemoteControl) and fake.controller_version[:2] >= REMOTE_CONTROL_SINCE:
        return dash.remote_control_text(arm.remote_control)
    if isinstance(command, dash.GetPolyscopeVersion):
        return dash.polyscope_version_text(fake.controller_version, "Jan 01 2026")
    if isinstance(command, dash.GetVersion):
        return dash.version_text(fake.controller_version)
    if isinstance(command, dash.GetSerialNumber):
        return SERIAL_NUMBER
    if isinstance(command, dash.GetRobotModel):
        return fake.model.model.upper().removesuffix("E")
    if isinstance(command, dash.GetOperationalMode | dash.GetUserRole | dash.IsInRemoteControl):  # not here
        return dash.unknown_command_text(command.KEYWORD)
    return None


async def dashboard_answer(fake: DashboardController, command: Any) -> str:
    """The dashboard's answer to ``command``, as :func:`dashboard_reply`, but ``load`` reads and
    translates a ``.urp`` off the event loop (in the compiler thread): the reply waits for it, every
    fake's clock and every other connection do not."""
    if isinstance(command, dash.Load):
        path = program_path(fake, command.path)
        if path is not None and _is_urp(fake, path):
            translated = _refused(fake, path, await fake.programs.off_loop(_read_and_translate, path))
            return _load(fake, path, translated)
    return dashboard_reply(fake, command)


def _is_urp(fake: DashboardController, path: str) -> bool:
    return path != fake.default_program and path.endswith(URP_SUFFIX)


def _load(fake: DashboardController, path: str, translated: UrpProgram | None) -> str:
    """``load`` of ``path`` once read: refused if it is a ``.urp`` the fake could not translate
    (``translated`` None), else the loaded program, the running one stopped."""
    if _is_urp(fake, path):
        if translated is None:
            return f"Error while loading program: {path}"
        fake.programs.loaded_urp = (path, translated)
    fake.programs.stop()
    fake.loaded_program = path
    return f"Loading program: {path}"


def program_path(fake: DashboardController, name: str) -> str | None:
    """The program file ``name`` stands for (relative names under the programs directory), or None
    if there is no such file. The default External Control program always exists."""
    base = str(fake.programs_dir) if fake.programs_dir is not None else PROGRAMS_DIR
    path = name if name.startswith("/") else f"{base.rstrip('/')}/{name}"
    if path == fake.default_program:
        return path
    if fake.programs_dir is None or not Path(path).is_file():
        return None
    return path


def play(fake: DashboardController) -> str | None:
    """``play``: resume a paused program, or start the loaded one; a reason if it cannot."""
    arm, program = fake.arm, fake.loaded_program
    if program is None:  # a headless program (sent, not loaded) cannot be played, not even resumed
        return "no program loaded"
    if arm.runtime_state is RuntimeState.PAUSED:
        return arm.resume_program()
    if arm.runtime_state is RuntimeState.PAUSING:  # still slowing down: neither resumed nor started anew
        return "the program is pausing"
    if arm.runtime_state is RuntimeState.PLAYING or fake.programs.busy:
        return None  # already playing (or about to): nothing starts anew
    urp = _loaded_urp(fake, program) if program != fake.default_program else None
    if program != fake.default_program and urp is None and not program.endswith(SCRIPT_SUFFIXES):
        return f"{program}: the fake plays URScript files, .urp programs and the External Control program"
    reason = arm.start_program()
    if reason is not None:
        return reason
    if program == fake.default_program or (urp is not None and urp.external_control):
        fake.play_urcap()
        return None
    if urp is not None:
        text = urp.script or ""
    else:
        try:
            text = Path(program).read_text(encoding="ascii")
        except (OSError, UnicodeDecodeError) as err:
            arm.stop_program()
            return str(err)
    arm.life.wait_for_script()
    fake.programs.submit(_basename(program) or program, text)
    return None


def _read_urp(fake: DashboardController, path: str) -> UrpProgram | None:
    """The program a ``.urp`` file holds, or None (the reason logged and sent as a robot message, as
    PolyScope shows why it could not load a program). Read on the event loop: :func:`dashboard_answer`
    reads off it."""
    return _refused(fake, path, _read_and_translate(path))


def _read_and_translate(path: str) -> UrpProgram | str:
    """The program a ``.urp`` file holds, or why it cannot be loaded (pure but for the read)."""
    try:
        with open(path, "rb") as file:  # no more than a program may hold, even compressed
            data = file.read(MAX_URP_BYTES + 1)
        return translate(data, path)
    except OSError as err:
        return str(err)
    except UrpRefused as err:
        return err.reason


def _refused(fake: DashboardController, path: str, read: UrpProgram | str) -> UrpProgram | None:
    """The program read, or None once the reason it was not is logged and sent as a robot message."""
    if isinstance(read, UrpProgram):
        return read
    log.info("%s cannot load %s: %s", fake.address, path, read)
    fake.programs.broadcast(prim.TextMessage(f"Error while loading program {path}: {read}"))
    return None


def _loaded_urp(fake: DashboardController, program: str) -> UrpProgram | None:
    """The translation of the loaded ``.urp`` program (None for other files)."""
    if not program.endswith(URP_SUFFIX):
        return None
    loaded = fake.programs.loaded_urp
    if loaded is not None and loaded[0] == program:
        return loaded[1]
    return _read_urp(fake, program)


def _basename(path: str | None) -> str | None:
    return None if path is None else path.rsplit("/", 1)[-1]
