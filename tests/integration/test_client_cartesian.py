"""The client's and the CLI's Cartesian commands (issue 17): ``move_pose``, ``move_linear``, ``twist``,
``set_tcp``, ``urdaemon move --pose [--linear]`` and examples/cartesian.py.

First what the client sends, against a stand-in daemon (raw Zenoh queryables that record every
request: the messages of docs/keys.md exactly, optional fields left out); then against one daemon
per module (the mock backend, in the test's loop): the goals reach their poses on tcp_pose, a twist
moves the TCP and stops, set_tcp changes tcp_pose, the CLI and the example do what they say.

Reproduction on the code before issue 17: ``RobotClient`` had none of these methods (AttributeError)
and ``urdaemon move`` had no ``--pose`` (exit 2, usage error), so every test here fails.
"""

from __future__ import annotations

import asyncio
import json
import math
from collections.abc import AsyncIterator, Sequence
from typing import Any

import pytest
import pytest_asyncio
import zenoh

from tests.helpers import free_tcp_port, in_thread, run_cli_in_thread, run_script
from tests.integration.conftest import ROOT, running_daemon
from urdaemon.client import Client, RobotClient
from urdaemon.daemon import Daemon
from urdaemon.errors import GoalRejected
from urdaemon.publish.session_config import zenoh_config
from urdaemon.teleop_keys import rotation_vector

pytestmark = pytest.mark.timeout(120)

CELL = """
cell: cartcell
robots:
  - name: alice
    model: ur10e
    backend: mock
    pose: {xyz: [0.5, 0.0, 0.0]}
    mock: {initial_positions: [0.3, -1.8, 1.6, -1.4, -1.5708, 0.2]}
    motion: {stream_timeout: 0.1}
"""
"""alice on the world link half a metre along +x (base = base_link turned pi about z), started away
from every singularity (elbow bent, wrist not aligned)."""
WAIT_S = 20.0
"""Bound of every wait for a message (a busy machine is slow, never this slow)."""
POSITION_TOL_M = 1e-5
ANGLE_TOL_RAD = 1e-5


# ---- what goes on the wire ------------------------------------------------------------------------


class _StandIn:
    """A stand-in daemon serving robot ``wirecell/alice``: it records each goal, service request and
    twist it receives, accepts every goal and answers set_tcp with ``set_tcp_reply``; no lease
    queryable (a client then sends without a token, as to a daemon older than leases)."""

    def __init__(self, session: Any) -> None:
        self.requests: list[tuple[str, dict[str, Any]]] = []
        self.twists: asyncio.Queue[dict[str, Any]] = asyncio.Queue()
        self.set_tcp_reply: dict[str, Any] = {"ok": True}
        loop = asyncio.get_running_loop()
        base = "wirecell/alice"
        self._held = [
            session.liveliness().declare_token(f"{base}/alive"),
            session.declare_queryable(f"{base}/goal/move", self._on_goal),
            session.declare_queryable(f"{base}/goal/linear", self._on_goal),
            session.declare_queryable(f"{base}/service/set_tcp", self._on_set_tcp),
            session.declare_subscriber(
                f"{base}/command/twist",
                lambda sample: loop.call_soon_threadsafe(
                    self.twists.put_nowait, json.loads(sample.payload.to_bytes())
                ),
            ),
        ]

    def _record(self, query: Any) -> None:
        payload = query.payload
        self.requests.append((str(query.key_expr), json.loads(payload.to_bytes()) if payload else {}))

    def _on_goal(self, query: Any) -> None:
        self._record(query)
        reply = {"accepted": True, "goal_id": f"alice-{len(self.requests)}", "duration": 1.0}
        query.reply(str(query.key_expr), json.dumps(reply).encode())

    def _on_set_tcp(self, query: Any) -> None:
        self._record(query)
        query.reply(str(query.key_expr), json.dumps(self.set_tcp_reply).encode())

    def close(self) -> None:
        for item in self._held:
            item.undeclare()


@pytest_asyncio.fixture
async def stand_in() -> AsyncIterator[tuple[_StandIn, RobotClient]]:
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    loop = asyncio.get_running_loop()
    server = await loop.run_in_executor(None, zenoh.open, zenoh_config("peer", [endpoint], []))
    served = _StandIn(server)
    try:
        async with await Client.connect(endpoint) as client:
            yield served, await client.robot("alice", timeout=10.0)
    finally:
        served.close()
        await loop.run_in_executor(None, server.close)


async def test_pose_and_linear_goals_send_the_documented_messages(
    stand_in: tuple[_StandIn, RobotClient],
) -> None:
    served, alice = stand_in
    pose = [0.4, -0.2, 0.5, 3.1, 0.1, 0.0]
    await alice.move_pose(pose)
    await alice.move_pose(
        pose,
        frame="world",
        configuration={"elbow": "up"},
        duration=2.5,
        velocity_scale=0.5,
        acceleration_scale=0.25,
        tolerances={"goal_position": 0.01},
        preempt=True,
    )
    await alice.move_linear(pose)
    await alice.move_linear([pose, [0.4, -0.1, 0.5, 3.1, 0.1, 0.0]], blend_radii=[0.01], speed=0.1)
    await alice.move_linear([pose], frame="world", acceleration=0.5, jerk=5.0, angular_speed=0.5)
    await alice.move_linear((tuple(pose),), angular_acceleration=2.0, angular_jerk=20.0)  # any sequences
    move, linear = "wirecell/alice/goal/move", "wirecell/alice/goal/linear"
    common = {"v": 1, "pose": pose}
    scales = {"velocity_scale": 1.0, "acceleration_scale": 1.0}
    assert served.requests == [
        (move, {**common, "frame": "base", **scales, "preempt": False}),
        (move, {**common, "frame": "world", "velocity_scale": 0.5, "acceleration_scale": 0.25,
                "preempt": True, "configuration": {"elbow": "up"}, "duration": 2.5,
                "tolerances": {"goal_position": 0.01}}),
        (linear, {"v": 1, "poses": [pose], "frame": "base"}),
        (linear, {"v": 1, "poses": [pose, [0.4, -0.1, 0.5, 3.1, 0.1, 0.0]], "frame": "base",
                  "blend_radii": [0.01], "speed": 0.1}),
        (linear, {"v": 1, "poses": [pose], "frame": "world", "acceleration": 0.5, "jerk": 5.0,
                  "angular_speed": 0.5}),
        (linear, {"v": 1, "poses": [pose], "frame": "base", "angular_acceleration": 2.0,
                  "angular_jerk": 20.0}),
    ]  # fmt: skip


async def test_twist_and_set_tcp_send_the_documented_messages_and_a_refusal_raises(
    stand_in: tuple[_StandIn, RobotClient],
) -> None:
    served, alice = stand_in
    await alice.ensure_lease()  # a stream never waits for the lease (none served here: no token)
    alice.twist([0.1, 0.0, 0.0], (0.0, 0.0, 0.2))
    alice.twist((0.0, 0.0, 0.0), [0.0, 0.0, 0.0], frame="tool")
    received = [await asyncio.wait_for(served.twists.get(), WAIT_S) for _ in range(2)]
    assert received == [
        {"v": 1, "linear": [0.1, 0.0, 0.0], "angular": [0.0, 0.0, 0.2], "frame": "base"},
        {"v": 1, "linear": [0.0, 0.0, 0.0], "angular": [0.0, 0.0, 0.0], "frame": "tool"},
    ]
    await alice.set_tcp([0.0, 0.0, 0.1, 0.0, 0.0, 0.0])
    served.set_tcp_reply = {"ok": False, "reason": "set_tcp: the robot is moving"}
    with pytest.raises(GoalRejected, match="set_tcp: the robot is moving"):
        await alice.set_tcp((0.0, 0.0, 0.2, 0.0, 0.0, 0.0))
    assert served.requests == [
        ("wirecell/alice/service/set_tcp", {"v": 1, "pose": [0.0, 0.0, 0.1, 0.0, 0.0, 0.0]}),
        ("wirecell/alice/service/set_tcp", {"v": 1, "pose": [0.0, 0.0, 0.2, 0.0, 0.0, 0.0]}),
    ]


# ---- against a daemon -----------------------------------------------------------------------------


@pytest_asyncio.fixture(loop_scope="module", scope="module")
async def served() -> AsyncIterator[tuple[Daemon, RobotClient]]:
    """One daemon for the module's end-to-end tests, and alice's client (holding her lease)."""
    async with running_daemon(CELL) as (daemon, client):
        alice = await client.robot("alice")
        await alice.ensure_lease()
        yield daemon, alice


async def _tcp_pose(alice: RobotClient) -> list[float]:
    """alice's next tcp_pose as x, y, z, rx, ry, rz (base frame)."""
    sub = alice.client.subscribe(alice.keys.tcp_pose, 10)
    try:
        message = await sub.get_json(WAIT_S)
    finally:
        alice.client.unsubscribe(sub)
    return [*message["position"], *rotation_vector(message["orientation"])]


def _close(a: Sequence[float], b: Sequence[float], position: float, angle: float) -> bool:
    if math.dist(a[:3], b[:3]) > position:
        return False
    return _rotation_angle(a[3:], b[3:]) <= angle


def _rotation_angle(a: Sequence[float], b: Sequence[float]) -> float:
    """The angle between two orientations given as rotation vectors."""
    qa, qb = _quaternion(a), _quaternion(b)
    dot = abs(sum(x * y for x, y in zip(qa, qb, strict=True)))
    return 2.0 * math.acos(min(1.0, dot))


def _quaternion(r: Sequence[float]) -> tuple[float, float, float, float]:
    angle = math.sqrt(sum(v * v for v in r))
    if angle < 1e-15:
        return (0.0, 0.0, 0.0, 1.0)
    s = math.sin(angle / 2) / angle
    return (r[0] * s, r[1] * s, r[2] * s, math.cos(angle / 2))


def _shifted(pose: Sequence[float], dx: float = 0.0, dy: float = 0.0, dz: float = 0.0) -> list[float]:
    return [pose[0] + dx, pose[1] + dy, pose[2] + dz, *pose[3:]]


@pytest.mark.asyncio(loop_scope="module")
async def test_move_pose_reaches_the_pose_on_tcp_pose(served: tuple[Daemon, RobotClient]) -> None:
    _, alice = served
    target = _shifted(await _tcp_pose(alice), dx=0.05, dz=-0.03)
    goal = await alice.move_pose(target)
    assert (await goal.result(timeout=WAIT_S))["status"] == "succeeded"
    reached = await _tcp_pose(alice)
    assert _close(reached, target, POSITION_TOL_M, ANGLE_TOL_RAD), (reached, target)


@pytest.mark.asyncio(loop_scope="module")
async def test_move_linear_through_two_poses_reaches_the_last(served: tuple[Daemon, RobotClient]) -> None:
    _, alice = served
    start = await _tcp_pose(alice)
    path = [_shifted(start, dy=0.04), _shifted(start, dy=0.04, dz=0.03)]
    goal = await alice.move_linear(path, speed=0.2)
    assert (await goal.result(timeout=WAIT_S))["status"] == "succeeded"
    reached = await _tcp_pose(alice)
    assert _close(reached, path[-1], POSITION_TOL_M, ANGLE_TOL_RAD), (reached, path[-1])


@pytest.mark.asyncio(loop_scope="module")
async def test_an_unreachable_pose_is_rejected_naming_it(served: tuple[Daemon, RobotClient]) -> None:
    _, alice = served
    with pytest.raises(GoalRejected, match="out of reach"):
        await alice.move_pose([3.0, 0.0, 0.5, 0.0, 3.14, 0.0])


@pytest.mark.asyncio(loop_scope="module")
async def test_twists_move_the_tcp_and_it_stops_when_they_stop(served: tuple[Daemon, RobotClient]) -> None:
    daemon, alice = served
    start = await _tcp_pose(alice)
    states = alice.joint_states(10_000)
    try:
        for _ in range(25):  # one twist every 5 joint states (10 ms at 500 Hz): within the deadman
            alice.twist([0.0, 0.0, 0.05], [0.0, 0.0, 0.0])
            for _ in range(5):
                await states.get(timeout=WAIT_S)
        for _ in range(5000):  # at most 10 s of joint states until every joint rests
            sample = json.loads((await states.get(timeout=WAIT_S))[1])
            if all(v == 0.0 for v in sample["velocity"]):
                break
        else:
            raise AssertionError("alice still moves 10 s after the last twist")
    finally:
        alice.client.unsubscribe(states)
    moved = await _tcp_pose(alice)
    assert moved[2] - start[2] > 0.002, "the twist raised the TCP"
    assert math.dist(moved[:2], start[:2]) < 0.1 * (moved[2] - start[2]), "along z, not across"
    assert daemon.runtimes[0].controller.active_goal_id is None


@pytest.mark.asyncio(loop_scope="module")
async def test_set_tcp_moves_tcp_pose_by_the_offset(served: tuple[Daemon, RobotClient]) -> None:
    _, alice = served
    before = await _tcp_pose(alice)
    await alice.set_tcp([0.0, 0.0, 0.1, 0.0, 0.0, 0.0])
    try:
        for _ in range(100):  # the next tcp_pose may be one composed before the new offset
            after = await _tcp_pose(alice)
            if math.dist(after[:3], before[:3]) > 0.05:
                break
        assert math.dist(after[:3], before[:3]) == pytest.approx(0.1, abs=1e-6), (before, after)
    finally:
        await alice.set_tcp([0.0] * 6)


@pytest.mark.asyncio(loop_scope="module")
async def test_cli_move_pose_and_linear(served: tuple[Daemon, RobotClient]) -> None:
    daemon, alice = served
    endpoint = daemon.listen_endpoints[0]
    start = await _tcp_pose(alice)
    await alice.release()  # the CLI takes the lease; the module's client takes it back after
    try:
        target = _shifted(start, dx=-0.03)
        text = ",".join(repr(v) for v in target)
        run = await run_cli_in_thread("move", "alice", "--pose", text, "--connect", endpoint, timeout=60)
        assert run.code == 0, run
        assert json.loads(run.stdout)["status"] == "succeeded"
        assert _close(await _tcp_pose(alice), target, POSITION_TOL_M, ANGLE_TOL_RAD)
        path = [_shifted(target, dz=0.02), _shifted(target, dy=-0.02, dz=0.02)]
        words = [w for pose in path for w in ("--pose", ",".join(repr(v) for v in pose))]
        run = await run_cli_in_thread(
            "move", "alice", *words, "--linear", "--speed", "0.1", "--connect", endpoint, timeout=60
        )
        assert run.code == 0, run
        assert json.loads(run.stdout)["status"] == "succeeded"
        assert _close(await _tcp_pose(alice), path[-1], POSITION_TOL_M, ANGLE_TOL_RAD)
        run = await run_cli_in_thread(
            "move", "alice", "--pose", "3,0,0.5,0,3.14,0", "--connect", endpoint, timeout=60
        )
        assert run.code == 1, run
        assert "rejected: " in run.stderr
        assert "out of reach" in run.stderr
    finally:
        await alice.ensure_lease()


@pytest.mark.parametrize(
    ("words", "problem"),
    [
        (["--pose", "1,2,3"], "--pose needs 6 numbers"),
        (["--pose", "1,2,3,4,5,x"], "--pose must be comma-separated numbers"),
        (["--pose", "0,0,0,0,0,0", "--pose", "0,0,0,0,0,0"], "add --linear"),
        (["--joints", "0,0,0,0,0,0", "--linear"], "--linear moves to --pose"),
        (["--pose", "0,0,0,0,0,0", "--linear", "--duration", "2"], "--linear takes --speed"),
        (["--pose", "0,0,0,0,0,0", "--speed", "0.1"], "--speed (m/s) is for --linear"),
        (["--pose", "0,0,0,0,0,0", "--linear", "--speed", "-1"], "--speed must be"),
        (["--pose", "-0.1,0,0.5,0,0,nan"], "--pose must be finite numbers"),
    ],
)
async def test_cli_move_refuses_bad_pose_arguments_before_connecting(words: list[str], problem: str) -> None:
    nobody = f"tcp/127.0.0.1:{free_tcp_port()}"
    run = await run_cli_in_thread("move", "alice", *words, "--connect", nobody, timeout=30)
    assert run.code == 2, run
    assert problem in run.stderr, run.stderr


async def test_cli_move_takes_joints_or_pose_not_both() -> None:
    run = await run_cli_in_thread("move", "alice", "--joints", "0,0,0,0,0,0", "--pose", "0,0,0,0,0,0")
    assert run.code == 2, run
    assert "not allowed with argument" in run.stderr


@pytest.mark.asyncio(loop_scope="module")
async def test_the_cartesian_example_runs_against_the_demo_cell() -> None:
    text = (ROOT / "configs" / "dual_robot_mock.yaml").read_text()
    async with running_daemon(text) as (daemon, _):
        endpoint = daemon.listen_endpoints[0]
        path = ROOT / "examples" / "cartesian.py"
        run = await in_thread(lambda: run_script(path, "--connect", endpoint), "cartesian.py", 90.0)
        assert run.code == 0, run
        for line in ("pose move: succeeded", "linear move: succeeded", "jogged", "at rest"):
            assert line in run.stdout, run.stdout
