"""The gate (runtime/motion.py) while a goal is planned from where the robot rests (``from_rest``,
review of issue 17).

A linear goal's plan is the joints of every cycle from where the robot rested when its planning began;
until it is answered, every stream (joint position, joint velocity, twist: ``check_accepting``) and
every move goal and cell goal part (``check_not_planning_from_rest``) is refused as busy, naming the
goal being planned. The gate's facts are set as the daemon sets them: a ticket claimed, its work
planned ``from_rest`` (held between slices), a tool contact's end, shutting down.

Reproduction: on dd4200c^ the gate had no ``from_rest`` nor ``check_not_planning_from_rest``, and
``check_accepting`` let streams through while a linear goal was planned (each test fails).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import AsyncIterator, Generator
from dataclasses import dataclass, field
from typing import Any, cast

import pytest

from urdaemon.backends.base import Backend
from urdaemon.control import MotionController
from urdaemon.errors import GoalRejected
from urdaemon.model import ForceModeRequest, RobotState
from urdaemon.publish import services
from urdaemon.runtime.motion import TOOL_CONTACT_BUSY, TOOL_CONTACT_REASON, How, RobotMotion
from urdaemon.runtime.queries import Requests
from urdaemon.runtime.service_runner import ServiceRunner
from urdaemon.runtime.status import StatusPublisher

BUSY = (
    "busy: a linear goal is being planned from where the robot rests (linear goal of 2 poses); "
    "wait for its answer or cancel it"
)


@dataclass
class _Backend:
    freedrive_active: bool = False
    passthrough_goal: str | None = None
    state: RobotState = field(default_factory=lambda: RobotState.zeros(("a",)))

    def cancel_passthrough(self) -> None:
        pass


class _Controller:
    active_goal_id: str | None = None

    def abort(self, reason: str) -> None:
        pass

    def drain_events(self) -> list[Any]:
        return []


class _Status:
    def publish(self) -> None:
        pass


def _motion(backend: _Backend | None = None) -> RobotMotion:
    return RobotMotion(
        backend=cast(Backend, backend or _Backend()),
        controller=cast(MotionController, _Controller()),
        status=cast(StatusPublisher, _Status()),
        events=cast(Any, None),
        log=logging.LoggerAdapter(logging.getLogger("test")),
    )


def _from_rest(motion: RobotMotion) -> bool:
    """Whether the gate says a goal is planned from rest (read afresh)."""
    return motion.from_rest


@contextlib.asynccontextmanager
async def _planned(motion: RobotMotion, what: str, *, from_rest: bool) -> AsyncIterator[None]:
    """A goal ``what`` being planned (``from_rest``) until the block ends: its work held between slices."""
    held = True

    def steps() -> Generator[None, None, None]:
        while held:
            yield

    with motion.claim(what) as ticket:
        task = asyncio.ensure_future(motion.plan(ticket, steps(), from_rest=from_rest))
        await asyncio.sleep(0)
        try:
            yield
        finally:
            held = False
            with contextlib.suppress(GoalRejected):  # what ended motion meanwhile refused it
                await task


async def test_streams_and_goals_are_refused_naming_the_linear_goal_being_planned() -> None:
    motion = _motion()
    assert not _from_rest(motion)
    motion.check_accepting()
    motion.check_not_planning_from_rest()
    async with _planned(motion, "linear goal of 2 poses", from_rest=True):
        assert _from_rest(motion)
        with pytest.raises(GoalRejected) as err:
            motion.check_accepting()
        assert str(err.value) == BUSY
        with pytest.raises(GoalRejected) as err:
            motion.check_not_planning_from_rest()
        assert str(err.value) == BUSY
    # Answered (accepted or refused): streams and goals are accepted again.
    assert not _from_rest(motion)
    assert motion.planning is None
    motion.check_accepting()
    motion.check_not_planning_from_rest()


async def test_a_trajectory_goal_being_planned_does_not_hold_streams() -> None:
    """A trajectory goal's plan starts from the setpoint when it is accepted, not from a pose fixed
    when its planning began: streams go on meanwhile (only ``from_rest`` holds them)."""
    motion = _motion()
    async with _planned(motion, "trajectory of 3 points", from_rest=False):
        assert motion.planning == "trajectory of 3 points"
        motion.check_accepting()
        motion.check_not_planning_from_rest()


async def test_the_other_rules_still_come_first() -> None:
    """Freedrive and a tool contact are named before a linear goal being planned; shutting down first."""
    backend = _Backend(freedrive_active=True)
    motion = _motion(backend)
    async with _planned(motion, "linear goal of 2 poses", from_rest=True):
        with pytest.raises(GoalRejected, match="busy: freedrive is on"):
            motion.check_accepting()
        backend.freedrive_active = False
        motion.end(TOOL_CONTACT_REASON, How.CONTACT)
        with pytest.raises(GoalRejected) as err:
            motion.check_accepting()
        assert str(err.value) == TOOL_CONTACT_BUSY
        motion.end(TOOL_CONTACT_REASON, How.CONTACT, touched=False)
        motion.close()
        with pytest.raises(GoalRejected, match="shut"):
            motion.check_accepting()


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
    motion = _motion(backend)
    log = logging.LoggerAdapter(logging.getLogger("test"))
    runner = ServiceRunner(  # force mode uses only the gate and the backend
        backend=cast(Backend, backend),
        controller=cast(MotionController, None),
        motion=motion,
        requests=Requests(),
        status=cast(StatusPublisher, None),
        log=log,
    )
    request = ForceModeRequest((0.0,) * 6, (0, 0, 1, 0, 0, 0), (0.0, 0.0, -5.0, 0.0, 0.0, 0.0), (0.1,) * 6)
    handle = services.spec("start_force_mode").handle
    assert handle is not None
    async with _planned(motion, "linear goal of 2 poses", from_rest=True):
        with pytest.raises(GoalRejected) as err:
            await handle(runner, request)
        assert str(err.value) == BUSY
        assert backend.started == []
    await handle(runner, request)
    assert len(backend.started) == 1
