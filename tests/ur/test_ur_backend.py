"""The `ur` backend through the whole daemon, against the fake controller."""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from tests.helpers import fake_address, free_tcp_port, run_cli_in_thread
from tests.integration.conftest import running_daemon
from urdaemon.client import Client
from urdaemon.control.stopping import SETTLE_POSITION
from urdaemon.description.urmodels import load_ur_model
from urdaemon.errors import GoalRejected
from urdaemon.fakeur.controller import FakeController
from urdaemon.model import RobotMode

pytestmark = pytest.mark.timeout(90)

HOME = [0.0, -1.57, 1.57, -1.57, -1.57, 0.0]
E_SERIES = (5, 15, 0, 0)
CB3 = (3, 15, 7, 0)
SERIES = pytest.mark.parametrize(
    ("series", "version"), [("e", E_SERIES), ("cb3", CB3)], ids=["e-series", "cb3"]
)
"""The tests marked with it run our control script rendered for each series, in the fake's interpreter."""


def _model(name: str, series: str) -> str:
    """``ur10e`` on e-Series, ``ur10`` on CB3."""
    return name if series == "e" else name.removesuffix("e")


def _cell(address: str, *, headless: bool = True, startup: bool = True, model: str = "ur10e") -> str:
    ports = [free_tcp_port() for _ in range(4)]
    return f"""
cell: urcell
robots:
  - name: alice
    model: {model}
    backend: ur
    address: {address}
    headless: {str(headless).lower()}
    ports:
      {{reverse: {ports[0]}, script_sender: {ports[1]}, trajectory: {ports[2]}, script_command: {ports[3]}}}
    ur: {{startup: {str(startup).lower()}, listen_address: 127.0.0.1}}
"""


async def _until(client: Client, key: str, predicate: Any, limit: int = 400) -> dict[str, Any]:
    sub = client.subscribe(key, 100)
    try:
        for _ in range(limit):
            message = await sub.get_json(timeout=10.0)
            if predicate(message):
                return message
        raise AssertionError(f"no message on {key} matched")
    finally:
        client.unsubscribe(sub)


@SERIES
async def test_startup_from_powered_off_headless_then_a_move_succeeds(
    series: str, version: tuple[int, int, int, int]
) -> None:
    model = _model("ur10e", series)
    fake = FakeController(model, address=fake_address(), initial_positions=HOME, controller_version=version)
    await fake.start()
    try:
        assert fake.arm.robot_mode is RobotMode.POWER_OFF
        async with running_daemon(_cell(fake.address, model=model)) as (daemon, client):
            alice = await client.robot("alice")
            status = await _until(client, alice.keys.status, lambda s: s["ready"])
            assert status["backend"] == "ur"
            assert status["robot_mode"] == "RUNNING"
            assert status["program_running"] is True
            assert status["rate_hz"] == (500.0 if series == "e" else 125.0)
            target = [0.3, -1.4, 1.4, -1.5, -1.6, 0.2]
            goal = await alice.move(target, duration=2.0)
            result = await goal.result(timeout=20)
            assert result["status"] == "succeeded", result
            assert fake.arm.q == pytest.approx(target, abs=0.01)
            # services go through RTDE inputs and the script command socket
            assert (await alice.set_speed_slider(0.5))["ok"] is True
            assert (await alice.set_io("digital", 4, True))["ok"] is True
            assert (await alice.set_payload(1.25, (0.0, 0.0, 0.05)))["ok"] is True
            io_state = await _until(
                client, alice.keys.io, lambda m: m["digital_out"][4] and m["payload"]["mass"] == 1.25
            )
            assert io_state["digital_out"][4] is True
            assert fake.arm.speed_slider == pytest.approx(0.5)
            assert fake.arm.payload_mass == pytest.approx(1.25)
            assert daemon.runtimes[0].backend.statistics().cycles > (500 if series == "e" else 125)
    finally:
        await fake.close()


async def test_urcap_mode_plays_the_program_which_fetches_the_script() -> None:
    address = fake_address()
    text = _cell(address, headless=False)
    script_sender = int(text.split("script_sender: ")[1].split(",")[0])
    fake = FakeController(
        "ur10e", address=address, initial_positions=HOME, urcap=("127.0.0.1", script_sender)
    )
    await fake.start()
    try:
        async with running_daemon(text) as (_, client):
            alice = await client.robot("alice")
            await _until(client, alice.keys.status, lambda s: s["ready"])
            goal = await alice.move([0.2, *HOME[1:]], duration=1.0)
            assert (await goal.result(timeout=20))["status"] == "succeeded"
            assert fake.arm.q[0] == pytest.approx(0.2, abs=0.01)
    finally:
        await fake.close()


async def test_dashboard_and_program_services_and_robot_messages_over_zenoh() -> None:
    address = fake_address()
    nominal = load_ur_model("ur10e").dh
    calibrated = type(nominal)(
        theta=nominal.theta, a=nominal.a, d=tuple(v + 1e-4 for v in nominal.d), alpha=nominal.alpha
    )
    fake = FakeController("ur10e", address=address, initial_positions=HOME, dh=calibrated)
    await fake.start()
    try:
        async with running_daemon(_cell(address, startup=False)) as (daemon, client):
            alice = await client.robot("alice")
            events = client.subscribe(alice.keys.events, 100)
            assert await alice.dashboard("robotmode") == {"v": 1, "ok": True, "reply": "Robotmode: POWER_OFF"}
            # a command the controller refuses is answered, not ok (nothing is loaded to play)
            assert (await alice.dashboard("play"))["ok"] is False
            assert (await alice.startup())["ok"] is True
            await _until(client, alice.keys.status, lambda s: s["ready"])
            assert (await alice.set_tool_voltage(24))["ok"] is True
            assert (await alice.set_tool_voltage(5))["ok"] is False
            assert (await alice.zero_ft_sensor())["ok"] is True
            await _until(client, alice.keys.io, lambda m: m["tool_voltage"] == 24)
            assert fake.arm.io.tool_voltage == 24
            # the fake's DH differs from the nominal one the cell expects: a mismatch is published
            assert daemon.runtimes[0].backend.calibration_ok is False  # type: ignore[attr-defined]
            endpoint = daemon.listen_endpoints[0]
            await alice.release()  # the CLI is another client: it takes the command lease for its call
            run = await run_cli_in_thread("dashboard", "alice", "robotmode", "--connect", endpoint)
            assert run.code == 0, run.stderr
            assert run.stdout.strip() == "Robotmode: RUNNING"
            events.close()
    finally:
        await fake.close()


async def test_a_calibration_mismatch_is_published_on_the_events_key() -> None:
    address = fake_address()
    nominal = load_ur_model("ur10e").dh
    calibrated = type(nominal)(
        theta=nominal.theta, a=nominal.a, d=tuple(v + 2e-4 for v in nominal.d), alpha=nominal.alpha
    )
    fake = FakeController("ur10e", address=address, initial_positions=HOME, dh=calibrated)
    await fake.start()
    try:
        text = _cell(address, startup=False)
        async with running_daemon(text) as (_, client):
            alice = await client.robot("alice")
            events = client.subscribe(alice.keys.events, 100)
            # reconnect so that the check runs again while we listen: drop the RTDE link
            fake.drop("rtde")
            event = await _next_kind(events, "calibration_mismatch")
            assert "kinematics hash" in event["text"]
            assert "urdaemon calibration" in event["text"]
    finally:
        await fake.close()


async def _next_kind(sub: Any, kind: str) -> dict[str, Any]:
    for _ in range(100):
        event: dict[str, Any] = await sub.get_json(timeout=20.0)
        if event["kind"] == kind:
            return event
    raise AssertionError(f"no {kind} event")


def _two_robot_cell(alice: str, bob: str, series: str = "e") -> str:
    ports = [free_tcp_port() for _ in range(8)]
    robots = []
    models = (_model("ur10e", series), _model("ur3e", series))
    for name, model, address, p in (
        ("alice", models[0], alice, ports[:4]),
        ("bob", models[1], bob, ports[4:]),
    ):
        robots.append(
            f"""  - name: {name}
    model: {model}
    backend: ur
    address: {address}
    ports: {{reverse: {p[0]}, script_sender: {p[1]}, trajectory: {p[2]}, script_command: {p[3]}}}
    ur: {{startup: true, listen_address: 127.0.0.1}}
"""
        )
    return "cell: twocell\nrobots:\n" + "".join(robots)


PASSTHROUGH_POINTS = [
    {"positions": [0.2, -1.5, 1.5, -1.5, -1.6, 0.1], "time_from_start": 0.6},
    {"positions": [0.4, -1.4, 1.4, -1.5, -1.6, 0.2], "time_from_start": 1.2},
    {"positions": [0.3, -1.45, 1.45, -1.55, -1.6, 0.15], "time_from_start": 1.8},
]


@SERIES
async def test_alice_servos_a_trajectory_while_bob_runs_a_passthrough_trajectory(
    series: str, version: tuple[int, int, int, int]
) -> None:
    fakes = [
        FakeController(
            _model(name, series), address=fake_address(), initial_positions=HOME, controller_version=version
        )
        for name in ("ur10e", "ur3e")
    ]
    fake_a, fake_b = fakes
    await fake_a.start()
    await fake_b.start()
    try:
        async with running_daemon(_two_robot_cell(fake_a.address, fake_b.address, series)) as (_, client):
            alice, bob = await client.robot("alice"), await client.robot("bob")
            await _until(client, alice.keys.status, lambda s: s["ready"])
            await _until(client, bob.keys.status, lambda s: s["ready"])
            alice_goal = await alice.send_trajectory(
                [{"positions": [0.5, -1.3, 1.3, -1.5, -1.5, 0.3], "time_from_start": 1.2}]
            )
            bob_goal = await bob.send_trajectory(PASSTHROUGH_POINTS, passthrough=True)
            assert bob_goal.duration == pytest.approx(1.8, abs=0.01)
            with pytest.raises(GoalRejected, match=r"passthrough goal .* runs on the robot"):
                await bob.move(HOME, preempt=True)
            feedback = [f async for f in bob_goal.feedback()]
            assert feedback, "feedback while the robot interpolates"
            results = [await alice_goal.result(timeout=20), await bob_goal.result(timeout=20)]
            assert [r["status"] for r in results] == ["succeeded", "succeeded"], results
            assert fake_b.arm.q == pytest.approx(PASSTHROUGH_POINTS[-1]["positions"], abs=0.01)
            assert fake_a.arm.q == pytest.approx([0.5, -1.3, 1.3, -1.5, -1.5, 0.3], abs=0.01)
            # a canceled passthrough ends CANCELED and the robot stops short of the goal
            again = await bob.send_trajectory(
                [{"positions": [-0.4, *HOME[1:]], "time_from_start": 4.0}], passthrough=True
            )
            async for _ in again.feedback():
                break
            assert (await bob.cancel())["canceled"] is True
            result = await again.result(timeout=20)
            assert result["status"] == "canceled"
            assert fake_b.arm.q[0] > -0.4 + 0.05, "stopped before the goal"
    finally:
        await fake_a.close()
        await fake_b.close()


async def test_passthrough_on_a_mock_robot_is_refused_with_the_reason() -> None:
    text = "cell: m\nrobots:\n  - {name: alice, model: ur10e, backend: mock}\n"
    async with running_daemon(text) as (_, client):
        alice = await client.robot("alice")
        with pytest.raises(
            GoalRejected, match="passthrough: the mock backend has no robot-side interpolation"
        ):
            await alice.send_trajectory(PASSTHROUGH_POINTS, passthrough=True)


async def test_a_read_only_robot_is_watched_and_never_commanded() -> None:
    """ur.read_only: state published; no inputs claimed, no program, no callback server, commands refused."""
    fake = FakeController("ur10e", address=fake_address(), initial_positions=HOME, powered=True)
    await fake.start()
    text = _cell(fake.address, startup=False).replace(
        "ur: {startup: false,", "ur: {read_only: true, startup: false,"
    )
    reverse_port = int(text.split("reverse: ")[1].split(",")[0])
    try:
        async with running_daemon(text) as (daemon, client):
            alice = await client.robot("alice")
            status = await _until(
                client, alice.keys.status, lambda s: s["lifecycle"] == "running" and s["cycles"] > 10
            )
            assert "read-only" in status["reason"]
            assert status["ready"] is False
            states = alice.joint_states(10)
            state = await states.get_json(timeout=10.0)
            states.close()
            assert state["position"] == pytest.approx(HOME, abs=1e-9)
            assert fake.rtde.input_owner == {}  # no RTDE input claimed: another client may own them all
            with pytest.raises(ConnectionRefusedError):  # no callback server listens
                await asyncio.open_connection("127.0.0.1", reverse_port)
            for reply in (
                await alice.set_io("digital", 1, True),
                await alice.set_speed_slider(0.5),
                await alice.startup(),
                await alice.resend_program(),
            ):
                assert reply["ok"] is False
                assert "read-only" in reply["reason"]
            with pytest.raises(GoalRejected):
                await alice.move([0.1, *HOME[1:]], duration=1.0)
            assert daemon.runtimes[0].backend.statistics().cycles > 10
            assert fake.arm.q == pytest.approx(HOME, abs=1e-9)
    finally:
        await fake.close()


async def test_a_move_ends_with_the_arm_settled_on_its_goal() -> None:
    """move 1 rad in 2 s with the default servoj gain/lookahead (2000 / 0.03): once the goal succeeded
    the arm settles on the goal (the stop holds the last setpoint, as UR's ROS 2 driver does), not
    frozen where the goal tolerance (0.01 rad) let go of it. Before the stop held it (972271b), it came
    to rest 2.2e-4 rad past the goal (5.8e-3 rad short with 300 / 0.1)."""
    fake = FakeController("ur10e", address=fake_address(), initial_positions=HOME, powered=True)
    await fake.start()
    try:
        async with running_daemon(_cell(fake.address)) as (_, client):
            alice = await client.robot("alice")
            await _until(client, alice.keys.status, lambda s: s["ready"])
            target = [1.0, *HOME[1:]]
            goal = await alice.move(target, duration=2.0)
            assert (await goal.result(timeout=20))["status"] == "succeeded"
            # until the arm is at rest (stopj or settled): within 5 s of the fake's own time
            await fake.until(lambda: fake.arm.steady or max(abs(v) for v in fake.arm.qd) < 1e-9, cycles=2500)
            # the hold lets go within SETTLE_POSITION; the script's stopj then stops the arm from under
            # SETTLE_VELOCITY, a further few µrad at most
            assert fake.arm.q[0] == pytest.approx(target[0], abs=1.5 * SETTLE_POSITION)
    finally:
        await fake.close()
