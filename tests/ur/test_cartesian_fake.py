"""Cartesian goals on the fake's `ur` backend and on the mock, side by side (issue 17: "the linear path on
the fake deviates from the straight line by less than 0.1 mm and ends within 1e-5 m; jerk,
acceleration and speed stay within the limits along every Cartesian motion (sampled every cycle)";
"the same goals run on the mock and on the fake's `ur` backend").

One daemon serves two UR10e of one cell with the same TCP offset: ``alice`` on a fake controller
(``ur`` backend, our control script in the fake's interpreter) and ``bob`` on the mock, both resting
at ``HOME``. Each goal's request is built once and sent to both (the same bytes). The fake's own record
is its arm's TCP pose (RTDE ``actual_TCP_pose``) after every controller cycle, with the controller's
timestamp. Every wait is on a goal's result or on the fake's cycles, bounded in count and time.

The fake ticks on a ``LockstepClock``: while the program streams, each controller cycle waits for the
daemon's frame for the one before, so what the arm does is what the daemon commanded, whatever the
machine's load (on its own real-time clock a starved test process let the fake run cycles without
the daemon's servoj, and the held-then-jumped target showed as jerk the daemon never commanded).
"""

from __future__ import annotations

import itertools
import json
import math
from collections.abc import AsyncIterator, Callable, Sequence
from contextlib import asynccontextmanager
from dataclasses import dataclass, field
from typing import Any

import pytest

from tests.helpers import fake_address, free_tcp_port
from tests.integration.conftest import running_daemon
from tests.ur.lockstep import LockstepClock
from urdaemon.backends.ur.backend import UrBackend
from urdaemon.client import Client, GoalHandle, RobotClient
from urdaemon.control.stopping import SETTLE_POSITION
from urdaemon.daemon import Daemon
from urdaemon.description.frames import compose, frame_of_pose, inverse, pose_of_frame
from urdaemon.description.ik import UrKinematics
from urdaemon.description.urmodels import load_ur_model
from urdaemon.fakeur.controller import FakeController
from urdaemon.model import CommandMode
from urdaemon.urscript import DEFAULT_SERVOJ_GAIN, DEFAULT_SERVOJ_LOOKAHEAD_S

pytestmark = pytest.mark.timeout(120)

HOME = (0.0, -1.57, 1.57, -1.57, -1.57, 0.0)
TCP = (0.0, 0.0, 0.1, 0.0, 0.0, 0.0)
"""Both robots' cell-file TCP offset (a straight 10 cm tool)."""
KIN = UrKinematics(load_ur_model("ur10e"))
"""The arms' model (the fake's DH is the nominal one, as the cell expects)."""
PERIOD = 0.002
SPEED, ACCELERATION, JERK = 0.25, 1.2, 10.0
ANGULAR_SPEED, ANGULAR_ACCELERATION, ANGULAR_JERK = 1.0, 4.0, 40.0
"""The cell's default Cartesian limits (a linear goal that names none runs within them)."""


def _robot(name: str, backend: str, address: str | None) -> str:
    common = f"""
  - name: {name}
    model: ur10e
    tcp: [{", ".join(map(str, TCP))}]"""
    if backend == "mock":
        return common + f"\n    backend: mock\n    mock: {{initial_positions: [{', '.join(map(str, HOME))}]}}"
    p = [free_tcp_port() for _ in range(4)]
    ports = f"{{reverse: {p[0]}, script_sender: {p[1]}, trajectory: {p[2]}, script_command: {p[3]}}}"
    return (
        common
        + f"""
    backend: ur
    address: {address}
    headless: true
    ports: {ports}
    ur: {{startup: true, listen_address: 127.0.0.1}}"""
    )


@dataclass
class Record:
    """The fake arm's TCP pose after each controller cycle from ``on`` until the daemon stops servoing
    after it started (``done``: its hold let go; the script's stopj then kills the last µm/s)."""

    on: bool = False
    servoing: bool = False
    done: bool = False
    poses: list[tuple[float, ...]] = field(default_factory=list)
    answered: list[bool] = field(default_factory=list)
    """Per recorded cycle while servoing: whether the daemon had answered the cycle before
    (``LockstepClock``)."""


@dataclass
class Pair:
    daemon: Daemon
    client: Client
    fake: FakeController
    alice: RobotClient
    bob: RobotClient
    record: Record
    plans: dict[str, list[Any]]
    replies: dict[str, list[tuple[bytes, dict[str, Any]]]]


def _record(fake: FakeController, record: Record, clock: LockstepClock, backend: Callable[[], Any]) -> None:
    arm = fake.arm
    step: Callable[[float], None] = arm.step

    def recorded(dt: float) -> None:
        step(dt)
        if not record.on or record.done:
            return
        servoing = backend().command.mode is CommandMode.POSITION
        if record.servoing and not servoing:
            record.done = True
            return
        record.servoing = servoing
        record.poses.append(tuple(arm.actual_tcp_pose()))
        if servoing:  # at rest before the goal the arm holds whatever the daemon's timing
            record.answered.append(clock.last_answered)

    arm.step = recorded  # type: ignore[method-assign]


def _lockstep(clock: LockstepClock, backend: UrBackend) -> None:
    """The fake waits for the daemon's frame every cycle while the program streams."""
    send = backend.send_command

    def sent() -> None:
        before = backend.turnaround.count
        send()
        if backend.turnaround.count != before:
            clock.answered()

    backend.send_command = sent  # type: ignore[method-assign]
    clock.follow = lambda: backend.servers.reverse.connected and backend.state.ready_for_motion


def _spy(pair: Pair) -> None:
    """Keep every plan each robot's controller starts, and every goal request's bytes and reply."""
    for runtime in pair.daemon.runtimes:
        name = runtime.robot.name
        controller = runtime.controller
        accept = controller.accept_planned
        pair.plans[name] = []

        def planned(
            goal_id: str, plan: Any, *args: Any, _a: Any = accept, _n: str = name, **kw: Any
        ) -> float:
            pair.plans[_n].append(plan)
            return float(_a(goal_id, plan, *args, **kw))

        controller.accept_planned = planned  # type: ignore[method-assign]
    for robot in (pair.alice, pair.bob):
        command = robot._command
        pair.replies[robot.name] = []

        async def spied(
            key: str,
            body: dict[str, Any],
            answer: str,
            timeout: float,
            _c: Any = command,
            _n: str = robot.name,
        ) -> dict[str, Any]:
            reply = await _c(key, body, answer, timeout)
            pair.replies[_n].append((json.dumps(body).encode(), reply))
            return dict(reply)

        robot._command = spied  # type: ignore[method-assign]


@asynccontextmanager
async def _pair() -> AsyncIterator[Pair]:
    fake = FakeController("ur10e", address=fake_address(), initial_positions=HOME, powered=True)
    clock = LockstepClock(PERIOD)
    fake.use_clock(clock, 0)
    record = Record()
    found: list[Any] = []
    _record(fake, record, clock, lambda: found[0])
    text = "cell: cartcell\nrobots:" + _robot("alice", "ur", fake.address) + _robot("bob", "mock", None)
    async with fake, running_daemon(text) as (daemon, client):
        pair = Pair(
            daemon, client, fake, await client.robot("alice"), await client.robot("bob"), record, {}, {}
        )
        backend = daemon.runtimes[0].backend
        assert isinstance(backend, UrBackend)
        found.append(backend)
        _lockstep(clock, backend)
        await fake.until(
            lambda: backend.state.ready_for_motion and backend.servers.reverse.connected,
            cycles=20_000,
            timeout=60.0,
        )
        _spy(pair)
        yield pair


async def _both(pair: Pair, key: Callable[[RobotClient], str], body: dict[str, Any]) -> dict[str, GoalHandle]:
    """The same request to both robots."""
    return {robot.name: await robot._send_goal(key(robot), dict(body)) for robot in (pair.alice, pair.bob)}


async def _settled(fake: FakeController) -> None:
    """Until the fake arm is at rest (bounded in cycles: 5 s of its time)."""
    await fake.until(lambda: fake.arm.steady or max(abs(v) for v in fake.arm.qd) < 1e-9, cycles=2500)


def _servo_bound() -> float:
    """How much the fake's servoj law (q'' = gain (q* - q - lookahead q'), docs/fake-robot.md) may
    amplify any derivative of the setpoint stream: the L1 norm of its impulse response (1 when
    critically damped or more, above 1 when it overshoots, as with our defaults 2000 / 0.03)."""
    omega = math.sqrt(DEFAULT_SERVOJ_GAIN)
    zeta = DEFAULT_SERVOJ_LOOKAHEAD_S * omega / 2.0
    if zeta >= 1.0:
        return 1.0
    damped = omega * math.sqrt(1.0 - zeta * zeta)
    dt, total = 1e-5, 0.0
    for k in range(200_000):  # 2 s: the response has decayed by e^-60
        t = (k + 0.5) * dt
        total += abs(math.exp(-zeta * omega * t) * math.sin(damped * t)) * dt
    return omega * omega / damped * total


def _velocities(poses: Sequence[Sequence[float]], h: float) -> tuple[list[list[float]], list[list[float]]]:
    """The TCP's linear and angular velocity (base frame) between samples ``h`` apart."""
    linear, angular = [], []
    for a, b in itertools.pairwise(poses):
        linear.append([(b[i] - a[i]) / h for i in range(3)])
        turn = pose_of_frame(
            compose(frame_of_pose((0, 0, 0, *b[3:])), inverse(frame_of_pose((0, 0, 0, *a[3:]))))
        )
        angular.append([v / h for v in turn[3:]])
    return linear, angular


def _peaks(velocities: list[list[float]], h: float) -> tuple[float, float, float]:
    """Largest |velocity|, |acceleration| and |jerk| (finite differences of the velocities)."""
    d2 = [[(b[i] - a[i]) / h for i in range(3)] for a, b in itertools.pairwise(velocities)]
    d3 = [[(b[i] - a[i]) / h for i in range(3)] for a, b in itertools.pairwise(d2)]
    return tuple(max(math.hypot(*v) for v in d) for d in (velocities, d2, d3))  # type: ignore[return-value]


def _check_limits(poses: Sequence[Sequence[float]], factor: float, slack: tuple[float, float, float]) -> None:
    """Every cycle's TCP speed, acceleration and jerk (linear, angular) within ``factor`` x the cell's
    default limits, plus ``slack`` (the finite differences' rounding: speed, acceleration, jerk)."""
    linear, angular = _velocities(poses, PERIOD)
    for what, peaks, limits in (
        ("linear", _peaks(linear, PERIOD), (SPEED, ACCELERATION, JERK)),
        ("angular", _peaks(angular, PERIOD), (ANGULAR_SPEED, ANGULAR_ACCELERATION, ANGULAR_JERK)),
    ):
        for name, peak, limit, extra in zip(
            ("speed", "acceleration", "jerk"), peaks, limits, slack, strict=True
        ):
            assert peak <= factor * limit + extra, f"{what} {name} {peak:.6g} over {factor:.4g} x {limit:g}"


def _line_distance(p: Sequence[float], a: Sequence[float], b: Sequence[float]) -> float:
    """Distance of point ``p`` from the segment a-b."""
    ab = [b[i] - a[i] for i in range(3)]
    ap = [p[i] - a[i] for i in range(3)]
    s = max(0.0, min(1.0, sum(ab[i] * ap[i] for i in range(3)) / sum(v * v for v in ab)))
    return math.dist(p[:3], [a[i] + s * ab[i] for i in range(3)])


async def test_a_linear_goal_on_the_fake_is_straight_within_the_limits_as_on_the_mock() -> None:
    """Reproduction: there were no linear goals (``goal/linear`` did not exist). Now one linear goal,
    the same request to the fake's `ur` robot and to the mock: both plan the same joint samples from
    the same rest pose; the plan's TCP keeps the cell's default Cartesian limits every cycle; the fake
    arm's own TCP, every controller cycle until the daemon's hold lets go, stays within 0.1 mm of the
    straight line and ends within 1e-5 m of the pose, and its speed, acceleration and jerk stay within
    the limits times what the servoj law's overshoot can add (``_servo_bound``)."""
    async with _pair() as pair:
        start = KIN.forward(HOME, TCP)
        end = pose_of_frame(compose(frame_of_pose(start), frame_of_pose((0.05, 0.1, -0.1, 0.0, 0.3, 0.2))))
        pair.record.on = True
        goals = await _both(pair, lambda r: r.keys.goal_linear, {"poses": [list(end)], "frame": "base"})
        results = {name: await goal.result(timeout=30.0) for name, goal in goals.items()}
        assert all(r["status"] == "succeeded" for r in results.values()), results
        await pair.fake.until(lambda: pair.record.done, cycles=5000)
        bodies = [body for body, _ in (pair.replies["alice"][0], pair.replies["bob"][0])]
        assert bodies[0] == bodies[1], "the same request bytes"

        plans = pair.plans["alice"][0], pair.plans["bob"][0]
        assert plans[0].sample_count == plans[1].sample_count
        samples = [[plan.positions(n) for n in range(plan.sample_count)] for plan in plans]
        assert samples[0] == samples[1], "the same joint targets every cycle on the mock and the fake"
        planned = [KIN.forward(q, TCP) for q in samples[0]]
        assert max(_line_distance(p, start, end) for p in planned) < 1e-9
        assert math.dist(planned[-1][:3], end[:3]) < 1e-9
        # IK noise (1e-10 rad, ~1e-10 m) in the k-th difference over 2 ms: 2^k 1e-10 / h^k
        _check_limits(planned, 1.0 + 1e-6, (1e-7, 1e-4, 0.1))

        poses = pair.record.poses
        assert len(poses) > plans[0].sample_count, "recorded the whole motion"
        answered = pair.record.answered
        assert len(answered) >= plans[0].sample_count, "a servo cycle recorded for every planned sample"
        assert all(answered), "every servo cycle ran after the daemon's frame for the one before"
        deviation = max(_line_distance(p, start, end) for p in poses)
        assert deviation < 1e-4, f"{deviation * 1e3:.4f} mm off the straight line"
        assert math.dist(poses[-1][:3], end[:3]) < 1e-5
        _check_limits(poses, _servo_bound(), (1e-7, 1e-4, 0.1))


async def test_a_pose_goal_on_the_fake_reaches_the_pose_as_on_the_mock() -> None:
    """Reproduction: ``goal/move`` took joint positions only. Now the same pose goal on the fake's `ur`
    robot and on the mock picks the same joint target (the accept reply's ``positions``), and the fake
    arm's TCP comes to rest at the pose (within what the stop's settling lets go: SETTLE_POSITION per
    joint on a 1.3 m arm)."""
    async with _pair() as pair:
        target = (0.3, -1.4, 1.4, -1.5, -1.6, 0.2)
        pose = KIN.forward(target, TCP)
        body = {"pose": list(pose), "frame": "base", "velocity_scale": 1.0, "acceleration_scale": 1.0}
        goals = await _both(pair, lambda r: r.keys.goal_move, body)
        results = {name: await goal.result(timeout=30.0) for name, goal in goals.items()}
        assert all(r["status"] == "succeeded" for r in results.values()), results
        (sent_a, reply_a), (sent_b, reply_b) = pair.replies["alice"][0], pair.replies["bob"][0]
        assert sent_a == sent_b
        assert reply_a["positions"] == reply_b["positions"]
        assert reply_a["positions"] == pytest.approx(target, abs=1e-9)
        await _settled(pair.fake)
        reached = pair.fake.arm.actual_tcp_pose()
        assert math.dist(reached[:3], pose[:3]) < 1.3 * 1.5 * SETTLE_POSITION
        assert pair.fake.arm.q == pytest.approx(target, abs=1.5 * SETTLE_POSITION)
