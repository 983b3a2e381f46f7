"""Review of issue 13's fix, the ``ur`` backend's part: a passthrough goal is encoded before it is
accepted, so what the trajectory-point protocol cannot carry is a clear refusal and nothing is left
in limbo. A RobotRuntime drives a ``UrBackend`` against the fake controller (no Zenoh: a fake node and
fake queries); waits are on cycles and replies, bounded in time."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager

import pytest

from tests.helpers import fake_address, free_tcp_port
from tests.integration.test_review_planning import Node, Query, trajectory
from tests.ur.test_links_harness import HOME, UrRun, program_is_running
from urdaemon.backends.ur.backend import UrBackend
from urdaemon.cell.load import parse_cell
from urdaemon.control import MotionController
from urdaemon.daemon import describe_cell
from urdaemon.errors import BackendError
from urdaemon.fakeur.controller import FakeController
from urdaemon.protocols import trajectory_point
from urdaemon.robot import RobotRuntime

pytestmark = pytest.mark.timeout(90)


class CountedUrBackend(UrBackend):
    """The ur backend; ``after_cycle`` runs after each cycle, once the runtime's work of it is done."""

    after_cycle: Callable[[], None] = staticmethod(lambda: None)

    async def run(self, on_cycle: Callable[[], None]) -> None:
        def cycle() -> None:
            on_cycle()
            self.after_cycle()

        await super().run(cycle)


@asynccontextmanager
async def served() -> AsyncIterator[tuple[RobotRuntime, UrRun]]:
    """alice (a ``ur`` robot) served by a RobotRuntime against a fake controller, ready."""
    address = fake_address()
    ports = [free_tcp_port() for _ in range(4)]
    cell = parse_cell(
        f"""
cell: review
robots:
  - name: alice
    model: ur10e
    backend: ur
    address: {address}
    headless: true
    ports:
      {{reverse: {ports[0]}, script_sender: {ports[1]}, trajectory: {ports[2]}, script_command: {ports[3]}}}
    ur: {{startup: true, listen_address: 127.0.0.1}}
"""
    )
    robot = cell.robot("alice")
    limits = describe_cell(cell).limits["alice"]
    fake = FakeController("ur10e", address=address, initial_positions=HOME)
    await fake.start()
    backend = CountedUrBackend(robot, limits.names, expected_hash=None)
    run = UrRun(backend, fake)
    backend.after_cycle = run.on_cycle
    controller = MotionController(limits, period=backend.period)
    runtime = RobotRuntime(cell.cell, robot, backend, controller, Node(), cell.publish)  # type: ignore[arg-type]
    runtime.declare()
    task = asyncio.create_task(runtime.run())
    run.task = task
    try:
        await run.until(lambda: program_is_running(run), what="ready")
        yield runtime, run
    finally:
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
        await backend.close()
        await fake.close()


def encoded_ok(backend: UrBackend) -> bytes:
    return backend.encode_passthrough_point(HOME, (0.0,) * 6, None, 2147.0)


async def test_a_segment_longer_than_the_protocol_carries_is_refused_and_leaves_no_goal() -> None:
    """Reproduction: a passthrough goal whose last segment lasts 2200 s (trajectory_point carries at
    most 2147 s) passed the check and ``accept_external``; then encoding raised: the client was told
    "accepted: false, internal error" while the controller kept an EXTERNAL goal, so every later goal
    was refused "busy" and a result came later for the goal the client was told was refused."""
    async with served() as (runtime, run):
        too_long = Query("review/alice/goal/trajectory", trajectory(5, passthrough=True, last_segment=2200.0))
        runtime.goals.on_trajectory_goal(too_long)
        answer = await too_long.answer()
        assert answer["accepted"] is False
        assert answer["reason"] == (
            "passthrough: point 4: a segment of 2200 s is longer than the robot can take"
            " (at most 2147 s between two points)"
        ), answer
        assert runtime.controller.active_goal_id is None, "no goal kept, passthrough or other"
        assert runtime.controller.mode == "idle"
        assert run.backend.passthrough_problem() is None, "no START went out"
        good = Query("review/alice/goal/trajectory", trajectory(5, passthrough=True))
        runtime.goals.on_trajectory_goal(good)
        accepted = await good.answer()
        assert accepted["accepted"] is True, accepted
        assert runtime.controller.active_goal_id == accepted["goal_id"]
        assert runtime.controller.mode == "external", "the robot interpolates it (passthrough)"


async def test_the_backend_encodes_a_point_at_a_time_and_sends_pre_encoded_points() -> None:
    """The backend API the runtime slices: one point's frame, or a BackendError naming the value;
    START goes out only with whole frames."""
    async with served() as (_, run):
        backend = run.backend
        assert len(encoded_ok(backend)) == trajectory_point.FRAME_BYTES
        with pytest.raises(BackendError, match=r"segment of 2147\.5 s is longer than the robot can take"):
            backend.encode_passthrough_point(HOME, (0.0,) * 6, None, 2147.5)
        with pytest.raises(BackendError, match="not 2 encoded trajectory points"):
            backend.start_encoded_passthrough("g1", encoded_ok(backend), 2, lambda goal, code, why: None)
        assert backend.passthrough_problem() is None, "no START went out"
