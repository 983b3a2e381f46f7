"""The reverse channel's state machine from tables: every (state, event) → (state, action), the refused
transitions with their texts, and the frame each state sends per cycle (no sockets, time passed in)."""

from __future__ import annotations

from collections.abc import Callable

import pytest

from urdaemon.backends.ur.reverse_channel import (
    ENDED_BY_HAND_BACK,
    ENDED_BY_NEW_PROGRAM,
    ENDED_BY_PROGRAM_LOST,
    ENDED_BY_STOP,
    ENDED_BY_TRAJECTORY_LOST,
    FAILURE,
    HANDED_BACK_REFUSAL,
    NOT_CONNECTED,
    Action,
    Channel,
    Frame,
    ReverseChannel,
    Step,
)
from urdaemon.errors import BackendError
from urdaemon.model import CommandMode

NO, STREAM, PASS, FREE, BACK = (
    Channel.NO_PROGRAM,
    Channel.STREAMING,
    Channel.PASSTHROUGH,
    Channel.FREEDRIVE,
    Channel.HANDED_BACK,
)
FREEDRIVE_UNTIL = 1.0
"""The freedrive states below were asked for at t = 0 with a 1 s deadman."""


def in_state(state: Channel) -> ReverseChannel:
    """A channel brought to ``state`` by the events that lead there (the goal running is ``g1``)."""
    channel = ReverseChannel()
    if state is NO:
        return channel
    channel.program_connected()
    if state is PASS:
        channel.start_passthrough("g1", trajectory_connected=True)
    elif state is FREE:
        channel.freedrive(True, 0.0, FREEDRIVE_UNTIL)
    elif state is BACK:
        channel.hand_back()
    assert channel.state is state
    return channel


Event = Callable[[ReverseChannel], Step]

EVENTS: dict[str, Event] = {
    "program connected": lambda c: c.program_connected(),
    "program lost": lambda c: c.program_lost(),
    "trajectory lost": lambda c: c.trajectory_lost(),
    "hand back": lambda c: c.hand_back(),
    "take back": lambda c: c.take_back(),
    "stop": lambda c: c.stop(),
    "start g2": lambda c: c.start_passthrough("g2", trajectory_connected=True),
    "start g2 without trajectory link": lambda c: c.start_passthrough("g2", trajectory_connected=False),
    "cancel": lambda c: c.cancel_passthrough(),
    "result SUCCESS": lambda c: c.passthrough_result(0),
    "freedrive on": lambda c: c.freedrive(True, 0.5, 1.0),
    "freedrive off": lambda c: c.freedrive(False, 0.5, 1.0),
}

NOTHING = Step(Action.NOTHING)

TABLE: list[tuple[Channel, str, Channel, Step]] = [
    # (state, event, state after, step)
    (NO, "program connected", STREAM, NOTHING),
    (NO, "program lost", NO, NOTHING),
    (NO, "trajectory lost", NO, NOTHING),
    (NO, "take back", NO, NOTHING),
    (NO, "stop", NO, NOTHING),
    (NO, "cancel", NO, NOTHING),
    (NO, "result SUCCESS", NO, NOTHING),
    (NO, "freedrive off", NO, NOTHING),  # nothing to end: never refused
    (STREAM, "program connected", STREAM, NOTHING),
    (STREAM, "program lost", NO, NOTHING),
    (STREAM, "trajectory lost", STREAM, NOTHING),
    (STREAM, "hand back", BACK, Step(Action.SEND_STOPPED, None, FAILURE)),
    (STREAM, "take back", STREAM, NOTHING),
    (STREAM, "stop", NO, Step(Action.SEND_STOPPED, None, FAILURE)),
    (STREAM, "start g2", PASS, Step(Action.SEND_START, "g2")),
    (STREAM, "cancel", STREAM, NOTHING),
    (STREAM, "result SUCCESS", STREAM, NOTHING),
    (STREAM, "freedrive on", FREE, Step(Action.SEND_FREEDRIVE_START)),
    (STREAM, "freedrive off", STREAM, NOTHING),
    (PASS, "program connected", STREAM, Step(Action.END_GOAL, "g1", FAILURE, ENDED_BY_NEW_PROGRAM)),
    (PASS, "program lost", NO, Step(Action.END_GOAL, "g1", FAILURE, ENDED_BY_PROGRAM_LOST)),
    (PASS, "trajectory lost", STREAM, Step(Action.END_GOAL, "g1", FAILURE, ENDED_BY_TRAJECTORY_LOST)),
    (PASS, "hand back", BACK, Step(Action.SEND_STOPPED, "g1", FAILURE, ENDED_BY_HAND_BACK)),
    (PASS, "take back", PASS, NOTHING),
    (PASS, "stop", NO, Step(Action.SEND_STOPPED, "g1", FAILURE, ENDED_BY_STOP)),
    (PASS, "cancel", STREAM, Step(Action.SEND_CANCEL)),
    (PASS, "result SUCCESS", STREAM, Step(Action.END_GOAL, "g1", 0)),
    (PASS, "freedrive off", PASS, NOTHING),
    (FREE, "program connected", STREAM, NOTHING),
    (FREE, "program lost", NO, NOTHING),
    (FREE, "trajectory lost", FREE, NOTHING),
    (FREE, "hand back", BACK, Step(Action.SEND_STOPPED, None, FAILURE)),
    (FREE, "take back", FREE, NOTHING),
    (FREE, "stop", NO, Step(Action.SEND_STOPPED, None, FAILURE)),
    (FREE, "cancel", FREE, NOTHING),
    (FREE, "result SUCCESS", FREE, NOTHING),
    (FREE, "freedrive on", FREE, NOTHING),
    (FREE, "freedrive off", STREAM, Step(Action.SEND_FREEDRIVE_STOP)),
    (BACK, "program connected", STREAM, NOTHING),
    (BACK, "program lost", BACK, NOTHING),
    (BACK, "trajectory lost", BACK, NOTHING),
    (BACK, "take back", NO, NOTHING),
    (BACK, "stop", BACK, NOTHING),
    (BACK, "cancel", BACK, NOTHING),
    (BACK, "result SUCCESS", BACK, NOTHING),
    (BACK, "freedrive off", BACK, NOTHING),  # nothing to end: never refused
]

REFUSED: list[tuple[Channel, str, str]] = [
    # (state, event, the error's text): the state does not change
    (NO, "hand back", NOT_CONNECTED),
    (NO, "start g2", f"{NOT_CONNECTED} (no reverse or trajectory connection)"),
    (NO, "freedrive on", NOT_CONNECTED),
    (STREAM, "start g2 without trajectory link", f"{NOT_CONNECTED} (no reverse or trajectory connection)"),
    (PASS, "start g2", "passthrough goal g1 is still running on the robot"),
    (PASS, "freedrive on", "passthrough goal g1 runs on the robot; freedrive starts at rest"),
    (FREE, "start g2", "freedrive is on: a passthrough trajectory starts at rest"),
    (BACK, "hand back", HANDED_BACK_REFUSAL),
    (BACK, "start g2", HANDED_BACK_REFUSAL),
    (BACK, "freedrive on", HANDED_BACK_REFUSAL),
]


def test_the_tables_cover_every_state_and_event() -> None:
    rows = {(state, event) for state, event, *_ in TABLE} | {(state, event) for state, event, _ in REFUSED}
    missing = [
        (state.name, event)
        for state in Channel
        for event in EVENTS
        if (state, event) not in rows and event != "start g2 without trajectory link"
    ]
    assert not missing, f"no row for: {missing}"


@pytest.mark.parametrize(
    ("state", "event", "after", "step"), TABLE, ids=[f"{s.name}-{e}" for s, e, *_ in TABLE]
)
def test_transition(state: Channel, event: str, after: Channel, step: Step) -> None:
    channel = in_state(state)
    assert EVENTS[event](channel) == step
    assert channel.state is after
    running = "g2" if step.action is Action.SEND_START else "g1" if after is PASS else None
    assert channel.passthrough_goal == running


@pytest.mark.parametrize(("state", "event", "text"), REFUSED, ids=[f"{s.name}-{e}" for s, e, _ in REFUSED])
def test_refused_transition(state: Channel, event: str, text: str) -> None:
    channel = in_state(state)
    goal = channel.passthrough_goal
    with pytest.raises(BackendError) as refused:
        EVENTS[event](channel)
    assert str(refused.value) == text
    assert channel.state is state
    assert channel.passthrough_goal == goal


FRAMES: list[tuple[Channel, CommandMode, bool, float, Frame, Channel]] = [
    # (state, the controller's command, program playing, now, frame, state after)
    (NO, CommandMode.POSITION, True, 0.5, Frame.NONE, NO),
    (BACK, CommandMode.IDLE, True, 0.5, Frame.NONE, BACK),
    (STREAM, CommandMode.POSITION, False, 0.5, Frame.NONE, STREAM),
    (STREAM, CommandMode.POSITION, True, 0.5, Frame.SERVOJ, STREAM),
    (STREAM, CommandMode.VELOCITY, True, 0.5, Frame.SPEEDJ, STREAM),
    (STREAM, CommandMode.IDLE, True, 0.5, Frame.IDLE, STREAM),
    (PASS, CommandMode.IDLE, True, 0.5, Frame.TRAJECTORY_NOOP, PASS),
    (PASS, CommandMode.IDLE, False, 0.5, Frame.NONE, PASS),
    (FREE, CommandMode.IDLE, True, FREEDRIVE_UNTIL, Frame.FREEDRIVE_NOOP, FREE),
    (FREE, CommandMode.IDLE, True, FREEDRIVE_UNTIL + 0.001, Frame.FREEDRIVE_STOP, STREAM),
    (FREE, CommandMode.IDLE, False, FREEDRIVE_UNTIL + 0.001, Frame.NONE, FREE),
]


@pytest.mark.parametrize(
    ("state", "mode", "playing", "now", "frame", "after"),
    FRAMES,
    ids=[f"{row[0].name}-{row[1].name}-{'playing' if row[2] else 'paused'}-{row[3]}" for row in FRAMES],
)
def test_frame(
    state: Channel, mode: CommandMode, playing: bool, now: float, frame: Frame, after: Channel
) -> None:
    channel = in_state(state)
    assert channel.frame(mode, playing, now) is frame
    assert channel.state is after


def test_freedrive_on_again_moves_the_deadman() -> None:
    channel = in_state(FREE)
    assert channel.freedrive(True, 0.9, 1.0) == NOTHING
    assert channel.frame(CommandMode.IDLE, True, 1.5) is Frame.FREEDRIVE_NOOP
    assert channel.frame(CommandMode.IDLE, True, 1.91) is Frame.FREEDRIVE_STOP


def test_a_canceled_goals_answer_never_ends_the_next_goal() -> None:
    """Reproduction: start g1, cancel it, start g2, cancel it, start g3; the robot then answers
    CANCELED for g1 and for g2. The backend kept one flag for "swallow the next result", so g2's
    CANCELED ended g3 (as canceled on the robot) while the robot still ran g3. Each canceled
    trajectory's one answer is owed and swallowed; g3 ends only with its own."""
    channel = in_state(STREAM)
    for goal in ("g1", "g2"):
        channel.start_passthrough(goal, trajectory_connected=True)
        assert channel.cancel_passthrough() == Step(Action.SEND_CANCEL)
    channel.start_passthrough("g3", trajectory_connected=True)
    # two answers are owed: both swallowed, and only the third ends g3
    assert channel.passthrough_result(1) == Step(Action.SWALLOW)
    assert channel.passthrough_result(1) == Step(Action.SWALLOW)
    assert channel.passthrough_goal == "g3"
    assert channel.passthrough_result(0) == Step(Action.END_GOAL, "g3", 0)
    assert channel.state is STREAM


def test_a_lost_link_forgets_the_answers_owed() -> None:
    """No answer comes on a lost trajectory socket: the next program's first result is its own."""
    for lose in (ReverseChannel.program_lost, ReverseChannel.trajectory_lost):
        channel = in_state(PASS)
        channel.cancel_passthrough()
        lose(channel)
        channel.program_connected()
        channel.start_passthrough("g2", trajectory_connected=True)
        assert channel.passthrough_result(0) == Step(Action.END_GOAL, "g2", 0)
