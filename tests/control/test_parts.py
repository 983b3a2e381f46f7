"""The controller's parts on their own: the contracts the façade relies on, and the tick benchmark."""

from __future__ import annotations

import math
from types import ModuleType

import pytest

from tests.helpers import load_benchmark
from urdaemon.control import GoalFeedback, GoalResult, MotionController, TrajectoryPoint
from urdaemon.control.online import OnlineGenerator
from urdaemon.control.setpoint import Setpoint
from urdaemon.control.streams import STREAM_EXPIRED, STREAM_FOLLOWED, StreamFollower
from urdaemon.model import UR_JOINTS, CommandMode, JointCommand

from .sim import PERIOD, UR10E_LIMITS, ready_state

START = [0.0, -1.57, 1.57, -1.57, -1.57, 0.0]


def _follower(timeout: float) -> tuple[StreamFollower, Setpoint]:
    setpoint = Setpoint(UR10E_LIMITS, UR10E_LIMITS, PERIOD)
    online = OnlineGenerator(UR10E_LIMITS, PERIOD, setpoint)
    return StreamFollower(UR10E_LIMITS, PERIOD, timeout, online, setpoint), setpoint


def test_a_drained_list_is_kept_as_drained_while_the_goal_feeds_back_on() -> None:
    """The running goal appends to the controller's own list, so a drain hands out a copy: what was
    drained stays as it was, and what the goal emits later comes with the next drain, once."""
    controller = MotionController(UR10E_LIMITS, period=PERIOD, feedback_period=0.0)
    state = ready_state(UR_JOINTS, START)
    command = JointCommand.idle(6)
    goal = tuple(p + 0.2 for p in START)
    point = TrajectoryPoint(positions=goal, time_from_start=1.0)
    controller.accept_trajectory("g1", UR_JOINTS, [point], state, 0.0)
    controller.tick(state, command, 0.0)
    first = controller.drain_events()
    assert [type(e) for e in first] == [GoalFeedback]
    assert not controller.has_events
    controller.tick(state, command, PERIOD)
    assert [type(e) for e in first] == [GoalFeedback]  # the drained list did not change
    second = controller.drain_events()
    assert [type(e) for e in second] == [GoalFeedback]
    assert isinstance(first[0], GoalFeedback)
    assert isinstance(second[0], GoalFeedback)
    assert second[0].time_from_start > first[0].time_from_start
    assert controller.drain_events() == []
    controller.cancel("g1")
    assert [type(e) for e in controller.drain_events()] == [GoalResult]


def test_a_stream_without_a_command_for_longer_than_its_timeout_has_expired() -> None:
    """The deadman: past the timeout a stream tick writes nothing and says so; the controller stops it."""
    follower, setpoint = _follower(timeout=0.1)
    perm = tuple(range(6))
    follower.follow_positions(perm, [p + 0.1 for p in START], None, START, now=0.0)
    command = JointCommand.idle(6)
    assert follower.tick_positions(command, now=0.1) == STREAM_FOLLOWED
    assert command.mode is CommandMode.POSITION
    assert command.positions == setpoint.pos
    command.mode = CommandMode.IDLE
    assert follower.tick_positions(command, now=0.1 + 1e-6) == STREAM_EXPIRED
    assert command.mode is CommandMode.IDLE
    follower.forget()
    assert not follower.active(0.0)


def test_a_velocity_stream_latches_a_joint_at_its_limit_until_asked_the_other_way() -> None:
    """A velocity stream into a limit stops there and stays stopped while the client still asks to go
    on; asking the other way moves it back out."""
    follower, setpoint = _follower(timeout=1.0)
    perm = tuple(range(6))
    command = JointCommand.idle(6)
    up = [0.0, 0.0, 1.0, 0.0, 0.0, 0.0]
    follower.follow_velocities(perm, up, START, first=True, now=0.0)
    now = 0.0
    for _ in range(2_000):
        now += PERIOD
        follower.follow_velocities(perm, up, None, first=False, now=now)
        assert follower.tick_velocities(command, now) == STREAM_FOLLOWED
        assert setpoint.pos[2] <= math.pi + 1e-9
    assert setpoint.vel[2] == pytest.approx(0.0, abs=1e-9)
    assert setpoint.pos[2] > math.pi - 0.1
    follower.follow_velocities(perm, [-v for v in up], None, first=False, now=now)
    for _ in range(100):
        now += PERIOD
        assert follower.tick_velocities(command, now) == STREAM_FOLLOWED
    assert setpoint.vel[2] < 0.0


def _bench() -> ModuleType:
    return load_benchmark("tick_cost")


def test_each_case_of_the_tick_benchmark_stays_in_the_mode_it_measures(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """benchmarks/tick_cost.py: each case keeps the controller in its mode for all its cycles (the run
    raises otherwise), so the figures it prints are of that mode's tick."""
    bench = _bench()
    monkeypatch.setattr(bench, "CYCLES", 1_000)
    for case, mode in (
        (bench._goal, "goal"),
        (bench._position_stream, "stream_position"),
        (bench._velocity_stream, "stream_velocity"),
        (bench._into_a_limit, "stream_velocity"),
    ):
        assert bench.run_once(case, mode) > 0.0
