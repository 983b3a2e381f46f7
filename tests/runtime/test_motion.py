"""runtime/motion.py: one owner of a robot's motion.

- The gate's facts (shutting down, tool contact, the goal being planned, "from rest", the generation)
  are written only inside runtime/motion.py: the source of urdaemon/ is read (ast) for any other
  assignment to them.
- Every stop of the daemon goes through ``RobotMotion.end``: each former stop site's trigger is
  driven on one runtime (a mock-backed robot on a fake node, its cycles not running) whose
  collaborators are spied on, and the calls they get are the end sequence of the site's row in
  ``ENDINGS`` (the controller told, the robot's own trajectory cancelled, goal events and status
  published) with the goal being planned refused (the generation) where the row says.

Reproduction: before issue 31 the gate's facts were written 16 times from 6 modules (the scan
names them) and runtime/motion.py did not exist (ImportError).
"""

from __future__ import annotations

import ast
import asyncio
import json
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from tests.integration.conftest import TWO_MOCKS
from tests.integration.test_review_planning import HOME, ROOT, HandBackend, Node, Query
from urdaemon import robot as robot_module
from urdaemon.cell import parse_cell
from urdaemon.control import GoalResult, MotionController
from urdaemon.daemon import describe_cell
from urdaemon.model import Lifecycle, RobotMode, SafetyMode
from urdaemon.publish.lease_request import LeaseRequest
from urdaemon.robot import RobotRuntime
from urdaemon.runtime.motion import ENDINGS, How

FACTS = frozenset({"closing", "in_contact", "planning", "from_rest", "generation"})
"""The gate's facts (public names; their private fields are these with a leading underscore)."""
OWNER = Path("urdaemon/runtime/motion.py")


def _fact_writes(source: str) -> list[tuple[int, str]]:
    """Assignments (plain, augmented, annotated) to a gate fact of another object (``x.planning = ``,
    ``self._gate.generation += 1``, ``runtime.motion._in_contact = ``): line and target. An object's
    own attribute (``self._planning``: a cell goal's own flag) is its own fact, not the gate's."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Assign):
            targets = node.targets
        elif isinstance(node, (ast.AugAssign, ast.AnnAssign)):
            targets = [node.target]
        else:
            continue
        for target in targets:
            for item in target.elts if isinstance(target, ast.Tuple) else [target]:
                if not isinstance(item, ast.Attribute) or item.attr.lstrip("_") not in FACTS:
                    continue
                if isinstance(item.value, ast.Name) and item.value.id == "self":
                    continue
                found.append((node.lineno, ast.unparse(item)))
    return found


def test_the_scan_finds_a_write_of_a_gate_fact_from_outside() -> None:
    """The scan itself: each way to write another object's fact is found, an object's own is not."""
    source = (
        "runtime.motion._planning = None\n"
        "self._gate.generation += 1\n"
        "gate.in_contact, x = True, 1\n"
        "motion.closing: bool = True\n"
        "self._planning = False\n"
        "seen = motion.from_rest\n"
    )
    assert [target for _, target in _fact_writes(source)] == [
        "runtime.motion._planning",
        "self._gate.generation",
        "gate.in_contact",
        "motion.closing",
    ]


def test_the_gate_is_written_only_inside_runtime_motion() -> None:
    root = ROOT / "urdaemon"
    writes = {
        f"{path.relative_to(ROOT)}:{line}": target
        for path in sorted(root.rglob("*.py"))
        if path.relative_to(ROOT) != OWNER
        for line, target in _fact_writes(path.read_text())
    }
    assert writes == {}, f"the gate's facts are RobotMotion's to write: {writes}"


# ---- every stop goes through end ----------------------------------------------------------------


class SpyBackend(HandBackend):
    """The mock with freedrive and passthrough (test_review_planning.py); the robot runs
    ``passthrough``'s goal itself; hand_back_control and tool contact do nothing."""

    @property
    def passthrough_goal(self) -> str | None:
        return None if self.passthrough is None else self.passthrough[0]

    async def hand_back_control(self) -> None:
        pass

    async def tool_contact(self, start: bool) -> None:
        pass


@dataclass
class Robot:
    """alice's runtime, not running (no cycle), with a record of what its collaborators were told."""

    runtime: RobotRuntime
    backend: SpyBackend
    calls: list[str]

    def key(self, tail: str) -> str:
        return f"{self.runtime.keys.base}/{tail}"

    def move(self) -> str:
        """Start a move goal; its id."""
        query = Query(self.key("goal/move"), {"positions": [v + 0.2 for v in HOME]})
        self.runtime.goals.on_move_goal(query)
        assert query.replies[0]["accepted"], query.replies
        goal_id: str = query.replies[0]["goal_id"]
        return goal_id


def _robot() -> Robot:
    cell = parse_cell(TWO_MOCKS, base_dir=ROOT / "configs")
    limits = describe_cell(cell).limits["alice"]
    backend = SpyBackend("alice", limits.names, 500.0, initial_positions=HOME)
    state = backend.state
    state.lifecycle, state.robot_mode, state.safety_mode = (
        Lifecycle.RUNNING,
        RobotMode.RUNNING,
        SafetyMode.NORMAL,
    )
    state.program_running = True
    controller = MotionController(limits, period=backend.period)
    node: Any = Node()
    runtime = RobotRuntime(cell.cell, cell.robot("alice"), backend, controller, node, cell.publish)
    runtime.declare()
    calls: list[str] = []

    def spy(obj: Any, name: str, shown: Callable[..., str] | None = None) -> None:
        real = getattr(obj, name)

        def called(*args: Any, **kwargs: Any) -> Any:
            calls.append(name if shown is None else shown(*args))
            return real(*args, **kwargs)

        setattr(obj, name, called)

    for name in ("stop", "abort", "cancel"):
        spy(controller, name)
    spy(backend, "cancel_passthrough")
    spy(backend, "freedrive", lambda active, _: f"freedrive({active})")
    spy(backend, "hand_back_control")
    spy(backend, "tool_contact", lambda start: f"tool_contact({start})")
    spy(runtime.status, "publish", lambda: "status")
    spy(
        runtime.goals.events,
        "publish",
        lambda event: "result" if isinstance(event, GoalResult) else "feedback",
    )
    return Robot(runtime, backend, calls)


class DeadWatch:
    """The cell's watch of lease tokens, in which no token is alive."""

    def watch(self, key: str) -> None:
        pass

    def unwatch(self, key: str) -> None:
        pass

    def probe(self, key: str) -> None:
        pass

    def alive(self, key: str) -> bool:
        return False


async def _stop_service(robot: Robot, goal: str | None) -> None:
    query = Query(robot.key("service/stop"))
    robot.runtime.services.on_stop(query)
    assert query.replies == [{"v": 1, "ok": True}]


def _lease_held(robot: Robot, goal: str | None) -> None:
    robot.runtime.lease.book.acquire(LeaseRequest("acquire", "s" * 16, "tester"), time.time())
    robot.backend.freedrive_on = True  # nobody may keep it on once the lease ends


async def _lease_ended(robot: Robot, goal: str | None) -> None:
    robot.runtime.lease.attach(DeadWatch())  # type: ignore[arg-type]  # the holder's token is gone


async def _cancel_query(robot: Robot, goal: str | None) -> None:
    query = Query(robot.key("goal/cancel"), {})
    robot.runtime.goals.on_cancel(query)
    assert query.replies[0]["canceled"] is True, query.replies


async def _cancel_goal(robot: Robot, goal: str | None) -> None:
    assert goal is not None
    assert robot.runtime.goals.cancel_goal(goal)


async def _stop_goal(robot: Robot, goal: str | None) -> None:
    assert goal is not None
    assert robot.runtime.goals.stop_goal(goal, "another part failed")


def _robot_runs(robot: Robot, goal: str | None) -> None:
    assert goal is not None
    robot.backend.passthrough = (goal, 1)  # the robot runs the goal the daemon ends


async def _contact_notice(robot: Robot, goal: str | None) -> None:
    assert robot.backend.on_notice is not None
    robot.backend.on_notice("tool_contact", "contact")


def _touched(robot: Robot, goal: str | None) -> None:
    assert robot.backend.on_notice is not None
    robot.backend.on_notice("tool_contact", "contact")


async def _end_tool_contact(robot: Robot, goal: str | None) -> None:
    await robot.runtime.services.end_tool_contact()


async def _hand_back_control(robot: Robot, goal: str | None) -> None:
    await robot.runtime.services.hand_back_control()


async def _freedrive_on(robot: Robot, goal: str | None) -> None:
    robot.runtime.commands.on_freedrive(robot.key("command/freedrive"), json.dumps({"active": True}).encode())


async def _supervised(robot: Robot, *, fail: bool) -> None:
    """The backend fails once (``fail``) and restarts, or runs until the runtime shuts down."""
    runtime = robot.runtime
    running = asyncio.Event()
    runs = 0

    async def run(on_cycle: Any) -> None:
        nonlocal runs
        runs += 1
        if fail and runs == 1:
            raise RuntimeError("link lost")
        running.set()
        await asyncio.Event().wait()

    runtime.backend.run = run  # type: ignore[method-assign]
    task = asyncio.ensure_future(runtime._supervise())
    await running.wait()
    if fail:
        return
    task.cancel()
    with pytest.raises(asyncio.CancelledError):
        await task


async def _backend_failed(robot: Robot, goal: str | None) -> None:
    await _supervised(robot, fail=True)
    assert not robot.backend.state.program_running


async def _shutdown(robot: Robot, goal: str | None) -> None:
    await _supervised(robot, fail=False)
    assert robot.runtime.motion.closing


@dataclass(frozen=True)
class Site:
    """A former stop site: its trigger, what ends (``how``), and what the collaborators are told."""

    trigger: Callable[[Robot, str | None], Awaitable[None]]
    how: How
    calls: list[str]
    refused_planned: bool
    moving: bool = True
    """A goal runs when the trigger comes (else the robot rests)."""
    in_contact: bool = False
    setup: Callable[[Robot, str | None], None] | None = None
    """What is so before the trigger comes."""


SITES = {
    "stop service": Site(_stop_service, How.STOP, ["stop", "cancel_passthrough", "result", "status"], True),
    "lease ended": Site(
        _lease_ended,
        How.STOP,
        # then the lease's own event goes out with the status
        ["stop", "cancel_passthrough", "freedrive(False)", "result", "status", "status"],
        True,
        setup=_lease_held,
    ),
    "cancel query": Site(_cancel_query, How.CANCEL, ["cancel", "result", "status"], True),
    "cell goal cancels a part": Site(_cancel_goal, How.CANCEL, ["cancel", "result", "status"], False),
    "cell goal stops a part": Site(_stop_goal, How.STOP, ["stop", "result", "status"], False),
    "passthrough ended here": Site(
        _stop_goal, How.STOP, ["stop", "cancel_passthrough", "result", "status"], False, setup=_robot_runs
    ),
    "tool contact notice": Site(
        _contact_notice, How.CONTACT, ["abort", "result", "status"], True, in_contact=True
    ),
    "end_tool_contact": Site(
        _end_tool_contact,
        How.CONTACT,
        ["tool_contact(False)", "abort", "status"],
        False,
        moving=False,
        setup=_touched,
    ),
    "hand_back_control": Site(_hand_back_control, How.HAND_BACK, ["hand_back_control"], True),
    "freedrive on": Site(_freedrive_on, How.HAND_BACK, ["freedrive(True)"], True, moving=False),
    # then the status says the backend is disconnected
    "backend failed": Site(_backend_failed, How.ABORT, ["abort", "result", "status", "status"], False),
    "shutdown": Site(_shutdown, How.ABORT, ["abort", "result", "status"], False),
}
"""Each former stop site (``Goals.stop_goal``/``cancel_goal``/``on_cancel``, ``ServiceRunner.stop``/
``hand_back_control``/``end_tool_contact``, the runtime's backend failure, shutdown, tool contact
notice and lease end, ``Passthrough.ended_here``, ``Commands.on_freedrive``) and its end sequence."""


@pytest.mark.parametrize("name", list(SITES))
async def test_every_stop_site_ends_motion_through_one_end(
    name: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    site = SITES[name]
    monkeypatch.setattr(robot_module, "RESTART_BACKOFF_S", (0.0,))
    robot = _robot()
    goal = robot.move() if site.moving else None
    if site.setup is not None:
        site.setup(robot, goal)
    motion = robot.runtime.motion
    generation = motion.generation
    ended: list[How] = []
    end = motion.end

    def recorded(reason: str, how: How, *args: Any, **kwargs: Any) -> Any:
        ended.append(how)
        return end(reason, how, *args, **kwargs)

    motion.end = recorded  # type: ignore[method-assign]
    robot.calls.clear()
    await site.trigger(robot, goal)
    assert ended[-1] is site.how
    assert robot.calls == site.calls
    assert (motion.generation != generation) is site.refused_planned
    assert site.refused_planned is ENDINGS[site.how].refuse_planned or name.startswith(
        ("cell goal", "passthrough", "end_tool_contact")  # one goal, or a contact's end: not the plan
    )
    assert motion.in_contact is site.in_contact
    told = any(call in ("stop", "abort", "cancel") for call in site.calls)
    assert (robot.runtime.controller.active_goal_id is None) is (told or not site.moving)
