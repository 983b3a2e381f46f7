"""What the robot's control program does with the reverse socket: one sans-IO state machine.

Pure: no asyncio, no sockets, no clock (time is passed in). The backend feeds it the events that
happen to the program (its reverse link came or went, a passthrough goal started, was canceled or
answered, freedrive was asked for, control was handed back, the daemon stops) and executes the
``Action`` each event returns; once per robot cycle ``frame`` says which frame goes out.

States (``Channel``)::

    NO_PROGRAM   no program reads the reverse socket: nothing is sent
    STREAMING    the program follows the daemon's frame each cycle (servoj, speedj, or an idle keepalive)
    PASSTHROUGH  the program runs a trajectory the daemon sent (``passthrough_goal``): keepalive NOOPs
    FREEDRIVE    the program holds freedrive while the deadman (``freedrive(True, now, timeout)``) holds
    HANDED_BACK  STOPPED was sent: the program left (or leaves) its loop; it is not sent again until
                 ``take_back`` (startup, resend_program) or a new program connects

The one fact "which trajectory the robot runs itself" is ``passthrough_goal``. Every trajectory the
robot started answers exactly one result on the trajectory socket, in order: a canceled one's answer
(CANCELED, or a SUCCESS that crossed the CANCEL) is owed and swallowed, so it never ends a later goal.
Refused transitions raise ``BackendError`` naming why (``docs/architecture.md`` has the table).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from urdaemon.errors import BackendError
from urdaemon.model import CommandMode
from urdaemon.protocols.rtde_variables import RuntimeState
from urdaemon.protocols.trajectory_point import TrajectoryResultCode

__all__ = [
    "ENDED_BY_HAND_BACK",
    "ENDED_BY_NEW_PROGRAM",
    "ENDED_BY_PROGRAM_LOST",
    "ENDED_BY_STOP",
    "ENDED_BY_TRAJECTORY_LOST",
    "FAILURE",
    "HANDED_BACK_REFUSAL",
    "NOT_CONNECTED",
    "READING_FRAMES",
    "Action",
    "Channel",
    "Frame",
    "ReverseChannel",
    "Step",
]

RUNTIME_PLAYING = int(RuntimeState.PLAYING)
RUNTIME_PAUSING = int(RuntimeState.PAUSING)
READING_FRAMES = frozenset((RUNTIME_PLAYING, RUNTIME_PAUSING))
"""RTDE ``runtime_state`` values in which the program reads its frames (pausing: until it has paused);
the backend passes ``runtime_state in READING_FRAMES`` to ``frame`` as ``playing``."""
FAILURE = int(TrajectoryResultCode.FAILURE)
"""The trajectory result code of a goal whose program or trajectory link was lost (``FAILURE``)."""
NOT_CONNECTED = "the control program is not connected"
HANDED_BACK_REFUSAL = "control was handed back to the robot (resend_program takes it back)"
ENDED_BY_HAND_BACK = "control was handed back to the robot while it ran the trajectory"
ENDED_BY_STOP = "the daemon stopped while the robot ran the trajectory"
ENDED_BY_NEW_PROGRAM = "a new control program connected while the robot ran the trajectory"
ENDED_BY_PROGRAM_LOST = "the control program's reverse connection was lost while the robot ran the trajectory"
ENDED_BY_TRAJECTORY_LOST = "the trajectory connection was lost while the robot ran the trajectory"


class Channel(enum.Enum):
    """What the program does with the reverse socket."""

    NO_PROGRAM = "no program"
    STREAMING = "streaming"
    PASSTHROUGH = "passthrough"
    FREEDRIVE = "freedrive"
    HANDED_BACK = "handed back"


class Action(enum.Enum):
    """What the backend does after an event."""

    NOTHING = "nothing"
    SEND_START = "send trajectory START, then the points"
    SEND_CANCEL = "send trajectory CANCEL"
    SEND_FREEDRIVE_START = "send freedrive START"
    SEND_FREEDRIVE_STOP = "send freedrive STOP"
    SEND_STOPPED = "send STOPPED"
    END_GOAL = "end the passthrough goal with the code"
    SWALLOW = "drop the result (its goal has ended already)"


class Frame(enum.IntEnum):
    """The frame of this cycle."""

    NONE = 0
    SERVOJ = 1
    SPEEDJ = 2
    IDLE = 3
    TRAJECTORY_NOOP = 4
    FREEDRIVE_NOOP = 5
    FREEDRIVE_STOP = 6


@dataclass(frozen=True, slots=True)
class Step:
    """An event's outcome: the action, and for ``END_GOAL`` the goal and its trajectory result code.

    ``SEND_STOPPED`` may end a goal too (``goal`` set): the program stops its trajectory with it.
    ``reason`` says why a goal ended when the daemon's side ended it (None: the robot's own result)."""

    action: Action
    goal: str | None = None
    code: int = 0
    reason: str | None = None


_NOTHING = Step(Action.NOTHING)
_NO_PROGRAM, _STREAMING, _PASSTHROUGH, _HANDED_BACK = (
    Channel.NO_PROGRAM,
    Channel.STREAMING,
    Channel.PASSTHROUGH,
    Channel.HANDED_BACK,
)
_POSITION, _VELOCITY = CommandMode.POSITION, CommandMode.VELOCITY
_NONE, _SERVOJ, _SPEEDJ, _IDLE = Frame.NONE, Frame.SERVOJ, Frame.SPEEDJ, Frame.IDLE
_TRAJECTORY_NOOP, _FREEDRIVE_NOOP, _FREEDRIVE_STOP = (
    Frame.TRAJECTORY_NOOP,
    Frame.FREEDRIVE_NOOP,
    Frame.FREEDRIVE_STOP,
)
_CONNECTED = (Channel.STREAMING, Channel.PASSTHROUGH, Channel.FREEDRIVE)


class ReverseChannel:
    """The reverse channel's state; every method is one event (see the module's table)."""

    __slots__ = ("_freedrive_until", "_goal", "_owed", "state")

    def __init__(self) -> None:
        self.state = Channel.NO_PROGRAM
        self._goal: str | None = None
        self._owed = 0
        """Results of canceled trajectories still to come (each is swallowed)."""
        self._freedrive_until = 0.0

    # ---- what it says -----------------------------------------------------------------------------

    @property
    def passthrough_goal(self) -> str | None:
        """The goal id of the trajectory the robot runs itself, or None."""
        return self._goal

    @property
    def freedrive_on(self) -> bool:
        """True while the program holds freedrive."""
        return self.state is Channel.FREEDRIVE

    @property
    def handed_back(self) -> bool:
        """True from hand_back until take_back or a new program."""
        return self.state is Channel.HANDED_BACK

    def passthrough_problem(self, trajectory_connected: bool) -> str | None:
        """Why a passthrough goal cannot start now (None when it can)."""
        state = self.state
        if state is Channel.HANDED_BACK:
            return HANDED_BACK_REFUSAL
        if state is Channel.NO_PROGRAM or not trajectory_connected:
            return f"{NOT_CONNECTED} (no reverse or trajectory connection)"
        if state is Channel.PASSTHROUGH:
            return f"passthrough goal {self._goal} is still running on the robot"
        if state is Channel.FREEDRIVE:
            return "freedrive is on: a passthrough trajectory starts at rest"
        return None

    # ---- the program -------------------------------------------------------------------------------

    def program_connected(self) -> Step:
        """The program's reverse link came up: it reads the daemon's frames (a new program)."""
        step = self._end_goal(reason=ENDED_BY_NEW_PROGRAM)
        self.state = Channel.STREAMING
        self._owed = 0
        return step

    def program_lost(self) -> Step:
        """The reverse link dropped: the program ended, and with it its trajectory and freedrive."""
        step = self._end_goal(reason=ENDED_BY_PROGRAM_LOST)
        if self.state is not Channel.HANDED_BACK:
            self.state = Channel.NO_PROGRAM
        self._owed = 0
        return step

    def trajectory_lost(self) -> Step:
        """The trajectory link dropped: no result can come any more."""
        self._owed = 0
        if self.state is not Channel.PASSTHROUGH:
            return _NOTHING
        self.state = Channel.STREAMING
        return self._end_goal(reason=ENDED_BY_TRAJECTORY_LOST)

    def hand_back(self) -> Step:
        """STOPPED: the program leaves its loop (a running trajectory ends with it)."""
        if self.state not in _CONNECTED:
            raise BackendError(HANDED_BACK_REFUSAL if self.handed_back else NOT_CONNECTED)
        goal = self._goal
        self._goal = None
        self.state = Channel.HANDED_BACK
        return Step(Action.SEND_STOPPED, goal, FAILURE, ENDED_BY_HAND_BACK if goal is not None else None)

    def take_back(self) -> Step:
        """startup or resend_program: a program may be sent or played again."""
        if self.state is Channel.HANDED_BACK:
            self.state = Channel.NO_PROGRAM
        return _NOTHING

    def stop(self) -> Step:
        """The daemon stops: STOPPED to a program that runs (urcl does the same on shutdown)."""
        if self.state not in _CONNECTED:
            return _NOTHING
        goal = self._goal
        self._goal = None
        self.state = Channel.NO_PROGRAM
        return Step(Action.SEND_STOPPED, goal, FAILURE, ENDED_BY_STOP if goal is not None else None)

    # ---- passthrough -------------------------------------------------------------------------------

    def start_passthrough(self, goal_id: str, trajectory_connected: bool) -> Step:
        """A passthrough goal starts: START, then its points."""
        problem = self.passthrough_problem(trajectory_connected)
        if problem is not None:
            raise BackendError(problem)
        self._goal = goal_id
        self.state = Channel.PASSTHROUGH
        return Step(Action.SEND_START, goal_id)

    def cancel_passthrough(self) -> Step:
        """CANCEL the running trajectory (nothing when none runs); its answer is owed."""
        if self.state is not Channel.PASSTHROUGH:
            return _NOTHING
        self._goal = None
        self._owed += 1
        self.state = Channel.STREAMING
        return Step(Action.SEND_CANCEL)

    def passthrough_result(self, code: int) -> Step:
        """A trajectory result arrived: an owed one is swallowed, else it ends the running goal."""
        if self._owed:
            self._owed -= 1
            return Step(Action.SWALLOW)
        if self.state is not Channel.PASSTHROUGH:
            return _NOTHING  # nobody's: no trajectory runs
        self.state = Channel.STREAMING
        return self._end_goal(code)

    # ---- freedrive ---------------------------------------------------------------------------------

    def freedrive(self, active: bool, now: float, timeout: float) -> Step:
        """Keep freedrive on until ``now + timeout`` (a deadman), or end it now."""
        state = self.state
        if not active:  # nothing to refuse: freedrive ends, or was not on
            if state is not Channel.FREEDRIVE:
                return _NOTHING
            self.state = Channel.STREAMING
            return Step(Action.SEND_FREEDRIVE_STOP)
        if state is Channel.HANDED_BACK:
            raise BackendError(HANDED_BACK_REFUSAL)
        if state is Channel.NO_PROGRAM:
            raise BackendError(NOT_CONNECTED)
        if state is Channel.PASSTHROUGH:
            raise BackendError(f"passthrough goal {self._goal} runs on the robot; freedrive starts at rest")
        self._freedrive_until = now + timeout
        if state is Channel.FREEDRIVE:
            return _NOTHING
        self.state = Channel.FREEDRIVE
        return Step(Action.SEND_FREEDRIVE_START)

    # ---- the cycle ---------------------------------------------------------------------------------

    def frame(self, mode: CommandMode, playing: bool, now: float) -> Frame:
        """This cycle's frame. ``playing``: the program runs (a paused one reads no frames, and frames
        queued meanwhile would be replayed on play, docs/protocols.md §6.2 step 5); ``mode``: the motion
        controller's command this cycle, which goes out as servoj or speedj while the program streams
        (the controller commands nothing while the robot runs a trajectory or is in freedrive)."""
        # (the 500 Hz path: members through module aliases, an enum's attribute lookup costs ~0.1 µs)
        state = self.state
        if not playing or state is _NO_PROGRAM or state is _HANDED_BACK:
            return _NONE
        if mode is _POSITION:
            return _SERVOJ
        if mode is _VELOCITY:
            return _SPEEDJ
        if state is _STREAMING:
            return _IDLE
        if state is _PASSTHROUGH:
            return _TRAJECTORY_NOOP
        if now > self._freedrive_until:  # the deadman: nobody asked for freedrive in time
            self.state = _STREAMING
            return _FREEDRIVE_STOP
        return _FREEDRIVE_NOOP

    def _end_goal(self, code: int = FAILURE, reason: str | None = None) -> Step:
        goal = self._goal
        if goal is None:
            return _NOTHING
        self._goal = None
        return Step(Action.END_GOAL, goal, code, reason)
