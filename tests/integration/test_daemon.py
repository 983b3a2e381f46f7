"""The daemon in-process, driven over Zenoh by the client API: services, streams, tf, supervision."""

from __future__ import annotations

import io
import json
from typing import Any

import pytest
import yourdfpy

from tests.integration.conftest import running_daemon
from urdaemon.backends.mock import MockBackend
from urdaemon.client import Client, RobotClient
from urdaemon.daemon import Daemon
from urdaemon.errors import GoalRejected
from urdaemon.model import Lifecycle, SafetyMode

pytestmark = pytest.mark.timeout(120)

HOME = [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]


async def _next_matching(client: Client, key: str, predicate: Any, limit: int = 500) -> dict[str, Any]:
    sub = client.subscribe(key, 100)
    try:
        for _ in range(limit):
            data = await sub.get_json(timeout=5.0)
            if predicate(data):
                return data
        raise AssertionError(f"no message on {key} matched within {limit} samples")
    finally:
        sub.close()


async def test_status_reports_a_healthy_mock_at_each_models_rate(cell: tuple[Daemon, Client]) -> None:
    _, client = cell
    alice, bob = await client.robot("alice"), await client.robot("bob")
    status_a = await alice.status()
    status_b = await bob.status()
    assert status_a["backend"] == "mock"
    assert status_a["lifecycle"] == "running"
    assert status_a["robot_mode"] == "RUNNING"
    assert status_a["safety_mode"] == "NORMAL"
    assert status_a["program_running"] is True
    assert status_a["ready"] is True
    assert status_a["rate_hz"] == 500.0
    assert status_b["rate_hz"] == 125.0, "a CB3 model runs at 125 Hz"
    assert sorted(r for _, r in await client.robots()) == ["alice", "bob"]


async def test_goal_on_a_robot_that_is_not_ready_is_rejected_with_the_reason(
    cell: tuple[Daemon, Client],
) -> None:
    daemon, client = cell
    alice = await client.robot("alice")
    state = daemon.runtimes[0].backend.state
    state.safety_mode = SafetyMode.PROTECTIVE_STOP
    with pytest.raises(GoalRejected, match="PROTECTIVE_STOP"):
        await alice.move(HOME, duration=1.0)
    state.safety_mode = SafetyMode.NORMAL
    state.lifecycle = Lifecycle.PAUSED
    with pytest.raises(GoalRejected, match="paused"):
        await alice.move(HOME, duration=1.0)
    state.lifecycle = Lifecycle.RUNNING
    goal = await alice.move(HOME, duration=0.5)
    assert (await goal.result(timeout=10))["status"] == "succeeded"


async def test_a_status_that_is_not_ready_always_says_why(cell: tuple[Daemon, Client]) -> None:
    """Reproduction (issue 13, found side by side under load): a status with ``ready: false`` went out
    with an empty ``reason`` when the backend had not worded its own yet (the program stopped between
    two packages). The status now falls back to the modes' reason and advice."""
    daemon, _ = cell
    runtime = daemon.runtimes[0]
    state = runtime.backend.state
    assert runtime.status_message()["reason"] == ""  # ready: nothing to explain
    state.safety_mode = SafetyMode.PROTECTIVE_STOP
    state.lifecycle_reason = ""
    status = runtime.status_message()
    assert status["ready"] is False
    assert "PROTECTIVE_STOP" in status["reason"]
    assert "unlock" in status["reason"]
    state.safety_mode = SafetyMode.NORMAL
    assert runtime.status_message()["reason"] == ""


async def test_speed_slider_at_half_makes_a_trajectory_take_twice_as_long(
    cell: tuple[Daemon, Client],
) -> None:
    daemon, client = cell
    alice = await client.robot("alice")
    state = daemon.runtimes[0].backend.state
    assert (await alice.set_speed_slider(0.5))["ok"] is True
    status = await _next_matching(client, alice.keys.status, lambda s: s["speed_scaling"] == 0.5)
    assert status["speed_slider"] == 0.5
    target = [0.3, -1.3, 1.3, -1.4, -1.5, 0.2]
    start_time = state.controller_time
    goal = await alice.send_trajectory([{"positions": target, "time_from_start": 1.0}])
    result = await goal.result(timeout=20)
    elapsed = state.controller_time - start_time
    assert result["status"] == "succeeded"
    assert 1.9 <= elapsed <= 2.4, f"a 1 s trajectory at 50 % took {elapsed:.3f} s of controller time"
    assert (await alice.set_speed_slider(1.0))["ok"] is True
    assert (await alice.set_speed_slider(1.5))["ok"] is False


async def test_io_and_payload_commands_are_acknowledged_and_reflected(cell: tuple[Daemon, Client]) -> None:
    _, client = cell
    alice = await client.robot("alice")
    assert (await alice.set_io("digital", 3, True))["ok"] is True
    assert (await alice.set_io("analog", 1, 0.25))["ok"] is True
    assert (await alice.set_io("tool", 1, True))["ok"] is True
    assert (await alice.set_payload(1.5, (0.0, 0.0, 0.05)))["ok"] is True
    io_state = await _next_matching(client, alice.keys.io, lambda m: m["payload"]["mass"] == 1.5)
    assert io_state["digital_out"][3] is True
    assert io_state["digital_out"][2] is False
    assert io_state["analog_out"][1] == 0.25
    assert io_state["tool_out"][1] is True
    assert io_state["payload"]["cog"] == [0.0, 0.0, 0.05]
    bad = await alice.set_io("digital", 9, True)
    assert bad["ok"] is False
    assert "pin 9" in bad["reason"]
    bad = await alice.set_io("analog", 0, 2.0)
    assert bad["ok"] is False
    assert "0..1" in bad["reason"]
    bad = await alice.set_payload(-1.0)
    assert bad["ok"] is False
    assert "mass" in bad["reason"]


async def test_position_stream_moves_the_robot_and_the_deadman_stops_it(cell: tuple[Daemon, Client]) -> None:
    daemon, client = cell
    alice = await client.robot("alice")
    state = daemon.runtimes[0].backend.state
    states = alice.joint_states(100_000)
    start = list(state.positions)
    target = [start[0] + 0.3, *start[1:]]
    await alice.ensure_lease()  # stream commands need the lease held first; they never wait for it
    # stream at ~100 Hz of joint-state time for 1 s: each command is sent after 5 new joint states
    for _ in range(100):
        alice.stream_positions(target)
        for _ in range(5):
            await states.get(timeout=5.0)
    assert state.positions[0] == pytest.approx(target[0], abs=0.01), "the stream reached its target"
    moving_target = [target[0] + 1.0, *target[1:]]
    for _ in range(10):
        alice.stream_positions(moving_target)
        for _ in range(5):
            await states.get(timeout=5.0)
    # no more commands: within stream_timeout (0.1 s) plus a braking time the robot must be at rest
    for _ in range(1500):  # 3 s of joint states at 500 Hz
        sample = await states.get_json(timeout=5.0)
        if all(v == 0.0 for v in sample["velocity"]):
            break
    else:
        raise AssertionError("the deadman did not stop the robot within 3 s")
    assert target[0] < state.positions[0] < moving_target[0], "stopped smoothly on the way, not at the target"
    status = await alice.status()
    assert status["active_goal"] is None


async def test_stream_commands_are_refused_while_a_goal_runs(cell: tuple[Daemon, Client]) -> None:
    _, client = cell
    alice = await client.robot("alice")
    await alice.ensure_lease()  # stream commands need the lease held first; they never wait for it
    events = client.subscribe(alice.keys.events, 100)  # from here on: no lease event to skip
    goal = await alice.move([0.5, *HOME[1:]], duration=2.0)
    alice.stream_velocities([0.1] * 6)
    event = await events.get_json(timeout=5.0)
    assert event["kind"] == "command_rejected"
    assert "busy" in event["reason"]
    alice.stream_positions([0.0, 0.0])  # wrong length: refused with a reason, not crashing anything
    event = await events.get_json(timeout=5.0)
    assert event["kind"] == "command_rejected"
    assert (await goal.result(timeout=10))["status"] == "succeeded"


async def test_cancel_ends_the_goal_canceled_and_only_once(cell: tuple[Daemon, Client]) -> None:
    _, client = cell
    alice = await client.robot("alice")
    results = client.subscribe(f"{alice.keys.base}/goal/*/result", 100)
    goal = await alice.move([0.8, *HOME[1:]], duration=3.0)
    feedback = goal.feedback()
    await feedback.__anext__()
    reply = await alice.cancel()
    assert reply["canceled"] is True
    assert reply["goal_id"] == goal.goal_id
    result = await goal.result(timeout=10)
    assert result["status"] == "canceled"
    published = await results.get_json(timeout=5.0)
    assert published["goal_id"] == goal.goal_id
    again = await alice.cancel(goal.goal_id)
    assert again["canceled"] is False
    follow = await alice.move(HOME)
    assert (await follow.result(timeout=20))["status"] == "succeeded"
    ids = [published["goal_id"]]
    for _ in range(5):
        try:
            ids.append((await results.get_json(timeout=0.5))["goal_id"])
        except Exception:
            break
    assert ids.count(goal.goal_id) == 1, "the canceled goal has exactly one result"


async def test_tf_covers_every_link_of_the_cell_in_the_world_frame(cell: tuple[Daemon, Client]) -> None:
    daemon, client = cell
    tf = await _next_matching(client, f"{daemon.cell.cell}/tf", lambda m: True)
    links = tf["links"]
    assert tf["frame"] == "world"
    for prefix in ("alice_", "bob_"):
        for link in ("base_link", "shoulder_link", "wrist_3_link", "flange", "tool0", "base"):
            assert f"{prefix}{link}" in links
    assert links["alice_base_link"][:3] == pytest.approx([0.5, 0.0, 0.0])
    assert links["bob_base_link"][:3] == pytest.approx([-0.5, 0.0, 0.0])


async def test_robot_description_answers_the_cell_urdf(cell: tuple[Daemon, Client]) -> None:
    daemon, client = cell
    urdf_text = await client.robot_description(daemon.cell.cell)
    urdf = yourdfpy.URDF.load(io.StringIO(urdf_text), build_scene_graph=True, load_meshes=False)
    assert len(urdf.actuated_joint_names) == 12
    assert "alice_shoulder_pan_joint" in urdf.actuated_joint_names
    assert "bob_wrist_3_joint" in urdf.actuated_joint_names


async def test_a_failing_backend_aborts_its_goal_restarts_and_the_other_robot_never_notices(
    cell: tuple[Daemon, Client],
) -> None:
    daemon, client = cell
    alice, bob = await client.robot("alice"), await client.robot("bob")
    alice_rt, bob_rt = daemon.runtimes
    backend = alice_rt.backend
    assert isinstance(backend, MockBackend)
    original_step = backend.step
    calls = {"n": 0}

    def failing_step() -> None:
        calls["n"] += 1
        if calls["n"] == 50:
            raise OSError("simulated link loss")
        original_step()

    statuses = client.subscribe(alice.keys.status, 1000)
    backend.step = failing_step  # type: ignore[method-assign]
    bob_goal = await bob.move([0.3, *HOME[1:]], duration=1.5)
    alice_goal = await alice.move([0.5, *HOME[1:]], duration=2.0)
    result = await alice_goal.result(timeout=10)
    assert result["status"] == "aborted"
    assert "simulated link loss" in result["reason"]
    assert (await bob_goal.result(timeout=10))["status"] == "succeeded"
    assert bob_rt.status_message()["restarts"] == 0
    seen = []
    for _ in range(200):
        status = await statuses.get_json(timeout=5.0)
        seen.append(status["lifecycle"])
        if status["lifecycle"] == "disconnected":
            assert "simulated link loss" in status["reason"]
            assert status["ready"] is False
        if status["restarts"] >= 1 and status["ready"]:
            break
    assert "disconnected" in seen, seen
    assert status["lifecycle"] == "running"
    retry = await alice.move(HOME, duration=1.0)
    assert (await retry.result(timeout=10))["status"] == "succeeded"


async def test_goal_result_can_be_asked_for_after_the_goal_ended(cell: tuple[Daemon, Client]) -> None:
    _, client = cell
    alice = await client.robot("alice")
    goal = await alice.move([0.1, *HOME[1:]], duration=1.0)
    assert (await goal.result(timeout=10))["status"] == "succeeded"
    replies = await client.query(alice.keys.goal_result(goal.goal_id))
    assert len(replies) == 1
    assert json.loads(replies[0])["status"] == "succeeded"
    assert await client.query(alice.keys.goal_result("alice-none-1"), timeout=1.0) == []


async def test_servo_arm_publishes_pca9685_channels_that_follow_the_command() -> None:
    text = (ROOT_CONFIGS / "servo_arm.yaml").read_text()
    async with running_daemon(text) as (daemon, client):
        arm: RobotClient = await client.robot("arm")
        key = arm.keys.servo_command
        first = await _next_matching(client, key, lambda m: True)
        assert len(first["channels"]) == 16
        assert first["pwm_frequency_hz"] == 50.0
        # at zero angles: mid pulse 1500 µs → round(1500 × 50 × 4096 / 1e6) = 307
        assert first["channels"][0] == 307
        assert first["channels"][4:] == [0] * 12
        goal = await arm.move([1.0, 0.0, 0.0, 0.0], duration=1.0)
        assert (await goal.result(timeout=10))["status"] == "succeeded"
        moved = await _next_matching(client, key, lambda m: m["channels"][0] != 307)
        # base_yaw at 1.0 rad: pulse = 500 + (1.0 + 1.5708) / 3.1416 × 2000 ≈ 2136.6 µs → 437.6 → 438
        assert moved["channels"][0] == 438
        assert daemon.runtimes[0].backend.state.positions[0] == pytest.approx(1.0, abs=0.01)


ROOT_CONFIGS = __import__("pathlib").Path(__file__).resolve().parents[2] / "configs"


async def test_a_dense_trajectory_is_planned_in_slices_and_succeeds_while_bob_moves(
    cell: tuple[Daemon, Client],
) -> None:
    import math

    daemon, client = cell
    alice, bob = await client.robot("alice"), await client.robot("bob")
    home = daemon.runtimes[0].backend.state.positions[:]
    w, amp, dt = 1.0, 0.2, 0.01
    points = [
        {
            "positions": [home[j] + amp * math.sin(w * t) for j in range(6)],
            "velocities": [amp * w * math.cos(w * t)] * 6,
            "accelerations": [-amp * w * w * math.sin(w * t)] * 6,
            "time_from_start": 0.5 + t,
        }
        for t in (dt * k for k in range(300))
    ]
    points.append({"positions": points[-1]["positions"], "time_from_start": 0.5 + 300 * dt + 1.0})
    bob_goal = await bob.move([0.4, *HOME[1:]], duration=2.0)
    goal = await alice.send_trajectory(points)
    assert goal.duration == pytest.approx(points[-1]["time_from_start"], abs=0.01)
    result = await goal.result(timeout=30)
    assert result["status"] == "succeeded", result
    assert (await bob_goal.result(timeout=30))["status"] == "succeeded"


async def test_tcp_pose_is_computed_only_while_someone_subscribes(cell: tuple[Daemon, Client]) -> None:
    """Forward kinematics and encoding are skipped for a stream nobody receives (issue 5)."""
    daemon, client = cell
    runtime = next(rt for rt in daemon.runtimes if rt.robot.name == "alice")
    alice = await client.robot("alice")
    assert not runtime._pose_wanted.active  # nobody has subscribed to tcp_pose yet
    pose = await _next_matching(client, alice.keys.tcp_pose, lambda data: True)
    assert (pose["robot"], pose["frame"], pose["child"]) == ("alice", "alice_base", "alice_tool0")
    assert (len(pose["position"]), len(pose["orientation"])) == (3, 4)


async def _first_joint_state(robot: RobotClient) -> dict[str, Any]:
    states = robot.joint_states(10)
    try:
        state: dict[str, Any] = await states.get_json(timeout=5.0)
    finally:
        states.close()
    return state


LOW_LATENCY_CELL = """
cell: fastcell
zenoh: {low_latency: true}
robots:
  - name: alice
    model: ur10e
    backend: mock
"""


async def test_a_low_latency_daemon_serves_low_latency_and_default_clients() -> None:
    """zenoh.low_latency: true changes the transport, not who may connect (issue 5)."""
    async with running_daemon(LOW_LATENCY_CELL) as (daemon, default_client):
        endpoint = daemon.listen_endpoints[0]
        async with await Client.connect(endpoint, low_latency=True) as fast_client:
            for client in (default_client, fast_client):
                alice = await client.robot("alice")
                state = await _first_joint_state(alice)
                assert state["robot"] == "alice"
                assert len(state["position"]) == 6
                assert (await alice.status())["ready"] is True


async def test_a_daemon_listening_on_a_unix_socket_serves_a_client_there(tmp_path: Any) -> None:
    """A subscriber on the same machine can use a Unix socket instead of loopback TCP (issue 5:
    less CPU per published sample, docs/performance.md)."""
    endpoint = f"unixsock-stream/{tmp_path}/urdaemon.sock"
    async with running_daemon(LOW_LATENCY_CELL.replace("{low_latency: true}", "{}"), endpoint=endpoint) as (
        daemon,
        client,
    ):
        assert daemon.listen_endpoints == (endpoint,)
        alice = await client.robot("alice")
        state = await _first_joint_state(alice)
        assert state["robot"] == "alice"
        assert len(state["position"]) == 6
        goal = await alice.move([0.1, *HOME[1:]], duration=2.0)
        assert (await goal.result(timeout=30))["status"] == "succeeded"


TCP_CELL = """
cell: tcpcell
robots:
  - name: alice
    model: ur10e
    backend: mock
    tcp: [0.01, -0.02, 0.15, 0.1, -0.2, 0.3]
    mock: {initial_positions: [0.3, -1.2, 1.4, -1.7, -1.5, 0.4]}
"""


async def test_tcp_pose_applies_the_cell_files_tcp_offset() -> None:
    """tcp_pose is the flange pose composed with the cell file's ``tcp``, named ``<robot>_tcp`` (issue 17).

    Checked against the IK module's forward kinematics with the same TCP (URScript ``get_forward_kin``).
    """
    from urdaemon.description import load_ur_model
    from urdaemon.description.frames import frame_of_pose
    from urdaemon.description.ik import UrKinematics

    tcp = (0.01, -0.02, 0.15, 0.1, -0.2, 0.3)
    q = (0.3, -1.2, 1.4, -1.7, -1.5, 0.4)
    expected = frame_of_pose(UrKinematics(load_ur_model("ur10e")).forward(q, tcp))
    async with running_daemon(TCP_CELL) as (_daemon, client):
        alice = await client.robot("alice")
        pose = await _next_matching(client, alice.keys.tcp_pose, lambda data: True)
    assert (pose["robot"], pose["child"]) == ("alice", "alice_tcp")
    assert pose["position"] == pytest.approx(expected[9:], abs=1e-9)
    x, y, z, w = pose["orientation"]
    rotation = (
        1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w),
        2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
        2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y),
    )  # fmt: skip
    assert rotation == pytest.approx(expected[:9], abs=1e-9)
