"""``urdaemon info`` of a ``ur`` robot against the in-process fake controller: the controller's
version as its primary interface's VERSION message named it, the ports, the calibration check."""

from __future__ import annotations

import json

import pytest

from tests.helpers import fake_address, free_tcp_port, run_cli_in_thread
from tests.integration.conftest import running_daemon
from urdaemon.client import Client
from urdaemon.fakeur.controller import FakeController

pytestmark = pytest.mark.timeout(120)

HOME = [0.0, -1.57, 1.57, -1.57, -1.57, 0.0]


def _cell_text(address: str, ports: list[int]) -> str:
    return f"""
cell: urinfo
robots:
  - name: alice
    model: ur10e
    backend: ur
    address: {address}
    headless: true
    ports: {{reverse: {ports[0]}, script_sender: {ports[1]},
             trajectory: {ports[2]}, script_command: {ports[3]}}}
    ur: {{listen_address: 127.0.0.1}}
"""


async def _daemon_answer(client: Client, tries: int = 100) -> dict[str, object]:
    """``urinfo/daemon``'s answer once the backend heard the controller's version and checked the
    calibration (at most ``tries`` questions, 0.1 s apart)."""
    import asyncio

    for _ in range(tries):
        answer = await client.request("urinfo/daemon")
        robot = answer["robots"][0]
        if robot["controller_version"] is not None and robot["calibration_ok"] is not None:
            return robot  # type: ignore[no-any-return]
        await asyncio.sleep(0.1)
    raise AssertionError("the daemon never said the controller's version")


async def test_info_names_the_controller_version_ports_and_calibration_check() -> None:
    fake = FakeController(
        "ur10e", address=fake_address(), initial_positions=HOME, controller_version=(5, 21, 3, 7)
    )
    ports = [free_tcp_port() for _ in range(4)]
    async with fake, running_daemon(_cell_text(fake.address, ports)) as (daemon, client):
        robot = await _daemon_answer(client)
        assert robot["controller_version"] == {
            "project": "URControl",
            "major": 5,
            "minor": 21,
            "bugfix": 3,
            "build": 7,
            "date": "01-01-2026, 00:00:00",
        }
        run = await run_cli_in_thread(
            "info", "alice", "--window", "0.3", "--connect", daemon.listen_endpoints[0], timeout=40
        )
        assert run.code == 0, run.stderr
        assert "URControl 5.21.3 (build 7, 01-01-2026, 00:00:00)" in run.stdout
        assert f"controller {fake.address}: primary 30001, rtde 30004, dashboard 29999" in run.stdout
        assert f"reverse {ports[0]}, script_sender {ports[1]}" in run.stdout
        assert "the model's nominal kinematics; matches the robot (expected hash" in run.stdout
        as_json = await run_cli_in_thread(
            "info", "alice", "--json", "--window", "0.3", "--connect", daemon.listen_endpoints[0], timeout=40
        )
        data = json.loads(as_json.stdout)
        assert data["robot"]["ports"]["callbacks"]["script_command"] == ports[3]
        assert data["robot"]["backend"] == "ur"
