"""Driving a cell through a recorded motion: check that the daemon serves the recording's cell with
the same robots and joints, move each robot to where the recording starts (one move goal each, at
once), then send the plan's cell goals one after another (goal_plan.py). Ctrl-C cancels whatever goal
runs (the robots stop), as ``urdaemon move`` does.

The goals take each robot's command lease like any client (``Client.robot``, ``send_cell_trajectory``).
"""

from __future__ import annotations

import asyncio
import json
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, TextIO

from urdaemon.client import CellGoalHandle, Client, GoalHandle, send_cell_trajectory
from urdaemon.errors import GoalRejected, UrDaemonError, UrTimeoutError
from urdaemon.publish.keys import RobotKeys
from urdaemon.replay.goal_plan import Plan, Track, make_plan, unplanned_motion
from urdaemon.replay.source import RecordedCell, mismatch, sample_period

if TYPE_CHECKING:
    from urdaemon.cell.config import Cell

__all__ = ["EXIT_BAD_INPUT", "EXIT_FAILED", "EXIT_INTERRUPTED", "EXIT_OK", "Drive", "served_joint_names"]

EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT, EXIT_INTERRUPTED = 0, 1, 2, 130
CANCEL_WAIT_S = 5.0
"""After Ctrl-C, how long to wait for the canceled goal's result."""
NAMES_WAIT_S = 5.0


async def served_joint_names(client: Client, cell: Cell) -> tuple[dict[str, tuple[str, ...]], str | None]:
    """Each robot's joint names as the daemon at ``client`` publishes them, or why the daemon does
    not serve ``cell`` (another cell, other robots, no joint states)."""
    served = await client.robots()
    robots = sorted(r for c, r in served if c == cell.cell)
    want = sorted(r.name for r in cell.robots)
    if robots != want:
        cells = sorted({c for c, _ in served})
        return {}, (
            f"the daemon at {client.endpoint} does not serve the cell file's cell {cell.cell!r} "
            f"(robots {', '.join(want)}): it serves "
            + (", ".join(f"{c}: {', '.join(r for cc, r in served if cc == c)}" for c in cells) or "nothing")
        )
    names: dict[str, tuple[str, ...]] = {}
    for robot in robots:
        sub = client.subscribe(RobotKeys(cell.cell, robot).joint_states, maxsize=4)
        try:
            message = await sub.get_json(NAMES_WAIT_S)
        except UrTimeoutError:
            return {}, f"robot {robot!r} published no joint_states within {NAMES_WAIT_S:g} s"
        finally:
            client.unsubscribe(sub)
        names[robot] = tuple(str(n) for n in message.get("names", ()))
    return names, None


@dataclass
class Drive:
    """One replay of ``recorded`` on the cell of ``client``, for ``robots`` at ``rate``."""

    client: Client
    cell: Cell
    recorded: RecordedCell
    robots: Sequence[str]
    rate: float
    err: TextIO
    out: TextIO
    mode: str | None = None
    """``samples`` or ``moves`` (goal_plan.py); None: chosen by the rate."""

    async def run(self) -> int:
        """Check, plan, drive; the exit code (130 after Ctrl-C, the goal canceled first)."""
        problem = await self._problem()
        if problem is not None:
            print(f"error: {problem}", file=self.err)
            return EXIT_BAD_INPUT
        tracks = self.tracks()
        plan = make_plan(tracks, self.rate, self.mode)
        for note in plan.notes:
            print(f"note: {note}", file=self.err)
        unplanned = unplanned_motion(tracks, plan)
        if unplanned:
            print(
                f"error: the recording shows {', '.join(unplanned)} moving, but no cell goal was planned "
                f"for it from its {sum(len(t.samples) for t in tracks if t.robot in unplanned)} joint "
                "state(s): samples missing or bunched read as rest (was the recorder starved?); "
                "nothing replayed",
                file=self.err,
            )
            return EXIT_FAILED
        print(
            f"replaying {', '.join(self.robots)} at rate {self.rate:g} ({plan.mode}): "
            f"{len(plan.steps)} cell goal(s) after the move to the start",
            file=self.err,
        )
        current: list[Any] = []
        try:
            return await self._drive(plan, current)
        except asyncio.CancelledError:
            task = asyncio.current_task()
            if task is not None:
                task.uncancel()
            await self._cancel(current)
            return EXIT_INTERRUPTED

    async def _problem(self) -> str | None:
        missing = [r for r in self.robots if r not in self.recorded.samples]
        if missing:
            return (
                f"--robot {', '.join(missing)}: no joint states of it in the recording "
                f"(it has {', '.join(self.recorded.robots) or 'none'})"
            )
        names, problem = await served_joint_names(self.client, self.cell)
        if problem is not None:
            return problem
        return mismatch(self.recorded, self.cell, names, self.robots)

    def tracks(self) -> list[Track]:
        """The chosen robots' recorded motion, each on its sample period."""
        config = {r.name: r for r in self.cell.robots}
        return [
            Track(
                r,
                sample_period(config[r], self.cell),
                tuple(self.recorded.samples[r]),
                tuple(self.recorded.goals.get(r, ())),
            )
            for r in self.robots
        ]

    async def _drive(self, plan: Plan, current: list[Any]) -> int:
        moves = [await self._send_move(robot, first, current) for robot, first in plan.first.items()]
        for goal in moves:
            result = await goal.result()
            if result.get("status") != "succeeded":
                return self._failed(f"the move of {goal.robot.name} to the recording's start", result)
        current.clear()
        for index, step in enumerate(plan.steps, 1):
            handle = await self._send_step(step.parts, current)
            print(
                f"cell goal {index}/{len(plan.steps)} ({', '.join(step.parts)}; recorded at "
                f"{step.start_s:.3f} s): accepted, planned {handle.duration:.3f} s",
                file=self.err,
            )
            result = await handle.result()
            current.clear()
            if result.get("status") != "succeeded":
                return self._failed(f"cell goal {index}", result)
        print(
            json.dumps({"replayed": list(self.robots), "cell_goals": len(plan.steps), "rate": self.rate}),
            file=self.out,
        )
        return EXIT_OK

    async def _send_move(self, robot: str, first: Sequence[float], current: list[Any]) -> GoalHandle:
        handle = await self.client.robot(robot, cell=self.cell.cell)
        # a task of its own, so that Ctrl-C while the reply is on its way still learns the goal
        sending = asyncio.ensure_future(handle.move(list(first)))
        current.append(sending)
        goal = await asyncio.shield(sending)
        current[current.index(sending)] = goal
        return goal

    async def _send_step(self, parts: dict[str, list[dict[str, Any]]], current: list[Any]) -> CellGoalHandle:
        sending = asyncio.ensure_future(send_cell_trajectory(self.client, self.cell.cell, parts))
        current.append(sending)
        handle = await asyncio.shield(sending)
        current[:] = [handle]
        return handle

    def _failed(self, what: str, result: dict[str, Any]) -> int:
        print(f"error: {what} ended {result.get('status')}: {result.get('reason', '')}", file=self.err)
        print(json.dumps(result), file=self.out)
        return EXIT_FAILED

    async def _cancel(self, current: list[Any]) -> None:
        """Cancel every goal sent (waiting for the reply of one on its way), then its result."""
        for item in current:
            goal = item
            if isinstance(item, asyncio.Future):
                try:
                    goal = await asyncio.wait_for(item, CANCEL_WAIT_S)
                except (GoalRejected, UrDaemonError, TimeoutError):
                    continue
            try:
                if isinstance(goal, CellGoalHandle):
                    print(f"interrupted: canceling cell goal {goal.goal_id}", file=self.err)
                    await goal.cancel()
                else:
                    print(f"interrupted: canceling goal {goal.goal_id} of {goal.robot.name}", file=self.err)
                    await goal.robot.cancel(goal.goal_id)
                await goal.result(timeout=CANCEL_WAIT_S)
            except UrDaemonError as err:
                print(f"error: the goal may still run: {err}", file=self.err)
        print("interrupted: the robots stop", file=self.err)
