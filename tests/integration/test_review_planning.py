"""Review of issue 13's fix: a trajectory goal being decoded, checked, planned or encoded (in slices,
over many turns of the event loop) must not start after something ended motion meanwhile.

One RobotRuntime on a mock backend (a fake node, fake queries: no Zenoh); the handlers are called as
Zenoh would call them. Waits are on replies and cycles (events), bounded in count and time.
"""

from __future__ import annotations

import asyncio
import json
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

import pytest

from tests.helpers import swing_trajectory
from tests.integration.conftest import TWO_MOCKS
from urdaemon.backends.base import PassthroughResult
from urdaemon.backends.mock import MockBackend
from urdaemon.cell import parse_cell
from urdaemon.control import MotionController
from urdaemon.daemon import describe_cell
from urdaemon.errors import BackendError
from urdaemon.protocols import trajectory_point
from urdaemon.publish.services import spec
from urdaemon.robot import RobotRuntime

pytestmark = pytest.mark.timeout(60)

ROOT = Path(__file__).resolve().parents[2]
HOME = (0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0)


class Payload:
    def __init__(self, data: bytes) -> None:
        self.data = data

    def to_bytes(self) -> bytes:
        return self.data


class Query:
    """What the runtime's queryables get from Zenoh: records every reply; ``answered`` on the first."""

    def __init__(self, key: str, body: bytes | dict[str, Any] | None = None) -> None:
        self.key_expr = key
        data = json.dumps(body).encode() if isinstance(body, dict) else body
        self.payload = None if data is None else Payload(data)
        self.replies: list[dict[str, Any]] = []
        self.dropped = 0
        self.answered = asyncio.Event()

    def reply(self, key: Any, payload: bytes) -> None:
        self.replies.append(json.loads(payload))
        self.answered.set()

    def drop(self) -> None:
        self.dropped += 1

    async def answer(self, timeout: float = 20.0) -> dict[str, Any]:
        await asyncio.wait_for(self.answered.wait(), timeout)
        assert len(self.replies) == 1, self.replies
        return self.replies[0]


class Publisher:
    def put(self, payload: bytes) -> None:
        pass


class Node:
    """Zenoh's node, recording what is published; no session."""

    def __init__(self) -> None:
        self.puts: list[tuple[str, bytes]] = []
        self.handlers: dict[str, Callable[[Any], None]] = {}

    def put(self, key: str, payload: bytes, *, attachment: bytes | None = None) -> None:
        self.puts.append((key, payload))

    def publisher(self, key: str, **_: Any) -> Publisher:
        return Publisher()

    def matching(self, publisher: Any) -> Any:
        from urdaemon.publish.tap import Matching

        return Matching(False)

    def queryable(self, key: str, handler: Any, **_: Any) -> None:
        self.handlers[key] = handler

    def subscriber(self, key: str, handler: Any, **_: Any) -> None:
        pass

    def liveliness_token(self, key: str) -> None:
        pass

    def results(self) -> list[dict[str, Any]]:
        return [json.loads(p) for k, p in self.puts if "/goal/result/" in k or k.endswith("/result")]


class HandBackend(MockBackend):
    """The mock with freedrive and robot-side interpolation (passthrough) as the ur backend has them:
    points encoded with the trajectory-point protocol's encoder, so what the wire cannot carry fails
    as it does on a UR robot. ``encoded_turns``: the event-loop turn of every point encoded;
    ``after_cycle`` runs after each cycle, once the runtime's work of the cycle is done."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.after_cycle: Callable[[], None] = lambda: None
        self.freedrive_on = False
        self.passthrough: tuple[str, int] | None = None
        self.turn: Callable[[], int] = lambda: 0
        self.encoded_turns: list[int] = []

    async def run(self, on_cycle: Callable[[], None]) -> None:
        def cycle() -> None:
            on_cycle()
            self.after_cycle()

        await super().run(cycle)

    @property
    def freedrive_active(self) -> bool:
        return self.freedrive_on

    def freedrive(self, active: bool, timeout: float) -> None:
        self.freedrive_on = active

    def passthrough_problem(self) -> str | None:
        return None if self.passthrough is None else "a passthrough goal runs on the robot"

    def encode_passthrough_point(self, *point: Any) -> bytes:
        self.encoded_turns.append(self.turn())
        try:
            return trajectory_point.encode_point(trajectory_point.SplinePoint(*point))
        except Exception as err:
            raise BackendError(f"cannot send the trajectory to the robot: {err}") from None

    def start_encoded_passthrough(
        self, goal_id: str, frames: bytes, count: int, on_result: PassthroughResult
    ) -> None:
        assert len(frames) == count * trajectory_point.FRAME_BYTES
        self.passthrough = (goal_id, count)

    def cancel_passthrough(self) -> None:
        self.passthrough = None


class Cell:
    """alice's runtime on a ``HandBackend``, running; ``turn`` counts turns of the event loop."""

    def __init__(self, runtime: RobotRuntime, backend: HandBackend, node: Node) -> None:
        self.runtime = runtime
        self.backend = backend
        self.node = node
        self.turns = 0
        self.cycle = asyncio.Event()

    def key(self, tail: str) -> str:
        return f"{self.runtime.keys.base}/{tail}"

    async def cycles(self, condition: Callable[[], bool], limit: int = 5000) -> None:
        """Wait, cycle by cycle (at most ``limit``), until ``condition()``."""
        for _ in range(limit):
            if condition():
                return
            self.cycle.clear()
            await asyncio.wait_for(self.cycle.wait(), 5.0)
        raise AssertionError(f"not within {limit} cycles")

    async def turns_until(self, condition: Callable[[], bool], limit: int = 100_000) -> None:
        """Yield turn by turn (at most ``limit``) until ``condition()``."""
        for _ in range(limit):
            if condition():
                return
            await asyncio.sleep(0)
        raise AssertionError(f"not within {limit} turns")


@asynccontextmanager
async def alice() -> AsyncIterator[Cell]:
    cell = parse_cell(TWO_MOCKS, base_dir=ROOT / "configs")
    robot = cell.robot("alice")
    limits = describe_cell(cell).limits["alice"]
    backend = HandBackend("alice", limits.names, 500.0, initial_positions=HOME)
    controller = MotionController(limits, period=backend.period)
    node = Node()
    runtime = RobotRuntime(cell.cell, robot, backend, controller, node, cell.publish)  # type: ignore[arg-type]
    runtime.declare()
    harness = Cell(runtime, backend, node)
    backend.after_cycle = harness.cycle.set
    loop = asyncio.get_running_loop()
    ticking = True

    def tick() -> None:
        harness.turns += 1
        if ticking:
            loop.call_soon(tick)

    loop.call_soon(tick)
    backend.turn = lambda: harness.turns
    task = asyncio.create_task(runtime.run())
    try:
        await harness.cycles(lambda: backend.state.ready_for_motion)
        yield harness
    finally:
        ticking = False
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)


def trajectory(points: int, *, passthrough: bool = False, last_segment: float = 1.0) -> dict[str, Any]:
    """A valid goal of ``points`` points with velocities and accelerations (a slow swing from rest)."""
    return swing_trajectory(points, HOME, passthrough=passthrough, last_segment=last_segment)


def planning(cell: Cell) -> bool:
    """True once the goal is past decoding (its points are being checked or planned)."""
    return (cell.runtime.motion.planning or "").startswith("trajectory of ")


async def test_stop_while_a_trajectory_is_planned_refuses_it() -> None:
    """Reproduction: a 3000-point goal; ``stop`` while it was checked answered ok, then the
    trajectory was accepted and the robot moved."""
    async with alice() as cell:
        goal = Query(cell.key("goal/trajectory"), trajectory(3000))
        cell.runtime.goals.on_trajectory_goal(goal)
        await cell.turns_until(lambda: planning(cell))
        stop = Query(cell.key("service/stop"))
        cell.runtime.services.on_stop(stop)
        assert (await stop.answer())["ok"] is True
        answer = await goal.answer()
        assert answer["accepted"] is False, answer
        assert "stopped while it was being planned" in answer["reason"]
        assert cell.runtime.controller.active_goal_id is None
        assert cell.runtime.controller.mode == "idle"


async def test_cancel_while_a_trajectory_is_planned_cancels_it() -> None:
    """Reproduction: ``cancel`` while a 3000-point goal was planned said "no active goal", then the
    trajectory was accepted and the robot moved."""
    async with alice() as cell:
        goal = Query(cell.key("goal/trajectory"), trajectory(3000))
        cell.runtime.goals.on_trajectory_goal(goal)
        await cell.turns_until(lambda: planning(cell))
        cancel = Query(cell.key("goal/cancel"), {})
        cell.runtime.goals.on_cancel(cancel)
        canceled = await cancel.answer()
        assert canceled["canceled"] is True, canceled
        assert "being planned" in canceled["planned"]
        answer = await goal.answer()
        assert answer["accepted"] is False
        assert "stopped while it was being planned" in answer["reason"]
        assert cell.runtime.controller.active_goal_id is None
        # nothing planned: cancel still says there is nothing to cancel
        again = Query(cell.key("goal/cancel"), {})
        cell.runtime.goals.on_cancel(again)
        nothing = await again.answer()
        assert (nothing["canceled"], nothing["reason"]) == (False, "no active goal"), nothing


async def test_stop_while_a_trajectory_is_decoded_refuses_it() -> None:
    """Reproduction: ``stop`` while a big goal was still being decoded did not stop it either."""
    async with alice() as cell:
        goal = Query(cell.key("goal/trajectory"), trajectory(3000))
        cell.runtime.goals.on_trajectory_goal(goal)
        await asyncio.sleep(0)  # its first decoding slice ran; thousands of points are left
        assert cell.runtime.motion.planning == "trajectory being decoded"
        cell.runtime.services.on_stop(Query(cell.key("service/stop")))
        answer = await goal.answer()
        assert answer["accepted"] is False
        assert "stopped while it was being planned" in answer["reason"]


async def test_a_goal_planned_after_a_stop_is_accepted_and_ends_once() -> None:
    """The counter refuses only what was planned across a stop: the next goal starts and succeeds,
    with exactly one result."""
    async with alice() as cell:
        cell.runtime.services.on_stop(Query(cell.key("service/stop")))
        goal = Query(cell.key("goal/trajectory"), trajectory(20))
        cell.runtime.goals.on_trajectory_goal(goal)
        answer = await goal.answer()
        assert answer["accepted"] is True, answer
        await cell.cycles(lambda: cell.runtime.controller.mode == "idle")
        results = [r for r in cell.node.results() if r.get("goal_id") == answer["goal_id"]]
        assert [r["status"] for r in results] == ["succeeded"], results


async def test_freedrive_is_refused_while_a_trajectory_is_planned() -> None:
    """Reproduction: freedrive switched on while a 3000-point goal was planned was accepted (the
    controller stays idle while a goal is planned); then the trajectory started too."""
    async with alice() as cell:
        goal = Query(cell.key("goal/trajectory"), trajectory(3000))
        cell.runtime.goals.on_trajectory_goal(goal)
        await cell.turns_until(lambda: planning(cell))
        rejected = cell.runtime.status.rejected_commands
        cell.runtime.commands.on_freedrive(cell.key("command/freedrive"), b'{"active": true}')
        assert cell.runtime.status.rejected_commands == rejected + 1
        assert not cell.backend.freedrive_on
        answer = await goal.answer()
        assert answer["accepted"] is True, answer  # freedrive never started: the goal may run


async def test_freedrive_on_before_accepting_refuses_the_trajectory() -> None:
    """Reproduction: the freedrive check ran once, before slicing; freedrive on by the time the goal
    was planned (here switched on at the backend) still let the trajectory start."""
    async with alice() as cell:
        goal = Query(cell.key("goal/trajectory"), trajectory(3000))
        cell.runtime.goals.on_trajectory_goal(goal)
        await cell.turns_until(lambda: planning(cell))
        cell.backend.freedrive(True, 1.0)
        answer = await goal.answer()
        assert answer["accepted"] is False
        assert "freedrive is on" in answer["reason"]
        assert cell.runtime.controller.active_goal_id is None


async def test_hand_back_control_while_a_trajectory_is_planned_refuses_it() -> None:
    """Reproduction: hand_back_control while a goal was planned, then the goal started anyway."""
    async with alice() as cell:

        async def handed_back() -> None:
            return None

        cell.backend.hand_back_control = handed_back  # type: ignore[method-assign]
        goal = Query(cell.key("goal/trajectory"), trajectory(3000))
        cell.runtime.goals.on_trajectory_goal(goal)
        await cell.turns_until(lambda: planning(cell))
        service = Query(cell.key("service/hand_back_control"))
        cell.runtime.services.run(service, spec("hand_back_control"))
        assert (await service.answer())["ok"] is True
        answer = await goal.answer()
        assert answer["accepted"] is False
        assert "stopped while it was being planned" in answer["reason"]


async def test_a_passthrough_goal_is_encoded_in_slices_before_it_is_accepted() -> None:
    """Reproduction: a 5000-point passthrough goal was encoded point by point in one turn of the
    event loop, after it was accepted (~50 ms held every robot's cycle)."""
    async with alice() as cell:
        goal = Query(cell.key("goal/trajectory"), trajectory(5000, passthrough=True))
        cell.runtime.goals.on_trajectory_goal(goal)
        answer = await goal.answer()
        assert answer["accepted"] is True, answer
        turns = cell.backend.encoded_turns
        assert len(turns) == 5000
        busiest = max(turns.count(t) for t in set(turns))
        assert busiest < 5000 // 4, f"{busiest} of 5000 points were encoded in one turn"
        assert cell.backend.passthrough == (answer["goal_id"], 5000)


async def test_a_passthrough_segment_too_long_for_the_robot_is_refused_before_accepting() -> None:
    """Reproduction: a passthrough segment of 2200 s (the protocol carries at most 2147 s) passed the
    check and was accepted by the controller, then encoding failed: the client heard "accepted:
    false, internal error" while the controller kept the goal, so every later goal was "busy"."""
    async with alice() as cell:
        goal = Query(cell.key("goal/trajectory"), trajectory(5, passthrough=True, last_segment=2200.0))
        cell.runtime.goals.on_trajectory_goal(goal)
        answer = await goal.answer()
        assert answer["accepted"] is False
        assert answer["reason"].startswith("passthrough: point 4: "), answer
        assert "2147" in answer["reason"], answer
        assert cell.runtime.controller.active_goal_id is None, "no goal kept, passthrough or other"
        assert cell.runtime.controller.mode == "idle"
        assert cell.node.results() == []  # no result for a goal the client was told was refused
        after = Query(cell.key("goal/trajectory"), trajectory(5, passthrough=True))
        cell.runtime.goals.on_trajectory_goal(after)
        assert (await after.answer())["accepted"] is True


async def test_a_passthrough_goal_the_backend_fails_to_send_ends_with_one_result() -> None:
    """Reproduction: the backend failed (a bug) after ``accept_external``: the client heard "accepted:
    false, internal error" while the controller kept the EXTERNAL goal (every later goal "busy").
    Now nothing is in limbo: the goal was accepted, so it is answered so and ends ABORTED, once."""
    async with alice() as cell:

        def broken(goal_id: str, frames: bytes, count: int, on_result: Any) -> None:
            raise RuntimeError("socket gone")

        cell.backend.start_encoded_passthrough = broken  # type: ignore[method-assign]
        goal = Query(cell.key("goal/trajectory"), trajectory(5, passthrough=True))
        cell.runtime.goals.on_trajectory_goal(goal)
        answer = await goal.answer()
        assert answer["accepted"] is True, answer
        results = [r for r in cell.node.results() if r.get("goal_id") == answer["goal_id"]]
        assert [r["status"] for r in results] == ["aborted"], results
        assert "internal error: RuntimeError: socket gone" in results[0]["reason"]
        assert cell.runtime.controller.mode == "idle"
        after = Query(cell.key("goal/trajectory"), trajectory(5))
        cell.runtime.goals.on_trajectory_goal(after)
        assert (await after.answer())["accepted"] is True
