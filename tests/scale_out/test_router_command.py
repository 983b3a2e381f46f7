"""``urdaemon router``: the command as users run it (its own process: SIGTERM stops it, exit 0), its
errors (exit 2 for bad input, 1 when it cannot listen), and what a daemon does when its router goes
away and comes back."""

from __future__ import annotations

import asyncio
import os
import re
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from tests.helpers import drain_in_background, run_cli, wait_for_line
from tests.scale_out.conftest import connected, open_router, serving, shipped_cell, wait_alive
from urdaemon.model import RobotState
from urdaemon.router import DEFAULT_LISTEN, Router, endpoint_problem, router_config

pytestmark = pytest.mark.timeout(180)

CONFIGS = Path(__file__).resolve().parents[2] / "configs" / "scale_out"
TARGET = [0.3, -1.4, 1.4, -1.5, -1.6, 0.2]
LONG_MOVE_S = 30.0
MODE_CHECKS = 200
"""Bound on the looks at a robot's controller mode while waiting for it to change (10 s at 50 ms)."""


async def test_the_router_command_logs_its_port_routes_a_cell_and_stops_on_sigterm() -> None:
    proc = subprocess.Popen(
        [sys.executable, "-m", "urdaemon", "router", "--listen", "tcp/127.0.0.1:0"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    log: list[str] = []
    try:
        log += await wait_for_line(proc, "listening on", timeout=60.0)
        drain_in_background(proc, log)
        found = re.search(r"listening on (tcp/127\.0\.0\.1:(\d+))", log[-1])
        assert found is not None, log[-1]
        assert int(found.group(2)) > 0, "the router logs the port the OS chose"
        endpoint = found.group(1)
        async with serving([shipped_cell("cell_a", endpoint)]) as site, connected(endpoint) as client:
            await wait_alive(client, {"cell_a/alice"}, site)
            alice = await client.robot("alice", cell="cell_a")
            goal = await alice.move(TARGET, duration=1.0)
            assert (await goal.result(timeout=30.0))["status"] == "succeeded"
    finally:
        proc.send_signal(signal.SIGTERM)
        try:
            code = await asyncio.get_running_loop().run_in_executor(None, lambda: proc.wait(timeout=20))
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=10)
            pytest.fail("the router did not stop within 20 s of SIGTERM")
    assert code == 0, "".join(log)
    assert any("SIGTERM: stopping the zenoh router" in line for line in log), "".join(log)
    assert not [line for line in log if "Traceback" in line], "".join(log)


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (["--listen", "127.0.0.1:7447"], "'127.0.0.1:7447' is not a Zenoh endpoint"),
        (["--listen", "tcp/127.0.0.1:99999"], "needs a port 0..65535"),
        (["--listen", "tcp/127.0.0.1"], "needs a port 0..65535"),
        (["--listen", "tcp/300.1.1.1:7447"], "300.1.1.1 is not an IPv4 address"),
        (["--listen", "tls/127.0.0.1:0"], "needs a certificate"),
        (["--connect", "tcp/router_a:7447"], "'router_a' is not an IP address or host name"),
        (["--zenoh-config", "no/such/file.json5"], "--zenoh-config 'no/such/file.json5' is not a file"),
    ],
)
def test_bad_input_is_named_and_exits_2(args: list[str], says: str) -> None:
    run = run_cli("router", *args)
    assert run.code == 2, run
    assert says in run.stderr
    assert "Traceback" not in run.stderr


def test_a_config_file_zenoh_cannot_read_exits_2(tmp_path: Path) -> None:
    bad = tmp_path / "router.json5"
    bad.write_text("{listen: ", encoding="utf-8")
    run = run_cli("router", "--zenoh-config", str(bad))
    assert run.code == 2, run
    assert f"--zenoh-config {bad}:" in run.stderr


def test_a_bad_endpoint_in_the_config_file_is_named_as_the_files(tmp_path: Path) -> None:
    config = tmp_path / "router.json5"
    config.write_text('{listen: {endpoints: ["tcp/127.0.0.1:99999"]}}', encoding="utf-8")
    run = run_cli("router", "--zenoh-config", str(config))
    assert run.code == 2, run
    assert "listen (in --zenoh-config) 'tcp/127.0.0.1:99999' needs a port 0..65535" in run.stderr


def test_a_taken_port_exits_1_naming_it() -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        run = run_cli("router", "--listen", f"tcp/127.0.0.1:{port}")
    assert run.code == 1, run
    assert f"cannot open the router (listen ['tcp/127.0.0.1:{port}'])" in run.stderr
    assert "Address already in use" in run.stderr


@pytest.mark.parametrize(
    ("endpoint", "problem"),
    [
        ("tcp/127.0.0.1:7447", None),
        ("tcp/0.0.0.0:0", None),
        ("tcp/[::1]:7447", None),
        ("tcp/router-a.example:7447", None),
        ("tls/10.5.0.1:7447#iface=eth1", None),
        ("udp/127.0.0.1:7447?rel=0", None),
        ("unixsock-stream//run/urdaemon/router.sock", None),
        ("7447", "is not a Zenoh endpoint"),
        ("tcp/127.0.0.1:", "needs a port"),
        ("tcp/127.0.0.1:65536", "needs a port"),
        ("tcp/[::g]:7447", "is not an IPv6 address"),
        ("tcp/1.2.3:7447", "is not an IPv4 address"),
        ("tcp/-bad-:7447", "is not an IP address or host name"),
    ],
)
def test_endpoint_problems(endpoint: str, problem: str | None) -> None:
    found = endpoint_problem(endpoint)
    if problem is None:
        assert found is None
    else:
        assert found is not None
        assert problem in found


def test_the_router_config_takes_the_file_then_the_options() -> None:
    site_b = str(CONFIGS / "router_site_b.json5")
    conf = router_config(config_file=site_b)
    assert conf.get_json("mode") == '"router"'
    assert conf.get_json("listen/endpoints") == '["tcp/0.0.0.0:7447"]'
    assert conf.get_json("connect/endpoints") == '["tcp/router-a.example:7447"]'
    assert conf.get_json("scouting/multicast/enabled") == "false"
    assert conf.get_json("adminspace/enabled") == "true"
    given = router_config(["tcp/127.0.0.1:0"], ["tcp/127.0.0.1:7448"], site_b)
    assert given.get_json("listen/endpoints") == '["tcp/127.0.0.1:0"]'
    assert given.get_json("connect/endpoints") == '["tcp/127.0.0.1:7448"]'
    bare = router_config()
    assert bare.get_json("listen/endpoints") == f'["{DEFAULT_LISTEN}"]'
    assert bare.get_json("connect/endpoints") == "[]"


async def test_a_daemon_outlives_its_router_stops_a_goal_whose_client_went_with_it_and_reconnects() -> None:
    router, endpoint = await open_router()
    async with serving([shipped_cell("cell_a", endpoint)]) as site:
        async with connected(endpoint) as client:
            await wait_alive(client, {"cell_a/alice"}, site)
            alice = await client.robot("alice", cell="cell_a")
            await alice.move(TARGET, duration=LONG_MOVE_S)
            runtime = site.daemons["cell_a"].runtimes[0]
            assert runtime.controller.mode == "goal"
            await router.close()  # the client's session, and with it the lease holder, is cut off
            for _ in range(MODE_CHECKS):
                if runtime.controller.mode != "goal":
                    break
                await asyncio.sleep(0.05)
            assert runtime.controller.mode in ("stopping", "idle"), "the robot stops when its holder is gone"
            cycle = runtime.backend.state.cycle
            await wait_cycles(runtime.backend.state, cycle + 100)  # the daemon serves on without its router
            assert not site.tasks["cell_a"].done()
        async with await Router.open(router_config([endpoint])), connected(endpoint) as client:
            await wait_alive(client, {"cell_a/alice"}, site)  # the daemon dialled the new router itself
            alice = await client.robot("alice", cell="cell_a")
            goal = await alice.move(TARGET, duration=1.0)
            assert (await goal.result(timeout=30.0))["status"] == "succeeded"


async def wait_cycles(state: RobotState, cycle: int) -> None:
    """Until the robot's cycle counter passes ``cycle`` (bounded: ``MODE_CHECKS`` looks)."""
    for _ in range(MODE_CHECKS):
        if state.cycle >= cycle:
            return
        await asyncio.sleep(0.05)
    raise AssertionError(f"the robot's cycle stayed at {state.cycle}, short of {cycle}")
