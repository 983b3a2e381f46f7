"""Signals on real processes: Ctrl-C on ``urdaemon move``, SIGHUP and a repeated SIGTERM on
``urdaemon serve`` (issue 13, findings 6 and 7).

Reproductions on the code before the fix: Ctrl-C on ``move`` exited at once and left the goal running
(the robot kept moving); SIGHUP killed the daemon outright (no result for the running goal, no clean
stop); a SIGTERM that came while the daemon was already stopping could kill it with -15.
"""

from __future__ import annotations

import asyncio
import os
import re
import signal
import socket
import subprocess
import sys
import threading
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path

import pytest

from tests.helpers import drain_in_background, free_tcp_port, wait_for_line
from tests.integration.conftest import TWO_MOCKS, running_daemon
from urdaemon.client import Client, RobotClient

pytestmark = pytest.mark.timeout(120)

ROOT = Path(__file__).resolve().parents[2]
AWAY = [0.2, -1.4, 1.4, -1.5, -1.6, 0.1]


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH", "")) if p)
    env["PYTHONUNBUFFERED"] = "1"
    return env


def _urdaemon(*args: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "urdaemon", *args],
        cwd=ROOT,
        env=_env(),
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


async def _wait(proc: subprocess.Popen[str], timeout: float = 60.0) -> int:
    return await asyncio.get_running_loop().run_in_executor(None, proc.wait, timeout)


async def _exit_and_log(proc: subprocess.Popen[str], reader: threading.Thread, timeout: float = 60.0) -> int:
    """The process's exit code, once it exited and its stderr was read to the end (the log's last
    lines reach the list after the exit, on a busy machine well after it)."""
    code = await _wait(proc, timeout)
    await asyncio.to_thread(reader.join, timeout)
    assert not reader.is_alive(), "stderr still open after the exit"
    return code


def _signal_masks(pid: int) -> str:
    """The process's blocked and ignored signal masks (``/proc/PID/status``), or why not."""
    try:
        lines = Path(f"/proc/{pid}/status").read_text(encoding="utf-8").splitlines()
    except OSError as err:
        return f"unreadable: {err}"
    return " ".join(line for line in lines if line.startswith(("SigBlk", "SigIgn")))


async def test_ctrl_c_on_move_cancels_its_goal_before_exiting() -> None:
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        pytest.skip(
            "this test process ignores SIGINT (started in the background of a shell without job "
            "control), and every process it starts inherits that: run the suite in the foreground"
        )
    async with running_daemon(TWO_MOCKS) as (daemon, client):
        endpoint = daemon.listen_endpoints[0]
        joints = ",".join(repr(v) for v in AWAY)
        proc = _urdaemon("move", "alice", "--joints", joints, "--duration", "30", "--connect", endpoint)
        try:
            lines = await wait_for_line(proc, "accepted", timeout=60.0)
            match = re.search(r"goal (\S+) accepted", lines[-1])
            assert match, lines
            goal_id = match.group(1)
            assert proc.poll() is None, "move had ended before its 'accepted' line was read"
            masks = _signal_masks(proc.pid)  # to tell, if Ctrl-C does nothing, whether it was ignored
            proc.send_signal(signal.SIGINT)
            code = await _wait(proc)
        finally:
            if proc.poll() is None:
                proc.kill()
        assert proc.stderr is not None
        assert proc.stdout is not None
        rest = proc.stderr.read()
        assert code == 130, f"{rest}\nmove's signal masks when SIGINT was sent: {masks}"
        assert f"goal {goal_id} canceled" in rest, rest
        alice = await client.robot("alice")
        replies = await client.query(alice.keys.goal_result(goal_id), timeout=5.0)
        assert replies, "the goal is still running: Ctrl-C left the robot moving"
        assert b'"canceled"' in replies[0], replies
        assert '"canceled"' in proc.stdout.read()


async def _ready(client: Client, robot: RobotClient) -> None:
    sub = client.subscribe(robot.keys.status, 100)
    try:
        for _ in range(1000):
            if (await sub.get_json(timeout=30.0)).get("ready"):
                return
        raise AssertionError(f"{robot.name} never became ready")
    finally:
        client.unsubscribe(sub)


@asynccontextmanager
async def _serve(
    tmp_path: Path,
) -> AsyncIterator[tuple[subprocess.Popen[str], Client, list[str], threading.Thread]]:
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    config = tmp_path / "cell.yaml"
    config.write_text(TWO_MOCKS, encoding="utf-8")
    proc = _urdaemon("serve", "--config", str(config), "--listen", endpoint)
    log: list[str] = []
    reader = drain_in_background(proc, log)
    try:
        async with await Client.connect(endpoint, timeout=30.0) as client:
            for name in ("alice", "bob"):
                await _ready(client, await client.robot(name, timeout=30.0))
            yield proc, client, log, reader
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)


async def test_sighup_stops_the_daemon_cleanly_and_the_goal_gets_its_result(tmp_path: Path) -> None:
    async with _serve(tmp_path) as (proc, client, log, reader):
        alice = await client.robot("alice")
        goal = await alice.move(AWAY, duration=30.0)
        proc.send_signal(signal.SIGHUP)
        result = await goal.result(timeout=30.0)  # ConnectionLostError when killed outright
        assert result["goal_id"] == goal.goal_id
        assert result["status"] != "succeeded", result
        assert await _exit_and_log(proc, reader) == 0, "".join(log)
        assert any("SIGHUP: stopping" in line for line in log), "".join(log)
        assert any("stopped" in line for line in log), "".join(log)


async def test_repeated_sigterm_while_stopping_still_exits_normally(tmp_path: Path) -> None:
    async with _serve(tmp_path) as (proc, _client, log, reader):
        sent = 0
        while proc.poll() is None and sent < 3000:  # again and again until it has exited
            proc.send_signal(signal.SIGTERM)
            sent += 1
            await asyncio.sleep(0.002)  # paces the signals; nothing is timed
        code = await _exit_and_log(proc, reader)
        assert sent > 1
        assert code == 0, f"exit {code} after {sent} SIGTERMs\n{''.join(log)}"
        assert any("already stopping" in line for line in log), "".join(log)


def test_serve_called_in_process_gives_ctrl_c_back_to_its_caller(tmp_path: Path) -> None:
    """Reproduction: ``serve`` run through ``main(argv)`` (a test, a program) left SIGINT, SIGTERM and
    SIGHUP ignored in the calling process when it returned, and every process started afterwards
    inherited the ignored SIGINT: in the suite, a ``urdaemon move`` started later by the same worker
    ran its whole goal through Ctrl-C (test_ctrl_c_on_move_cancels_its_goal_before_exiting failed,
    exit 0 instead of 130, whenever such a test had run before it on its worker). The command run as
    ``urdaemon`` still ignores them for its own exit."""
    from urdaemon.cli import main
    from urdaemon.stop_signals import STOP_SIGNALS

    before = {sig: signal.getsignal(sig) for sig in STOP_SIGNALS}
    config = tmp_path / "cell.yaml"
    config.write_text(TWO_MOCKS, encoding="utf-8")
    with socket.socket() as taken:  # the daemon cannot listen: serve starts, then ends at once
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        code = main(["serve", "--config", str(config), "--listen", f"tcp/127.0.0.1:{port}"])
    assert code != 0
    assert {sig: signal.getsignal(sig) for sig in STOP_SIGNALS} == before
    child = subprocess.run(
        [
            sys.executable,
            "-c",
            "import signal; print(signal.getsignal(signal.SIGINT) is signal.default_int_handler)",
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    had_ctrl_c = before[signal.SIGINT] is not signal.SIG_IGN  # not if this process was started ignoring it
    assert child.stdout.strip() == str(had_ctrl_c), "a process started afterwards has Ctrl-C as before"
