"""Properties over random command sequences: one result per accepted goal, and limits always respected."""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from urdaemon.control import GoalResult, GoalStatus, TrajectoryPoint
from urdaemon.errors import GoalRejected
from urdaemon.model import UR_JOINTS

from .sim import PERIOD, THREE_LIMITS, UR10E_LIMITS, SimRobot, check_command_limits

NAMES3 = ("a", "b", "c")

position = st.tuples(st.floats(-0.9, 0.9), st.floats(-1.8, 1.8), st.floats(-0.45, 0.45))


@dataclass(frozen=True)
class Op:
    kind: str
    preempt: bool = False
    points: tuple[tuple[float, float, float], ...] = ()
    spacing: float = 1.0
    scale: float = 1.0
    ticks: int = 0


def _ops(allow_not_ready: bool) -> st.SearchStrategy[Op]:
    kinds = [
        "trajectory",
        "move",
        "cancel",
        "cancel_other",
        "stop",
        "stream_position",
        "stream_velocity",
        "wait",
    ]
    if allow_not_ready:
        kinds.append("not_ready")
    return st.builds(
        Op,
        kind=st.sampled_from(kinds),
        preempt=st.booleans(),
        points=st.lists(position, min_size=1, max_size=3).map(tuple),
        spacing=st.floats(0.6, 2.0),
        scale=st.floats(0.2, 1.0),
        ticks=st.integers(0, 150),
    )


def _execute(robot: SimRobot, ops: list[Op]) -> tuple[list[str], list[str]]:
    """Apply ``ops`` to ``robot``; returns (accepted goal ids, rejected goal ids)."""
    controller = robot.controller
    accepted: list[str] = []
    rejected: list[str] = []
    stream_rejections: list[str] = []
    for n, op in enumerate(ops):
        goal_id = f"g{n}"
        try:
            if op.kind == "trajectory":
                points = [TrajectoryPoint(p, (k + 1) * op.spacing) for k, p in enumerate(op.points)]
                controller.accept_trajectory(
                    goal_id, NAMES3, points, robot.state, robot.now, preempt=op.preempt
                )
                accepted.append(goal_id)
            elif op.kind == "move":
                controller.accept_move(
                    goal_id,
                    NAMES3,
                    op.points[0],
                    robot.state,
                    robot.now,
                    velocity_scale=op.scale,
                    preempt=op.preempt,
                )
                accepted.append(goal_id)
        except GoalRejected:
            rejected.append(goal_id)
        if op.kind == "cancel":
            controller.cancel()
        elif op.kind == "cancel_other":
            assert controller.cancel("nobody") is False
        elif op.kind == "stop":
            controller.stop("test stop", robot.now)
        elif op.kind == "not_ready":
            robot.state.program_running = False
            for _ in range(3):
                robot.step()
            robot.state.program_running = True
        for k in range(op.ticks):
            if op.kind in ("stream_position", "stream_velocity") and k < op.ticks // 2:
                try:
                    if op.kind == "stream_position":
                        controller.stream_positions(NAMES3, op.points[-1], None, robot.state, robot.now)
                    else:
                        velocity = tuple(0.5 * op.scale * (1 if x >= 0 else -1) for x in op.points[-1])
                        controller.stream_velocities(NAMES3, velocity, robot.state, robot.now)
                except GoalRejected as exc:
                    stream_rejections.append(exc.reason)
            robot.step()
    # Let everything finish: goals end (bounded by their length and the goal time), streams time out.
    for _ in range(8000):
        if controller.mode == "idle":
            break
        robot.step()
    assert controller.mode == "idle"
    assert controller.active_goal_id is None
    # Streams are only ever refused because a goal is executing.
    assert all(reason.startswith("busy: goal ") for reason in stream_rejections), stream_rejections
    return accepted, rejected


def _check_one_result_each(robot: SimRobot, accepted: list[str], rejected: list[str]) -> None:
    results = robot.results()
    counts = Counter(r.goal_id for r in results)
    assert set(counts) == set(accepted)
    assert all(c == 1 for c in counts.values()), counts
    assert not set(rejected) & set(counts)
    # Results come in acceptance order: a goal only ends once the previous one has ended.
    assert [r.goal_id for r in results] == accepted
    stats = robot.controller.statistics()
    by_status = Counter(r.status for r in results)
    assert stats.goals_accepted == len(accepted)
    assert stats.goals_succeeded == by_status[GoalStatus.SUCCEEDED]
    assert stats.goals_aborted == by_status[GoalStatus.ABORTED]
    assert stats.goals_canceled == by_status[GoalStatus.CANCELED]
    assert stats.goals_preempted == by_status[GoalStatus.PREEMPTED]
    for r in results:
        assert isinstance(r, GoalResult)
        assert r.reason


@settings(max_examples=60, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(ops=st.lists(_ops(allow_not_ready=True), min_size=3, max_size=12))
def test_every_accepted_goal_gets_exactly_one_result(ops: list[Op]) -> None:
    robot = SimRobot.create(THREE_LIMITS)
    robot.record = False
    accepted, rejected = _execute(robot, ops)
    _check_one_result_each(robot, accepted, rejected)


@settings(max_examples=60, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(ops=st.lists(_ops(allow_not_ready=False), min_size=3, max_size=12))
def test_commands_respect_velocity_and_acceleration_limits(ops: list[Op]) -> None:
    robot = SimRobot.create(THREE_LIMITS)
    accepted, rejected = _execute(robot, ops)
    _check_one_result_each(robot, accepted, rejected)
    check_command_limits(robot.commands, THREE_LIMITS, PERIOD)
    for _, pos, _ in robot.commands:
        for i, p in enumerate(pos):
            assert THREE_LIMITS.min_position[i] - 1e-9 <= p <= THREE_LIMITS.max_position[i] + 1e-9


def test_ur10e_whole_execution_respects_limits() -> None:
    robot = SimRobot.create(UR10E_LIMITS)
    controller = robot.controller
    far = [2.0, -1.5, 2.5, -2.0, 2.0, 3.0]
    controller.accept_move("m1", UR_JOINTS, far, robot.state, robot.now)
    for _ in range(400):
        robot.step()
    # Preempt at full speed with a trajectory back through the middle.
    points = [TrajectoryPoint((0.0,) * 6, 3.0), TrajectoryPoint((-1.0, 0.5, -1.0, 1.0, -1.0, -2.0), 5.0)]
    controller.accept_trajectory("t1", UR_JOINTS, points, robot.state, robot.now, preempt=True)
    for _ in range(1000):
        robot.step()
    controller.accept_move("m2", UR_JOINTS, far, robot.state, robot.now, preempt=True)
    robot.run_until_result("m2", 5000)
    # Stream velocities at the limits, then let the deadman stop it.
    for _ in range(500):
        controller.stream_velocities(
            UR_JOINTS, [-2.094, 2.094, -3.14159, 3.14159, -3.14159, -3.14159], robot.state, robot.now
        )
        robot.step()
    robot.run_until_idle(2000)
    worst_v, worst_a = check_command_limits(robot.commands, UR10E_LIMITS, PERIOD)
    assert worst_v > 0.99  # the scenario really ran at the limits
    assert worst_a > 0.95
    assert [r.status for r in robot.results()] == [
        GoalStatus.PREEMPTED,
        GoalStatus.PREEMPTED,
        GoalStatus.SUCCEEDED,
    ]
    assert controller.statistics().deadman_stops == 1
    for _, pos, _ in robot.commands:
        for i, p in enumerate(pos):
            assert UR10E_LIMITS.min_position[i] <= p <= UR10E_LIMITS.max_position[i]


def test_public_api_is_exported() -> None:
    import urdaemon.control as control

    for name in (
        "GoalFeedback",
        "GoalResult",
        "GoalStatus",
        "MotionController",
        "ControllerStatistics",
        "PlannedTrajectory",
        "Tolerances",
        "TrajectoryPoint",
        "plan_move",
        "plan_trajectory",
        "reorder",
        "check_finite",
        "check_positions_within",
    ):
        assert name in control.__all__
        assert hasattr(control, name)
