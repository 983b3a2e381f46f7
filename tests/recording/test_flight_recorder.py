"""The daemon's flight recorder (cell file ``record``): its process started with the daemon and fed
through its stdin, a file on a client's request (mock cell) and on a protective stop injected in a
fake controller (``ur`` backend), holding the seconds before it; tcp_pose and tf in it only while a
client subscribes to them; restarted when it dies; working with access control and any endpoint."""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import json
import logging
import os
import signal
import subprocess
import sys
import time
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

import pytest
import zenoh

from tests.helpers import (
    drain_in_background,
    fake_address,
    free_tcp_port,
    run_cli_in_thread,
    wait_for_line,
    zenoh_ask,
)
from tests.integration.conftest import TWO_MOCKS, running_daemon
from urdaemon.cell import parse_cell
from urdaemon.client import Client
from urdaemon.daemon import Daemon
from urdaemon.errors import ConfigError
from urdaemon.fakeur.controller import FakeController
from urdaemon.recording.mcap_file import Recorded, read_recording
from urdaemon.runtime.flight_recorder import FlightRecorder

pytestmark = pytest.mark.timeout(120)

HOME = [0.0, -1.57, 1.57, -1.57, -1.57, 0.0]
TARGET = [0.3, -1.4, 1.4, -1.5, -1.6, 0.2]
READY_S = 60.0
"""Bound on the recorder's process starting (a fresh interpreter importing zenoh and mcap)."""


def _recorder(daemon: Daemon) -> FlightRecorder:
    assert daemon.flight_recorder is not None
    return daemon.flight_recorder


def _read(path: str) -> list[Recorded]:
    with open(path, "rb") as stream:
        return list(read_recording(stream))


@asynccontextmanager
async def _mock_cell(tmp_path: Path, ring_s: float = 30.0) -> AsyncIterator[tuple[Daemon, Client]]:
    text = TWO_MOCKS + f"record: {{ring_s: {ring_s}, after_s: 0.2, dir: {tmp_path / 'flight'}}}\n"
    async with running_daemon(text) as (daemon, client):
        await asyncio.wait_for(_recorder(daemon).ready.wait(), READY_S)
        yield daemon, client


async def test_a_request_writes_the_seconds_before_it_and_answers_with_the_path(tmp_path: Path) -> None:
    started_ns = time.time_ns()  # before the daemon, so before its recorder
    async with _mock_cell(tmp_path) as (daemon, client):
        await (await client.robot("alice")).joint_states().get(timeout=10.0)  # the stream flows
        sub = client.subscribe("testcell/alice/joint_states", 5000)
        for _ in range(500):  # a second of alice at 500 Hz, after the recorder subscribed
            await sub.get(timeout=10.0)
        asked_ns = time.time_ns()
        replies = await zenoh_ask(client.session, "testcell/service/flight_record", timeout=60.0)
        assert len(replies) == 1, replies
        assert replies[0]["ok"] is True, replies
        path = replies[0]["path"]
        assert Path(path).parent == tmp_path / "flight"
        assert Path(path).name.startswith("testcell_")
        assert path.endswith("_request.mcap")
        assert not list((tmp_path / "flight").glob("*.partial"))

        read = _read(path)
        alice = [r.log_time_ns for r in read if r.topic == "/testcell/alice/joint_states"]
        bob = [r.log_time_ns for r in read if r.topic == "/testcell/bob/joint_states"]
        assert len(alice) >= 500
        assert len(bob) >= 100
        assert min(alice) <= asked_ns - 1_000_000_000  # the second before the request
        assert min(alice) >= started_ns  # not before the recorder was there
        assert max(alice) >= asked_ns  # and what came after it (after_s)
        assert any(r.kind is None for r in read), "the cell URDF"
        topics = {r.topic for r in read}
        assert topics >= {"/testcell/alice/status", "/testcell/bob/status", "/testcell/bob/joint_states"}
        # derived from joint_states at the cost of forward kinematics: only for a client that wants them
        assert not topics & {"/testcell/tf", "/testcell/alice/tcp_pose", "/testcell/bob/tcp_pose"}
        recorder = _recorder(daemon)
        assert recorder.written[-1]["written"] == path

        poses = client.subscribe("testcell/bob/tcp_pose", 5000)
        for _ in range(100):
            await poses.get(timeout=10.0)
        recorder.file_written.clear()
        assert recorder.request("request", "second")  # with an id: a file of its own, not merged
        await asyncio.wait_for(recorder.file_written.wait(), 60.0)
        topics = {r.topic for r in _read(recorder.written[-1]["written"])}
        assert "/testcell/bob/tcp_pose" in topics, "a client subscribed: the daemon computes it"
        assert "/testcell/alice/tcp_pose" not in topics


async def test_the_process_is_started_again_when_it_dies(tmp_path: Path) -> None:
    async with _mock_cell(tmp_path) as (daemon, _client):
        recorder = _recorder(daemon)
        pid = recorder.pid
        assert pid is not None
        os.kill(pid, signal.SIGKILL)
        for _ in range(200):  # it notices, waits its first backoff and starts again
            if recorder.restarts == 1 and recorder.ready.is_set():
                break
            await asyncio.sleep(0.1)
        assert recorder.restarts == 1
        assert recorder.ready.is_set()
        assert recorder.pid not in (None, pid)
        assert recorder.dropped > 0, "what was published while it was down was dropped, not kept"
        endpoint = daemon.listen_endpoints[0]
        result = await run_cli_in_thread("record", "--flight", "--connect", endpoint, timeout=120.0)
        assert result.code == 0, result.stderr
        path = Path(result.stdout.strip())
        assert path.parent == tmp_path / "flight"
        assert path.name.endswith("_request.mcap")
        assert path.name in os.listdir(path.parent)


ACCESS = (
    "zenoh:\n  access:\n    identities: {local: {interfaces: [lo]}}\n"
    "    grants: [{identities: [local], read: ['*']}]"
)


@pytest.mark.parametrize("extra", ["zenoh: {listen: ['udp/127.0.0.1:7447']}", ACCESS])
def test_any_zenoh_setup_takes_a_recorder(tmp_path: Path, extra: str) -> None:
    text = TWO_MOCKS + f"record: {{dir: {tmp_path}}}\n{extra}\n"
    assert parse_cell(text, base_dir=tmp_path).record is not None


async def test_a_cell_with_access_control_records(tmp_path: Path) -> None:
    text = TWO_MOCKS + f"record: {{ring_s: 5, after_s: 0.2, dir: {tmp_path}}}\n{ACCESS}\n"
    async with running_daemon(text) as (daemon, _client):
        recorder = _recorder(daemon)
        await asyncio.wait_for(recorder.ready.wait(), READY_S)
        assert recorder.request("request")
        await asyncio.wait_for(recorder.file_written.wait(), 60.0)
        read = _read(recorder.written[-1]["written"])
        assert {r.topic for r in read} >= {"/testcell/alice/joint_states", "/testcell/bob/status"}


def _ur_cell(address: str, flight_dir: Path) -> str:
    p = [free_tcp_port() for _ in range(4)]
    ports = f"{{reverse: {p[0]}, script_sender: {p[1]}, trajectory: {p[2]}, script_command: {p[3]}}}"
    return f"""
cell: urcell
record: {{ring_s: 3, after_s: 0.5, dir: {flight_dir}}}
robots:
  - name: alice
    model: ur10e
    backend: ur
    address: {address}
    headless: true
    ports: {ports}
    ur: {{startup: true, listen_address: 127.0.0.1}}
"""


class _Published:
    """The host times of every message the daemon publishes on ``key``, from a subscriber of the
    daemon's own session (a put reaches it without a link, so none is dropped on the way) filling a
    Zenoh FIFO channel (on Zenoh's side, without Python)."""

    CAPACITY = 200_000

    def __init__(self, daemon: Daemon, key: str) -> None:
        assert daemon.node is not None
        self._sub = daemon.node.session.declare_subscriber(key, zenoh.handlers.FifoChannel(self.CAPACITY))

    def close(self) -> list[int]:
        """Everything received so far (host_time_ns), then no more."""
        times: list[int] = []
        for _ in range(self.CAPACITY):
            sample = self._sub.try_recv()
            if sample is None:
                break
            times.append(json.loads(sample.payload.to_bytes())["host_time_ns"])
        self._sub.undeclare()
        return times


async def _until_ready(client: Client, key: str) -> dict[str, Any]:
    sub = client.subscribe(key, 100)
    try:
        for _ in range(500):
            status = await sub.get_json(timeout=20.0)
            if status["ready"]:
                return status
        raise AssertionError(f"{key}: the robot never got ready")
    finally:
        client.unsubscribe(sub)


async def test_a_protective_stop_writes_the_seconds_before_it(tmp_path: Path) -> None:
    fake = FakeController("ur10e", address=fake_address(), initial_positions=HOME)
    async with fake, running_daemon(_ur_cell(fake.address, tmp_path)) as (daemon, client):
        recorder = _recorder(daemon)
        await asyncio.wait_for(recorder.ready.wait(), READY_S)
        ready_ns = time.time_ns()
        alice = await client.robot("alice")
        await _until_ready(client, alice.keys.status)
        published = _Published(daemon, "urcell/alice/joint_states")
        goal = await alice.move(TARGET, duration=8.0)
        sub = alice.joint_states(5000)
        for _ in range(2000):  # 4 s of motion at 500 Hz: more than the ring keeps
            await sub.get(timeout=10.0)
        client.unsubscribe(sub)
        assert recorder.written == []
        stop_ns = time.time_ns()
        fake.protective_stop()
        result = await goal.result(timeout=20.0)
        assert result["status"] == "aborted", result
        await asyncio.wait_for(recorder.file_written.wait(), 60.0)
        sent = published.close()

        [report] = recorder.written
        path = Path(report["written"])
        assert path.parent == tmp_path
        assert path.name.startswith("urcell_")
        assert path.name.endswith("_protective_stop_alice.mcap"), path.name
        assert set(report["reasons"]) == {"protective_stop_alice", "aborted_alice"}, report
        read = _read(str(path))
        states = [r for r in read if r.topic == "/urcell/alice/joint_states"]
        times = [r.log_time_ns for r in states]
        # the 3 s before the stop (the robot moved more than that since the recorder started)
        assert stop_ns - 3_300_000_000 <= min(times) <= stop_ns - 2_500_000_000, (stop_ns - min(times)) / 1e9
        assert max(times) >= stop_ns + 200_000_000  # and about after_s after it
        assert min(times) > ready_ns
        # the seconds before the stop, without a hole: every joint state the daemon published between
        # the first and the last in the file is in it (the times are the host's: a loaded machine
        # may publish none for a while, and then the file has none either)
        window = {t for t in sent if min(times) <= t <= max(times)}
        missing = sorted(window - set(times))
        gaps = [b - a for a, b in itertools.pairwise(times)]
        assert not missing, f"{len(missing)} of {len(window)} published missing; largest gap {max(gaps)} ns"
        assert len(times) == len(set(times))
        assert len({tuple(r.message["position"]) for r in states}) > 500, "the arm moving"
        lifecycles = [r.message["lifecycle"] for r in read if r.topic == "/urcell/alice/status"]
        assert "protective_stop" in lifecycles
        assert "running" in lifecycles


async def test_an_internal_error_the_daemon_logs_writes_a_file(tmp_path: Path) -> None:
    async with _mock_cell(tmp_path) as (daemon, _client):
        recorder = _recorder(daemon)
        logging.getLogger("urdaemon.daemon").error("tf not published: a bug")  # no traceback: no file
        try:
            raise RuntimeError("a bug")
        except RuntimeError:
            logging.getLogger("urdaemon.daemon").exception("tf not published")
        await asyncio.wait_for(recorder.file_written.wait(), 60.0)
        [report] = recorder.written
        assert report["reasons"] == ["internal_error"]
        assert report["written"].endswith("_internal_error.mcap")
        assert report["messages"] > 0


def _children(pid: int) -> list[int]:
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            with contextlib.suppress(OSError, IndexError):
                text = (entry / "stat").read_text()
                if int(text[text.rindex(")") + 2 :].split()[1]) == pid:
                    found.append(int(entry.name))
    return found


async def test_serve_stops_its_flight_recorder_on_ctrl_c(tmp_path: Path) -> None:
    config = tmp_path / "cell.yaml"
    config.write_text(TWO_MOCKS + f"record: {{ring_s: 5, dir: {tmp_path / 'flight'}}}\n")
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    argv = [sys.executable, "-m", "urdaemon", "serve", "--config", str(config), "--listen", endpoint]
    proc = subprocess.Popen(argv, stderr=subprocess.PIPE, text=True)
    try:
        await wait_for_line(proc, "flight recorder of 'testcell'", timeout=READY_S)
        [child] = _children(proc.pid)
        proc.send_signal(signal.SIGINT)
        lines: list[str] = []
        drain_in_background(proc, lines)
        assert await asyncio.to_thread(proc.wait, 30) == 0, "".join(lines)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert child not in _children(1) + _children(proc.pid), "the flight recorder ended with the daemon"
    assert _files(tmp_path / "flight") == [], "no file: nothing went wrong"


def _files(directory: Path) -> list[str]:
    return sorted(os.listdir(directory)) if directory.is_dir() else []


async def test_a_directory_the_daemon_cannot_write_stops_it_at_start(tmp_path: Path) -> None:
    blocked = tmp_path / "file"
    blocked.write_text("not a directory")
    text = TWO_MOCKS + f"record: {{dir: {blocked / 'flight'}}}\n"
    with pytest.raises(ConfigError, match=f"record.dir: cannot make {blocked / 'flight'}: Not a directory"):
        async with running_daemon(text):
            pass
