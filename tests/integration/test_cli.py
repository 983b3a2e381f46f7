"""The ``urdaemon`` command as a user runs it: echo, move, urdf, serve (SIGINT), --version.

Client commands run in-process (``urdaemon.cli.main`` in a thread of its own, ``run_cli_in_thread``)
against a daemon that runs in the test's own event loop, so the daemon keeps cycling while the test
waits for the command. Every client command is given ``--connect`` pointing at that daemon (never the
default 7447). ``serve`` runs as a real process: a signal to it is what that test is about.
"""

from __future__ import annotations

import asyncio
import io
import json
import math
import os
import signal
import subprocess
import sys
from collections.abc import AsyncIterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
import yourdfpy

from tests.helpers import CliRun, drain_in_background, free_tcp_port, run_cli_in_thread, wait_for_line
from tests.integration.conftest import TWO_MOCKS, running_daemon
from urdaemon import __version__
from urdaemon.cell import load_cell
from urdaemon.client import Client
from urdaemon.daemon import Daemon
from urdaemon.description import build_cell_urdf

pytestmark = pytest.mark.timeout(120)

ROOT = Path(__file__).resolve().parents[2]
DEMO_CONFIG = "configs/dual_robot_mock.yaml"  # relative to ROOT, as the docs type it
HOME = [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]
CLI_TIMEOUT_S = 30.0


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH", "")) if p)
    env["PYTHONUNBUFFERED"] = "1"
    return env


async def urdaemon(*args: str, timeout: float = CLI_TIMEOUT_S) -> CliRun:
    """Run ``urdaemon ARGS`` in-process, in a thread, so the in-loop daemon keeps serving (a new
    interpreter would add ~1.7 s of imports per run and test nothing more)."""
    return await run_cli_in_thread(*args, timeout=timeout)


@dataclass(frozen=True)
class Served:
    """A daemon in this loop, a client connected to it, and the endpoint a CLI must ``--connect`` to."""

    daemon: Daemon
    client: Client
    endpoint: str

    @property
    def cell(self) -> str:
        return self.daemon.cell.cell


@pytest.fixture
async def served() -> AsyncIterator[Served]:
    """The two-mock test cell (alice UR10e, bob UR5) on a free loopback port."""
    async with running_daemon(TWO_MOCKS) as (daemon, client):
        listen = daemon.listen_endpoints
        assert len(listen) == 1
        assert listen[0].startswith("tcp/127.0.0.1:")
        yield Served(daemon, client, listen[0])


def _joints(values: list[float]) -> str:
    return ",".join(repr(v) for v in values)


def _last_json_line(text: str) -> dict[str, Any]:
    lines = [line for line in text.splitlines() if line.strip()]
    assert lines, "nothing on stdout"
    data: dict[str, Any] = json.loads(lines[-1])
    return data


# ---- echo ----------------------------------------------------------------------------------------------


async def test_echo_prints_exactly_count_json_lines_of_joint_states(served: Served) -> None:
    key = f"{served.cell}/alice/joint_states"
    run = await urdaemon("echo", key, "--count", "3", "--connect", served.endpoint)
    assert run.code == 0, run.stderr
    lines = run.stdout.splitlines()
    assert len(lines) == 3, run.stdout
    cycles = []
    for line in lines:
        sample = json.loads(line)
        assert set(sample) == {"key", "value"}
        assert sample["key"] == key
        state = sample["value"]
        assert state["v"] == 1
        assert state["robot"] == "alice"
        assert state["names"][0] == "alice_shoulder_pan_joint"
        assert len(state["names"]) == 6
        for field in ("position", "velocity", "effort"):
            assert len(state[field]) == 6, field
            assert all(isinstance(x, float) and math.isfinite(x) for x in state[field]), field
        # the mock arm rests at its initial positions
        assert state["position"] == pytest.approx(HOME, abs=1e-9)
        assert isinstance(state["host_time_ns"], int)
        cycles.append(state["cycle"])
    assert cycles == sorted(cycles)
    assert len(set(cycles)) == 3, f"three distinct samples, got cycles {cycles}"


async def test_echo_with_a_timeout_on_a_silent_key_exits_1_with_an_error(served: Served) -> None:
    key = f"{served.cell}/nobody/joint_states"
    run = await urdaemon("echo", key, "--timeout", "0.5", "--connect", served.endpoint)
    assert run.code == 1, (run.stdout, run.stderr)
    assert run.stdout == ""
    assert "error:" in run.stderr
    assert key in run.stderr
    assert "Traceback" not in run.stderr


async def test_echo_with_an_invalid_key_expression_is_a_bad_argument(served: Served) -> None:
    run = await urdaemon(
        "echo", f"{served.cell}//joint_states", "--timeout", "0.5", "--connect", served.endpoint
    )
    assert "Traceback" not in run.stderr, run.stderr
    assert run.code == 2
    assert "error:" in run.stderr


# ---- move ----------------------------------------------------------------------------------------------


async def test_move_succeeds_prints_the_result_and_the_robot_gets_there(served: Served) -> None:
    target = [0.5, -1.2, 1.2, -1.5, -1.5, 0.3]
    run = await urdaemon(
        "move", "alice", "--joints", _joints(target), "--duration", "1", "--connect", served.endpoint
    )
    assert run.code == 0, run.stderr
    result = _last_json_line(run.stdout)
    assert result["status"] == "succeeded", result
    assert result["goal_id"].startswith("alice-")
    assert result["final_positions"] == pytest.approx(target, abs=0.01)
    assert result["duration"] == pytest.approx(1.0, abs=0.05)
    assert f"goal {result['goal_id']} accepted" in run.stderr
    positions = served.daemon.runtimes[0].backend.state.positions
    assert positions == pytest.approx(target, abs=1e-3)
    # bob was not touched
    assert served.daemon.runtimes[1].backend.state.positions == pytest.approx(HOME, abs=1e-9)


async def test_move_outside_the_joint_limits_is_rejected_naming_the_joint(served: Served) -> None:
    state = served.daemon.runtimes[0].backend.state
    before = list(state.positions)
    target = [0.0, -1.5708, 4.0, -1.5708, -1.5708, 0.0]  # elbow beyond ±π
    run = await urdaemon(
        "move", "alice", "--joints", _joints(target), "--duration", "1", "--connect", served.endpoint
    )
    assert run.code == 1, (run.stdout, run.stderr)
    assert "rejected:" in run.stderr
    assert "alice_elbow_joint" in run.stderr
    assert run.stdout == ""
    assert state.positions == pytest.approx(before, abs=1e-9), "a rejected goal moved the robot"


@pytest.mark.parametrize(
    "joints",
    [
        "1,2,x",
        "nan,-1.5708,1.5708,-1.5708,-1.5708,0.0",
        "0.0,-1.5708,inf,-1.5708,-1.5708,0.0",
        "",
        "0.1,,0.2",
    ],
)
async def test_move_with_joints_that_are_not_finite_numbers_exits_2(served: Served, joints: str) -> None:
    state = served.daemon.runtimes[0].backend.state
    before = list(state.positions)
    run = await urdaemon("move", "alice", f"--joints={joints}", "--connect", served.endpoint)
    assert run.code == 2, (run.stdout, run.stderr)
    assert "error: --joints" in run.stderr
    assert "Traceback" not in run.stderr
    assert run.stdout == ""
    assert state.positions == before


async def test_move_of_an_unknown_robot_exits_1(served: Served) -> None:
    joints = _joints(HOME)
    # with --cell the robot is not looked up; without it, discovery gives up after its 5 s default
    named, discovered = await asyncio.gather(
        urdaemon("move", "carol", "--cell", served.cell, "--joints", joints, "--connect", served.endpoint),
        urdaemon("move", "carol", "--joints", joints, "--connect", served.endpoint),
    )
    for run in (named, discovered):
        assert run.code == 1, (run.stdout, run.stderr)
        assert "error:" in run.stderr
        assert "carol" in run.stderr
        assert "Traceback" not in run.stderr
        assert run.stdout == ""
    assert "no robot 'carol'" in discovered.stderr


async def test_move_with_a_negative_first_joint_as_the_readme_types_it(served: Served) -> None:
    target = [-0.5, -1.3, 1.4, -1.6, -1.5, 0.0]
    run = await urdaemon(
        "move", "bob", "--joints", _joints(target), "--duration", "1.0", "--connect", served.endpoint
    )
    assert run.code == 0, run.stderr
    assert _last_json_line(run.stdout)["status"] == "succeeded"
    assert served.daemon.runtimes[1].backend.state.positions == pytest.approx(target, abs=1e-3)


async def test_move_with_a_duration_beyond_the_planner_range_is_rejected_promptly(served: Served) -> None:
    state = served.daemon.runtimes[0].backend.state
    before = list(state.positions)
    target = [0.2, *HOME[1:]]
    run = await urdaemon(
        "move", "alice", "--joints", _joints(target), "--duration", "10000", "--connect", served.endpoint
    )
    assert run.code == 1, (run.stdout, run.stderr)
    assert "rejected:" in run.stderr, run.stderr
    assert run.stdout == ""
    assert state.positions == before, "a rejected goal moved the robot"


async def test_move_with_a_malformed_connect_endpoint_is_a_bad_argument() -> None:
    run = await urdaemon("move", "alice", "--joints", _joints(HOME), "--connect", "not-an-endpoint")
    assert "Traceback" not in run.stderr, run.stderr
    assert run.code == 2
    assert "error:" in run.stderr


# ---- urdf ----------------------------------------------------------------------------------------------


async def test_urdf_prints_the_cell_urdf_with_twelve_actuated_joints() -> None:
    run = await urdaemon("urdf", "--config", DEMO_CONFIG)
    assert run.code == 0, run.stderr
    urdf = yourdfpy.URDF.load(io.StringIO(run.stdout), build_scene_graph=True, load_meshes=False)
    names = list(urdf.actuated_joint_names)
    assert len(names) == 12, names
    assert sum(n.startswith("alice_") for n in names) == 6
    assert sum(n.startswith("bob_") for n in names) == 6
    assert urdf.robot.name == "demo_cell"
    assert run.stdout == build_cell_urdf(load_cell(ROOT / DEMO_CONFIG)), "the CLI prints what serve publishes"


@pytest.mark.parametrize(
    ("name", "text"),
    [
        ("not_yaml.yaml", ": : :\n  - [\n"),
        ("unknown_model.yaml", "cell: x\nrobots:\n  - name: a\n    model: ur99\n    backend: mock\n"),
        ("robots_not_a_list.yaml", "cell: x\nrobots: 5\n"),
        ("empty.yaml", ""),
        ("missing.yaml", None),
    ],
)
async def test_urdf_on_a_bad_config_exits_2_naming_the_file(
    tmp_path: Path, name: str, text: str | None
) -> None:
    path = tmp_path / name
    if text is not None:
        path.write_text(text)
    run = await urdaemon("urdf", "--config", str(path))
    assert run.code == 2, (run.stdout, run.stderr)
    assert run.stdout == ""
    assert "error:" in run.stderr
    assert name in run.stderr
    assert "Traceback" not in run.stderr


# ---- serve ---------------------------------------------------------------------------------------------


async def _stop_process(proc: subprocess.Popen[str], timeout: float) -> int | None:
    """Wait (off the loop) up to ``timeout`` s for ``proc``; None if it is still running."""
    try:
        return await asyncio.to_thread(proc.wait, timeout)
    except subprocess.TimeoutExpired:
        return None


async def test_serve_stops_cleanly_on_sigint_and_the_running_goal_ends_aborted_once() -> None:
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    proc = subprocess.Popen(
        [sys.executable, "-m", "urdaemon", "serve", "--config", DEMO_CONFIG, "--listen", endpoint],
        cwd=ROOT,
        env=_env(),
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    log: list[str] = []
    try:
        log += await wait_for_line(proc, "serving 2 robot(s)", timeout=60.0)
        drain_in_background(proc, log)
        async with await Client.connect(endpoint) as client:
            alice = await client.robot("alice", timeout=10.0)
            assert alice.keys.cell == "demo_cell"
            target = [0.8, -1.2, 1.2, -1.5, -1.5, 0.3]
            goal = await alice.move(target, duration=5.0)
            assert goal.duration == pytest.approx(5.0, abs=0.01)
            results = client.subscribe(alice.keys.goal_result(goal.goal_id), 10)
            # the goal is running: its first feedback arrived
            feedback = await asyncio.wait_for(anext(goal.feedback()), 5.0)
            assert feedback["goal_id"] == goal.goal_id
            assert feedback["progress"] < 0.5

            proc.send_signal(signal.SIGINT)
            result = await goal.result(timeout=15.0)
            assert result["status"] == "aborted", result
            assert "shutting down" in result["reason"]
            assert result["goal_id"] == goal.goal_id
            assert result["final_positions"] != pytest.approx(target, abs=0.01), "it was stopped mid-way"

            code = await _stop_process(proc, 20.0)
            assert code is not None, "serve did not exit within 20 s of SIGINT"
            assert code == 0, "".join(log[-50:])

            published = [await results.get_json(timeout=5.0)]
            for _ in range(10):  # bounded: anything more would be a second result
                try:
                    published.append(await results.get_json(timeout=0.5))
                except TimeoutError:
                    break
            assert [r["goal_id"] for r in published] == [goal.goal_id], "exactly one result"
            assert published[0]["status"] == "aborted"
    finally:
        if proc.poll() is None:
            proc.kill()
            await _stop_process(proc, 10.0)
    text = "".join(log)
    assert "Traceback" not in text, text
    assert "stopped" in text, text


async def test_serve_on_a_missing_file_exits_2_naming_it(tmp_path: Path) -> None:
    missing = tmp_path / "no_such_cell.yaml"
    run = await urdaemon("serve", "--config", str(missing), "--listen", f"tcp/127.0.0.1:{free_tcp_port()}")
    assert run.code == 2, (run.stdout, run.stderr)
    assert "no_such_cell.yaml" in run.stderr
    assert "error:" in run.stderr
    assert "Traceback" not in run.stderr


async def test_version_prints_the_package_version() -> None:
    run = await urdaemon("--version")
    assert run.code == 0, run.stderr
    assert run.stdout.strip() == f"urdaemon {__version__}"
