"""What the view sends a robot (``urdaemon.view.control``), against a recording stand-in for the
robot's client: no Zenoh, no browser.

Reproduction on the code before issue 18: there was no ``urdaemon.view``, so every test fails at import.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Sequence
from typing import Any

import pytest

from urdaemon.client import LeaseHeld
from urdaemon.errors import UrDaemonError
from urdaemon.view.control import ANGULAR_PER_LINEAR, RobotControl, jog_twist
from urdaemon.view.feed import STALE_S, JointSample
from urdaemon.view.panel import problem_of, status_markdown
from urdaemon.view.scene import robot_of_link

START = (0.1, -1.5, 1.5, -1.5, -1.5, 0.2)


class FakeRobot:
    """Records what it is sent; ``held_by`` makes ``ensure_lease`` refuse as the daemon would."""

    name = "alice"

    def __init__(self, held_by: str | None = None) -> None:
        self.held_by = held_by
        self.calls: list[tuple[str, Any]] = []

    async def ensure_lease(self) -> str:
        if self.held_by is not None:
            raise LeaseHeld(f"lease: robot 'alice' is held by {self.held_by}")
        self.calls.append(("lease", None))
        return "token"

    async def release(self) -> None:
        self.calls.append(("release", None))

    async def stop(self) -> dict[str, Any]:
        self.calls.append(("stop", None))
        return {"ok": True}

    def stream_positions(self, positions: Sequence[float], velocities: Sequence[float] | None = None) -> None:
        self.calls.append(("positions", tuple(positions)))

    def twist(self, linear: Sequence[float], angular: Sequence[float], *, frame: str = "base") -> None:
        self.calls.append(("twist", (tuple(linear), tuple(angular), frame)))

    def sent(self, kind: str) -> list[Any]:
        return [value for name, value in self.calls if name == kind]


def _enabled(control: RobotControl) -> bool:
    return control.enabled


def _at_rest() -> JointSample:
    return JointSample(("alice_j1",) * 6, START, (0.0,) * 6, time.monotonic())


async def test_enable_streams_the_robots_own_joints_first() -> None:
    robot = FakeRobot()
    control = RobotControl(robot, _at_rest)
    control.set_target(0, 1.0)  # a slider moved while disabled: ignored
    control.tick()
    assert robot.calls == []
    assert await control.enable()
    assert robot.calls == [("lease", None)]  # the lease first, nothing streamed yet
    control.tick()
    assert robot.sent("positions") == [START]  # enabling moves nothing
    control.set_target(0, 0.5)
    control.tick()
    assert robot.sent("positions")[-1] == (0.5, *START[1:])
    await control.disable()
    control.tick()
    assert robot.calls[-1] == ("release", None)
    assert len(robot.sent("positions")) == 2


async def test_enable_refused_sends_nothing_and_says_who_holds_the_lease() -> None:
    robot = FakeRobot(held_by="urdaemon teleop (pid 7 on cell-pc)")
    control = RobotControl(robot, _at_rest)
    assert not await control.enable()
    assert "held by urdaemon teleop" in control.refusal
    control.tick()
    assert robot.calls == []


async def test_enable_without_joint_states_gives_the_lease_back() -> None:
    robot = FakeRobot()
    control = RobotControl(robot, lambda: None)
    assert not await control.enable()
    assert "no joint_states" in control.refusal
    assert robot.calls == [("lease", None), ("release", None)]


async def test_enable_refuses_joint_states_older_than_the_staleness_limit() -> None:
    """Reproduction: enable took whatever sample the feed held, however old, as the targets; a robot
    that moved since (or a feed that stopped) would then be streamed back towards an old pose."""
    robot = FakeRobot()
    old = JointSample(("alice_j1",) * 6, START, (0.0,) * 6, 100.0)
    control = RobotControl(robot, lambda: old, clock=lambda: 100.0 + STALE_S + 0.5)
    assert not await control.enable()
    assert "are 1.5 s old" in control.refusal
    control.tick()
    assert robot.calls == [("lease", None), ("release", None)]
    fresh = RobotControl(robot, lambda: old, clock=lambda: 100.0 + STALE_S)
    assert await fresh.enable()


async def test_a_refused_stream_disables_but_a_replaced_sample_does_not() -> None:
    robot = FakeRobot()
    control = RobotControl(robot, _at_rest)
    await control.enable()
    control.on_rejected("demo_cell/alice/command/joint_position", "busy: 1 sample(s) replaced by a newer one")
    assert _enabled(control)
    control.on_rejected("demo_cell/alice/command/joint_position", "robot not ready: protective stop")
    assert not _enabled(control)
    control.tick()
    assert robot.sent("positions") == []
    await asyncio.wait_for(asyncio.gather(*control._pending), 5.0)
    assert robot.calls[-1] == ("release", None)
    assert control.refusal == "refused: robot not ready: protective stop"


async def test_stop_stops_then_disables() -> None:
    robot = FakeRobot()
    control = RobotControl(robot, _at_rest)
    await control.enable()
    await control.stop()
    assert [name for name, _ in robot.calls] == ["lease", "stop", "release"]
    assert not control.enabled


async def test_a_stream_the_client_refuses_disables() -> None:
    class LostLease(FakeRobot):
        def stream_positions(
            self, positions: Sequence[float], velocities: Sequence[float] | None = None
        ) -> None:
            raise UrDaemonError("lease: taken over by someone else")

    robot = LostLease()
    control = RobotControl(robot, _at_rest)
    await control.enable()
    control.tick()
    assert not control.enabled
    await asyncio.wait_for(asyncio.gather(*control._pending), 5.0)
    assert "taken over" in control.refusal


async def test_a_jog_twists_then_zero_and_pauses_the_joint_stream() -> None:
    robot = FakeRobot()
    control = RobotControl(robot, _at_rest)
    assert not await control.jog((0.0, 0.0, 0.05), (0.0, 0.0, 0.0), "tool")  # not enabled: nothing
    assert robot.calls == []
    await control.enable()
    jog = asyncio.create_task(control.jog((0.0, 0.0, 0.05), (0.0, 0.0, 0.0), "tool"))
    await asyncio.sleep(0)
    control.tick()  # while jogging the joint stream sends nothing
    assert await asyncio.wait_for(jog, 10.0)
    twists = robot.sent("twist")
    moving = [t for t in twists if t[0] != (0.0, 0.0, 0.0)]
    assert moving
    assert all(t == ((0.0, 0.0, 0.05), (0.0, 0.0, 0.0), "tool") for t in moving)
    assert twists[-1][:2] == ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    assert twists[: len(moving)] == moving  # every moving twist before the zero ones
    assert robot.sent("positions") == []
    control.tick()
    assert robot.sent("positions") == [START]  # the stream goes on from where the jog left it


def test_jog_twists() -> None:
    assert jog_twist("z", 1, 0.05) == ((0.0, 0.0, 0.05), (0.0, 0.0, 0.0))
    assert jog_twist("rx", -1, 0.05) == ((0.0, 0.0, 0.0), (-0.05 * ANGULAR_PER_LINEAR, 0.0, 0.0))
    with pytest.raises(ValueError, match="no jog"):
        jog_twist("w", 1, 0.05)
    with pytest.raises(ValueError, match="no jog"):
        jog_twist("x", 1, float("nan"))


def test_what_is_shown_over_a_robot() -> None:
    assert problem_of(None, stale=True) == "disconnected"
    assert problem_of({"lifecycle": "protective_stop"}, stale=False) == "protective stop"
    assert problem_of({"lifecycle": "emergency_stop"}, stale=False) == "emergency stop"
    assert problem_of({"lifecycle": "running"}, stale=False) is None
    text = status_markdown(
        {"lifecycle": "running", "speed_scaling": 0.5, "active_goal": "g1", "lease": {"holder": "me"}},
        False,
        "",
    )
    assert "running" in text
    assert "50 %" in text
    assert "g1" in text
    assert "lease: me" in text


def test_links_belong_to_the_longest_robot_name_prefix() -> None:
    assert robot_of_link("alice_tool0", ["alice", "al"]) == "alice"
    assert robot_of_link("al_tool0", ["alice", "al"]) == "al"
    assert robot_of_link("world", ["alice"]) is None
