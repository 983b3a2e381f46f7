"""What runs in the controller, and the refusals of a request that would start while something runs.

Owns the controller's modes and the busy rules every commanding request goes through: a goal may take
over a stream or a stop but only preempt a goal when asked; a passthrough, a planned (Cartesian) goal or
a TCP change needs the robot at rest; a stream command is refused while a goal runs. Pure checks: they
read the controller's mode, goal and stream follower and raise ``GoalRejected`` naming the reason.
"""

from __future__ import annotations

import enum
from collections.abc import Sequence

from urdaemon.control.goal_run import GoalRun
from urdaemon.control.streams import StreamFollower
from urdaemon.errors import GoalRejected
from urdaemon.model import RobotState

__all__ = [
    "STREAMS",
    "Mode",
    "check_at_rest",
    "check_can_start",
    "check_ready",
    "check_still",
    "check_stream_command",
]


class Mode(enum.Enum):
    """What the controller runs; its value is the ``mode`` the status shows."""

    IDLE = "idle"
    GOAL = "goal"
    STREAM_POSITION = "stream_position"
    STREAM_VELOCITY = "stream_velocity"
    STREAM_TWIST = "stream_twist"
    STOPPING = "stopping"
    EXTERNAL = "external"
    """A goal the robot interpolates itself (passthrough): we hold still and wait for its result."""


STREAMS = frozenset({Mode.STREAM_POSITION, Mode.STREAM_VELOCITY, Mode.STREAM_TWIST})
"""The modes a client's stream drives (the deadman ends them)."""


def check_ready(state: RobotState) -> None:
    """Refuse motion on a robot that is not ready for it."""
    if not state.ready_for_motion:
        raise GoalRejected(f"robot not ready: {state.not_ready_reason()}")


def check_can_start(
    mode: Mode,
    goal: GoalRun | None,
    streams: StreamFollower,
    goal_id: str,
    state: RobotState,
    now: float,
    preempt: bool,
) -> None:
    """Refuse a goal that could not start now: not ready, a goal or an active stream runs (unless
    ``preempt``), a passthrough runs on the robot, or ``goal_id`` is the running goal's."""
    check_ready(state)
    if goal is not None and mode is Mode.EXTERNAL:
        # the robot runs that trajectory itself: taking over mid-way would fight it
        raise GoalRejected(f"busy: passthrough goal {goal.goal_id} runs on the robot; cancel it first")
    if goal is not None:
        if goal_id == goal.goal_id:
            raise GoalRejected(f"goal {goal_id} is already executing")
        if not preempt:
            raise GoalRejected(f"busy: goal {goal.goal_id} is executing")
    if not preempt and mode in STREAMS and streams.active(now):
        kind = "twist" if mode is Mode.STREAM_TWIST else "joint"
        raise GoalRejected(
            f"busy: a {kind} stream is active (last command {now - streams.last_command:.3g} s ago, "
            f"timeout {streams.timeout:.3g} s)"
        )


def check_at_rest(mode: Mode, goal: GoalRun | None, at_rest: bool, what: str) -> None:
    """Refuse ``what`` (a request that starts from rest) unless nothing moves: ``at_rest`` says whether
    the setpoint of a running stop rests already."""
    if goal is not None:
        raise GoalRejected(f"busy: goal {goal.goal_id} is running; {what}")
    if mode is not Mode.IDLE and not (mode is Mode.STOPPING and at_rest):
        raise GoalRejected(f"busy: the robot is {mode.value.replace('_', ' ')}; {what}")


def check_still(mode: Mode, goal: GoalRun | None, at_rest: bool, reason: str) -> None:
    """Refuse with ``reason`` unless nothing moves: idle, or a stop whose setpoint rests (``at_rest``)."""
    if goal is not None or not (mode is Mode.IDLE or (mode is Mode.STOPPING and at_rest)):
        raise GoalRejected(reason)


def check_stream_command(mode: Mode, goal: GoalRun | None, state: RobotState) -> Sequence[float] | None:
    """Refuse a stream command while the robot is not ready or a goal runs; the measured pose the
    stream starts at when idle, else None (it continues from the setpoint)."""
    check_ready(state)
    if goal is not None:
        raise GoalRejected(f"busy: goal {goal.goal_id} is executing")
    return state.positions if mode is Mode.IDLE else None
