"""MotionGate while a goal is planned from where the robot rests (``from_rest``, review of issue 17).

A linear goal's plan is the joints of every cycle from where the robot rested when its planning began;
until it is answered, every stream (joint position, joint velocity, twist: ``check_accepting``) and
every move goal and cell goal part (``check_not_planning_from_rest``) is refused as busy, naming the
goal being planned. Pure: the gate reads only the backend's freedrive flag.

Reproduction: on dd4200c^ the gate had no ``from_rest`` nor ``check_not_planning_from_rest``, and
``check_accepting`` let streams through while a linear goal was planned (each test fails).
"""

from __future__ import annotations

from dataclasses import dataclass

import pytest

from urdaemon.errors import GoalRejected
from urdaemon.runtime.gate import TOOL_CONTACT_BUSY, MotionGate

BUSY = (
    "busy: a linear goal is being planned from where the robot rests (linear goal of 2 poses); "
    "wait for its answer or cancel it"
)


@dataclass
class _Backend:
    freedrive_active: bool = False


def _gate(backend: _Backend | None = None) -> MotionGate:
    return MotionGate(backend or _Backend())  # type: ignore[arg-type]


def test_streams_and_goals_are_refused_naming_the_linear_goal_being_planned() -> None:
    gate = _gate()
    assert not gate.from_rest
    gate.check_accepting()
    gate.check_not_planning_from_rest()
    gate.planning = "linear goal of 2 poses"
    gate.from_rest = True
    with pytest.raises(GoalRejected) as err:
        gate.check_accepting()
    assert str(err.value) == BUSY
    with pytest.raises(GoalRejected) as err:
        gate.check_not_planning_from_rest()
    assert str(err.value) == BUSY
    # Answered (accepted or refused): streams and goals are accepted again.
    gate.from_rest = False
    gate.planning = None
    gate.check_accepting()
    gate.check_not_planning_from_rest()


def test_a_trajectory_goal_being_planned_does_not_hold_streams() -> None:
    """A trajectory goal's plan starts from the setpoint when it is accepted, not from a pose fixed
    when its planning began: streams go on meanwhile (only ``from_rest`` holds them)."""
    gate = _gate()
    gate.planning = "trajectory of 3 points"
    gate.check_accepting()
    gate.check_not_planning_from_rest()


def test_the_other_rules_still_come_first() -> None:
    """Freedrive and a tool contact are named before a linear goal being planned; shutting down first."""
    backend = _Backend(freedrive_active=True)
    gate = _gate(backend)
    gate.planning = "linear goal of 2 poses"
    gate.from_rest = True
    with pytest.raises(GoalRejected, match="busy: freedrive is on"):
        gate.check_accepting()
    backend.freedrive_active = False
    gate.in_contact = True
    with pytest.raises(GoalRejected) as err:
        gate.check_accepting()
    assert str(err.value) == TOOL_CONTACT_BUSY
    gate.in_contact = False
    gate.closing = True
    with pytest.raises(GoalRejected, match="shut"):
        gate.check_accepting()
