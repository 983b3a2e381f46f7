"""MotionGate while a goal is planned from where the robot rests (``from_rest``, review of issue 17).

A linear goal's plan is the joints of every cycle from where the robot rested when its planning began;
until it is answered, every stream (joint position, joint velocity, twist: ``check_accepting``) and
every move goal and cell goal part (``check_not_planning_from_rest``) is refused as busy, naming the
goal being planned. Pure: the gate reads only the backend's freedrive flag.

Reproduction: on dd4200c^ the gate had no ``from_rest`` nor ``check_not_planning_from_rest``, and
``check_accepting`` let streams through while a linear goal was planned (each test fails).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any, cast

import pytest

from urdaemon.backends.base import Backend
from urdaemon.control import MotionController
from urdaemon.errors import GoalRejected
from urdaemon.model import ForceModeRequest
from urdaemon.publish import services
from urdaemon.runtime.gate import TOOL_CONTACT_BUSY, MotionGate
from urdaemon.runtime.service_runner import ServiceRunner

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


@dataclass
class _ForceBackend(_Backend):
    """Records the force mode commands it was given."""

    started: list[object] | None = None

    async def force_mode(self, command: object) -> None:
        assert self.started is not None
        self.started.append(command)


async def test_force_mode_is_refused_while_a_linear_goal_is_planned_from_rest() -> None:
    """Reproduction: ``start_force_mode`` went to the backend while a linear goal was planned from where
    the robot rests (force mode moves it; only the plan's start check refused the plan afterwards).
    Now the service is refused as busy, as streams and move goals are; once answered it starts."""
    backend = _ForceBackend(started=[])
    gate = _gate(backend)
    parts: Any = (gate, None, None, None)  # force mode uses only the gate and the backend
    log = logging.LoggerAdapter(logging.getLogger("test"))
    runner = ServiceRunner(cast(Backend, backend), cast(MotionController, None), parts, log)
    request = ForceModeRequest((0.0,) * 6, (0, 0, 1, 0, 0, 0), (0.0, 0.0, -5.0, 0.0, 0.0, 0.0), (0.1,) * 6)
    handle = services.spec("start_force_mode").handle
    assert handle is not None
    gate.planning, gate.from_rest = "linear goal of 2 poses", True
    with pytest.raises(GoalRejected) as err:
        await handle(runner, request)
    assert str(err.value) == BUSY
    assert backend.started == []
    gate.planning, gate.from_rest = None, False
    await handle(runner, request)
    assert len(backend.started) == 1
