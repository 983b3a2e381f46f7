"""``move``: a goal to joint positions or a TCP pose (a straight line with ``--linear``) sent and
followed to its result, with a progress bar on a terminal. Ctrl-C cancels the goal first, also while
its accept reply is on its way, and exits 130."""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import sys
from collections.abc import Awaitable, Callable
from functools import partial
from typing import TYPE_CHECKING, Any

from urdaemon.cli.connect import bad_target, connect, fail
from urdaemon.cli.exit_codes import EXIT_BAD_INPUT, EXIT_FAILED, EXIT_INTERRUPTED, EXIT_OK
from urdaemon.errors import GoalRejected, UrDaemonError

if TYPE_CHECKING:
    from urdaemon.client import RobotClient

__all__ = ["GoalSender", "move"]


GoalSender = Callable[["RobotClient"], Awaitable[Any]]
"""What ``move`` sends: the goal for the robot, as a call of its client."""


def _move_problem(args: argparse.Namespace) -> tuple[GoalSender | None, str | None]:
    """The goal ``move``'s arguments ask for, or why they cannot be used."""
    if not (math.isfinite(args.velocity_scale) and 0 < args.velocity_scale <= 1):
        return None, f"--velocity-scale must be within (0, 1], got {args.velocity_scale}"
    if args.joints is not None:
        if args.linear:
            return None, "--linear moves to --pose values, not --joints"
        joints, problem = _numbers(args.joints, "--joints", None)
        send: GoalSender = partial(_send_move, joints, args)
        return (None, problem) if problem else (send, bad_target(args))
    poses = []
    for text in args.pose:
        pose, problem = _numbers(text, "--pose", 6)
        if problem is not None:
            return None, problem
        poses.append(pose)
    if not args.linear:
        return _pose_goal(poses, args)
    if args.duration is not None or args.velocity_scale != 1.0:
        return None, "--duration and --velocity-scale are for joint moves; --linear takes --speed (m/s)"
    if args.speed is not None and not (math.isfinite(args.speed) and args.speed > 0):
        return None, f"--speed must be a number of m/s > 0, got {args.speed}"
    return partial(_send_linear, poses, args), bad_target(args)


def _pose_goal(poses: list[list[float]], args: argparse.Namespace) -> tuple[GoalSender | None, str | None]:
    if len(poses) > 1:
        return None, "several --pose make a path: add --linear (a joint move goes to one pose)"
    if args.speed is not None:
        return None, "--speed (m/s) is for --linear; a pose move takes --duration or --velocity-scale"
    return partial(_send_pose, poses[0], args), bad_target(args)


def _numbers(text: str, option: str, count: int | None) -> tuple[list[float], str | None]:
    """``text``'s comma-separated finite numbers (``count`` of them when given), or why not."""
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        return [], f"{option} must be comma-separated numbers, got {text!r}"
    if not all(math.isfinite(v) for v in values):
        return [], f"{option} must be finite numbers"
    if count is not None and len(values) != count:
        return [], f"{option} needs {count} numbers (x,y,z in m, rx,ry,rz in rad), got {len(values)}"
    return values, None


async def _send_move(joints: list[float], args: argparse.Namespace, robot: RobotClient) -> Any:
    return await robot.move(joints, duration=args.duration, velocity_scale=args.velocity_scale)


async def _send_pose(pose: list[float], args: argparse.Namespace, robot: RobotClient) -> Any:
    return await robot.move_pose(
        pose, frame=args.frame, duration=args.duration, velocity_scale=args.velocity_scale
    )


async def _send_linear(poses: list[list[float]], args: argparse.Namespace, robot: RobotClient) -> Any:
    return await robot.move_linear(poses, frame=args.frame, speed=args.speed)


async def move(args: argparse.Namespace) -> int:
    """``urdaemon move ROBOT``: send the goal, follow it to its result; the exit code."""
    send, problem = _move_problem(args)
    if problem is not None or send is None:
        print(f"error: {problem}", file=sys.stderr)
        return EXIT_BAD_INPUT
    try:
        client = await connect(args)
    except UrDaemonError as err:
        return fail(err)
    async with client:
        try:
            robot = await client.robot(args.robot, cell=args.cell)
            # sent as a task of its own, so that Ctrl-C while the accept reply is on its way does not
            # lose the reply: the goal it names is canceled (_cancel_when_answered)
            sending = asyncio.ensure_future(send(robot))
            try:
                goal = await asyncio.shield(sending)
            except asyncio.CancelledError:
                return await _cancel_when_answered(sending)
        except GoalRejected as err:
            print(f"rejected: {err.reason}", file=sys.stderr)
            return EXIT_FAILED
        except UrDaemonError as err:
            return fail(err)
        print(f"goal {goal.goal_id} accepted, planned {goal.duration:.2f} s", file=sys.stderr)
        bar = _ProgressBar(sys.stderr)
        try:
            return await _follow(goal, bar)
        except asyncio.CancelledError:  # Ctrl-C: asyncio cancels this task; the robot must stop too
            bar.end()
            return await _cancel_on_interrupt(goal)


async def _follow(goal: Any, bar: _ProgressBar) -> int:
    """Show progress (on a terminal only) until the result; print it; the exit code."""
    try:
        async for feedback in goal.feedback():
            bar.show(float(feedback["progress"]))
        result = await goal.result()
    except UrDaemonError as err:
        bar.end()
        return fail(err)
    succeeded = result.get("status") == "succeeded"
    if succeeded:
        bar.show(1.0)
    bar.end()
    print(json.dumps(result))
    return EXIT_OK if succeeded else EXIT_FAILED


async def _cancel_when_answered(sending: asyncio.Future[Any]) -> int:
    """Ctrl-C while the goal's accept reply is awaited: wait for the reply (at most the request's
    own timeout) and cancel the goal it names, so no accepted goal is left with nobody following it."""
    task = asyncio.current_task()
    if task is not None:
        task.uncancel()
    print("interrupted: waiting for the goal's reply to cancel it", file=sys.stderr)
    try:
        goal = await sending
    except GoalRejected as err:
        print(f"goal not accepted, nothing moves: {err.reason}", file=sys.stderr)
        return EXIT_INTERRUPTED
    except UrDaemonError as err:
        fail(err, "no reply to the goal, which may still have been accepted (see `urdaemon cancel`): ")
        return EXIT_INTERRUPTED
    return await _cancel_on_interrupt(goal)


async def _cancel_on_interrupt(goal: Any) -> int:
    """Cancel ``goal`` after Ctrl-C and wait (briefly) for its result."""
    task = asyncio.current_task()
    if task is not None:
        task.uncancel()
    print(f"interrupted: canceling goal {goal.goal_id}", file=sys.stderr)
    try:
        reply = await goal.robot.cancel(goal.goal_id)
    except UrDaemonError as err:
        fail(err, f"goal {goal.goal_id} may still be running: cancel failed: ")
        return EXIT_INTERRUPTED
    if not reply.get("canceled"):
        print(f"goal {goal.goal_id} not canceled: {reply.get('reason', 'no reason')}", file=sys.stderr)
        return EXIT_INTERRUPTED
    try:
        result = await goal.result(timeout=5.0)
    except UrDaemonError as err:
        fail(err, f"goal {goal.goal_id} canceled, but its result did not come: ")
        return EXIT_INTERRUPTED
    print(f"goal {goal.goal_id} canceled: the robot stops", file=sys.stderr)
    print(json.dumps(result))
    return EXIT_INTERRUPTED


class _ProgressBar:
    """``\r``-rewritten progress, only when the stream is a terminal (never into a log or a pipe)."""

    def __init__(self, stream: Any) -> None:
        self._stream = stream
        self._active = bool(getattr(stream, "isatty", lambda: False)())
        self._shown = False

    def show(self, fraction: float) -> None:
        if self._active:
            self._stream.write(f"\r  {100.0 * fraction:5.1f} %")
            self._stream.flush()
            self._shown = True

    def end(self) -> None:
        if self._shown:
            self._stream.write("\n")
            self._stream.flush()
            self._shown = False
