"""``doctor`` on `ur` robots against fake controllers: every check passes or reports the truth
(remote control off, a CB3 without it, a dashboard that refuses connections), and nothing moves."""

from __future__ import annotations

from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

import pytest

from tests.helpers import fake_address, free_tcp_port, run_cli_in_thread
from tests.integration.conftest import running_daemon
from urdaemon.backends.ur.backend import UrBackend
from urdaemon.backends.ur.diagnosis import ROUND_TRIPS
from urdaemon.daemon import Daemon
from urdaemon.fakeur.controller import FakeController
from urdaemon.fakeur.faults import FaultInjector

pytestmark = pytest.mark.timeout(180)

HOME = [0.0, -1.57, 1.57, -1.57, -1.57, 0.0]


def _cell(fake: FakeController, model: str, startup: bool) -> str:
    p = [free_tcp_port() for _ in range(4)]
    ports = f"{{reverse: {p[0]}, script_sender: {p[1]}, trajectory: {p[2]}, script_command: {p[3]}}}"
    return f"""
cell: drcell
robots:
  - name: alice
    model: {model}
    backend: ur
    address: {fake.address}
    headless: true
    ports: {ports}
    ur: {{startup: {str(startup).lower()}, listen_address: {fake.address}}}
"""


@asynccontextmanager
async def _served(fake: FakeController, model: str, *, startup: bool = True) -> AsyncIterator[Daemon]:
    async with fake, running_daemon(_cell(fake, model, startup)) as (daemon, _):
        backend = daemon.runtimes[0].backend
        assert isinstance(backend, UrBackend)

        def ready() -> bool:
            streaming = backend.statistics().cycles > 0
            return streaming and (
                not startup or (backend.state.ready_for_motion and backend.servers.reverse.connected)
            )

        await fake.until(ready, cycles=20_000, timeout=60.0)
        yield daemon


def _verdicts(reply: dict[str, Any]) -> dict[str, str]:
    assert reply["ok"] is True, reply
    return {check["name"]: check["verdict"] for check in reply["checks"]}


def _measured(reply: dict[str, Any], name: str) -> str:
    return str(next(c["measured"] for c in reply["checks"] if c["name"] == name))


async def test_every_controller_check_on_a_running_fake_e_series() -> None:
    fake = FakeController("ur10e", address=fake_address(), initial_positions=HOME)
    async with _served(fake, "ur10e") as daemon:
        client_q = list(fake.arm.q)
        reply = await run_doctor(daemon)
        verdicts = _verdicts(reply)
        assert {name: verdicts[name] for name in ("dashboard", "primary", "controller_version")} == {
            "dashboard": "ok",
            "primary": "ok",
            "controller_version": "ok",
        }
        assert verdicts["remote_control"] == "ok"
        assert verdicts["callback_ports"] == "ok"
        assert verdicts["clock_offset"] in ("ok", "warn")
        assert verdicts["round_trip"] in ("ok", "warn")  # a loaded test machine may be slow: the truth
        assert verdicts["rtde_jitter"] in ("ok", "warn")
        assert verdicts["turnaround"] in ("ok", "warn", "fail")
        assert _measured(reply, "controller_version") == "PolyScope 5.15.0.0 (e-Series)"
        assert f"reached from {fake.address} (reverse link up)" in _measured(reply, "callback_ports")
        assert f"listening on {fake.address}" in _measured(reply, "callback_ports")
        controller = reply["facts"]["controller"]
        assert len(controller["dashboard"]["round_trips_ms"]) == ROUND_TRIPS
        assert controller["rtde_version"] == [5, 15, 0, 0]
        assert controller["clock"]["samples"] > 10
        clock = controller["clock"]
        assert clock["offset_s"] is not None
        if verdicts["clock_offset"] == "warn":
            assert clock["baseline_s"] >= 10.0, "the drift is judged only over 10 s"
        # nothing moved: the arm rests where it did, the program still runs
        assert fake.arm.q == client_q
        assert fake.arm.program_running
        # remote control off: the robot would refuse the daemon's program
        fake.arm.remote_control = False
        off = await run_doctor(daemon)
        assert _verdicts(off)["remote_control"] == "fail"
        action = next(c["action"] for c in off["checks"] if c["name"] == "remote_control")
        assert action.startswith("remote control is off: set the robot to Remote Control on the pendant")


async def run_doctor(daemon: Daemon) -> dict[str, Any]:
    """The CLI's JSON for alice, run in-process."""
    import json

    run = await run_cli_in_thread("doctor", "alice", "--json", "--connect", daemon.listen_endpoints[0])
    [reply] = json.loads(run.stdout)["robots"]
    assert run.code == (1 if reply["verdict"] == "fail" else 0), run.stdout
    return dict(reply)


async def test_a_cb3_has_no_remote_control_mode() -> None:
    fake = FakeController("ur5", address=fake_address(), controller_version=(3, 15, 8, 0))
    async with _served(fake, "ur5", startup=False) as daemon:
        reply = await run_doctor(daemon)
        verdicts = _verdicts(reply)
        assert verdicts["remote_control"] == "n/a"
        assert _measured(reply, "remote_control") == "CB3 has no remote control mode"
        assert _measured(reply, "controller_version") == "PolyScope 3.15.8.0 (CB3)"
        assert (
            reply["facts"]["controller"]["remote_control_text"]
            == "could not understand: 'is in remote control'"
        )
        assert verdicts["callback_ports"] == "warn", "no program started: the robot has not dialled them"
        assert reply["facts"]["controller"]["clock"]["period_ms"] == pytest.approx(8.0)


async def test_a_dashboard_that_refuses_connections_fails_naming_the_security_setting() -> None:
    fake = FakeController("ur10e", address=fake_address(), faults=FaultInjector(refused={"dashboard"}))
    async with _served(fake, "ur10e", startup=False) as daemon:
        reply = await run_doctor(daemon)
        verdicts = _verdicts(reply)
        assert verdicts["dashboard"] == "fail"
        assert verdicts["round_trip"] == "unknown"
        assert verdicts["primary"] == "ok"
        assert verdicts["controller_version"] == "ok", "RTDE said the version"
        action = next(c["action"] for c in reply["checks"] if c["name"] == "dashboard")
        assert "Settings > Security > Services" in action
        assert reply["verdict"] == "fail"
