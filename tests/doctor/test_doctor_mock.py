"""``doctor`` on an in-process mock cell: the host's checks and the mock's truth (no controller), over
the service and the command, and nothing moves or resets."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from tests.helpers import run_cli_in_thread
from tests.integration.conftest import TWO_MOCKS, running_daemon
from urdaemon.doctor.checks import host_checks, robot_checks

pytestmark = pytest.mark.timeout(120)


def _preempt_rt() -> bool:
    """Read here, independently of doctor/host.py."""
    try:
        flag = Path("/sys/kernel/realtime").read_text().strip()
    except OSError:
        flag = ""
    return flag == "1" or "PREEMPT_RT" in os.uname().version


async def test_the_doctor_service_on_a_mock_robot() -> None:
    async with running_daemon(TWO_MOCKS) as (daemon, client):
        alice = await client.robot("alice")
        runtime = daemon.runtimes[0]
        before = list(runtime.backend.state.positions)
        states = alice.joint_states(1)
        await states.get(timeout=30.0)  # it has cycled (a loaded machine starts it late)
        client.unsubscribe(states)
        counted = runtime.backend.statistics().cycles
        reply = await alice.doctor()
        assert reply["ok"] is True
        assert reply["robot"] == "alice"
        verdicts = {check["name"]: check["verdict"] for check in reply["checks"]}
        assert verdicts["kernel"] == ("ok" if _preempt_rt() else "warn")
        assert verdicts["realtime_priority"] == "warn", "the cell file asks for none"
        assert verdicts["controller"] == "n/a"
        assert verdicts["turnaround"] == "n/a"
        assert list(verdicts) == ["kernel", "realtime_priority", "controller", "cycles", "turnaround"]
        shown = {check["name"]: check for check in reply["checks"]}
        assert shown["controller"]["measured"] == "mock backend: no controller"
        assert "event loop thread SCHED_OTHER" in shown["realtime_priority"]["measured"]
        # the verdicts are the pure checks' of the facts the reply carries
        again = [c.as_dict() for c in (*host_checks(reply["host"]), *robot_checks(reply["facts"]))]
        assert again == reply["checks"]
        assert reply["facts"]["cycles"] >= counted > 0
        # nothing moved, and the client asked without the lease (a commanding service is refused so)
        assert list(runtime.backend.state.positions) == before


async def test_urdaemon_doctor_prints_every_robot_and_exits_by_the_verdicts() -> None:
    async with running_daemon(TWO_MOCKS) as (daemon, _):
        endpoint = daemon.listen_endpoints[0]
        every = await run_cli_in_thread("doctor", "--connect", endpoint, timeout=60.0)
        lines = every.stdout.splitlines()
        assert lines[0] == "testcell: the daemon's host"
        assert "testcell/alice (mock)" in lines
        assert "testcell/bob (mock)" in lines
        assert sum(line.startswith("  n/a     controller ") for line in lines) == 2
        assert sum(" kernel " in line for line in lines) == 1, "the host's checks once per cell"
        failed = any(line.startswith("  fail ") for line in lines)
        assert every.code == (1 if failed else 0), every.stdout
        one = await run_cli_in_thread("doctor", "bob", "--json", "--connect", endpoint, timeout=60.0)
        [bob] = json.loads(one.stdout)["robots"]
        assert (bob["cell"], bob["robot"], bob["facts"]["backend"]) == ("testcell", "bob", "mock")
        assert one.code == (1 if bob["verdict"] == "fail" else 0)
        missing = await run_cli_in_thread("doctor", "carol", "--connect", endpoint, timeout=60.0)
        assert missing.code == 1
        assert "carol" in missing.stderr
        bad = await run_cli_in_thread("doctor", "Bad-Name", "--connect", endpoint, timeout=60.0)
        assert bad.code == 2
        assert "not a robot name" in bad.stderr
