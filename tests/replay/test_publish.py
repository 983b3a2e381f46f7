"""``urdaemon replay FILE --publish``: the recorded messages arrive on their keys with their recorded
content, in order, no faster than recorded ÷ rate; the robots' liveliness tokens and the URDF are
there for a viewer, a lease is refused naming the recording; a cell a daemon serves is refused.

The command runs in a thread of its own (``run_cli_in_thread``) and listens on an OS-chosen port;
the test's raw Zenoh session connects there.
"""

from __future__ import annotations

import asyncio
import io
import json
from pathlib import Path
from typing import Any

import pytest
import zenoh

from tests.helpers import free_tcp_port, run_cli_in_thread, zenoh_ask
from tests.integration.conftest import TWO_MOCKS, running_daemon
from urdaemon.publish.session_config import zenoh_config
from urdaemon.recording.mcap_file import RecordingWriter

pytestmark = pytest.mark.timeout(120)

CELL = "testcell"
T0 = 1_764_000_000_000_000_000
URDF = '<robot name="testcell"><link name="world"/></robot>'
NAMES = [f"alice_j{i}" for i in range(6)]
STEP_NS = 20_000_000
"""20 ms between two recorded joint states."""


def _published() -> list[tuple[str, dict[str, Any]]]:
    out: list[tuple[str, dict[str, Any]]] = []
    for i in range(10):
        out.append(
            (
                f"{CELL}/alice/joint_states",
                {
                    "robot": "alice",
                    "names": NAMES,
                    "position": [0.1 * i + j for j in range(6)],
                    "velocity": [0.01 * j for j in range(6)],
                    "effort": [0.0] * 6,
                    "host_time_ns": T0 + STEP_NS * i,
                },
            )
        )
    out.append((f"{CELL}/alice/status", {"robot": "alice", "lifecycle": "running", "host_time_ns": T0 + 5}))
    out.append(
        (
            f"{CELL}/alice/goal/g1/result",
            {"robot": "alice", "goal_id": "g1", "status": "succeeded", "host_time_ns": T0 + STEP_NS * 9 + 1},
        )
    )
    return out


def _recording(path: Path) -> Path:
    buffer = io.BytesIO()
    writer = RecordingWriter(buffer, cell=CELL, urdf=URDF)
    for key, message in _published():
        assert writer.add(key, json.dumps(message).encode(), 1)
    writer.finish()
    path.write_bytes(buffer.getvalue())
    return path


async def _session(endpoint: str) -> Any:
    """A peer session connected to ``endpoint``, once it reached a peer there (bounded)."""
    loop = asyncio.get_running_loop()
    for _ in range(100):
        session = await loop.run_in_executor(None, zenoh.open, zenoh_config("peer", [], [endpoint]))
        for _ in range(20):
            if list(session.info.peers_zid()):
                return session
            await asyncio.sleep(0.05)
        await loop.run_in_executor(None, session.close)
    raise AssertionError(f"nothing listens at {endpoint}")


async def test_the_recording_is_published_as_recorded_with_what_a_viewer_asks(tmp_path: Path) -> None:
    recording = _recording(tmp_path / "cell.mcap")
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    command = asyncio.create_task(
        run_cli_in_thread(
            "replay", str(recording), "--publish", "--listen", endpoint, "--wait", "--rate", "2"
        )
    )
    session = await _session(endpoint)
    try:
        alive = await asyncio.get_running_loop().run_in_executor(
            None, lambda: [str(r.ok.key_expr) for r in session.liveliness().get(f"{CELL}/*/alive") if r.ok]
        )
        assert alive == [f"{CELL}/alice/alive"]
        urdf = await asyncio.get_running_loop().run_in_executor(
            None,
            lambda: [
                r.ok.payload.to_bytes().decode() for r in session.get(f"{CELL}/robot_description") if r.ok
            ],
        )
        assert urdf == [URDF]
        lease = await zenoh_ask(session, f"{CELL}/alice/lease", {"action": "acquire"})
        assert lease[0]["ok"] is False
        assert "is a recording replayed by `urdaemon replay --publish`" in lease[0]["reason"]
        arrived: list[tuple[str, dict[str, Any], float]] = []
        loop = asyncio.get_running_loop()
        done = asyncio.Event()
        expected = sorted(_published(), key=lambda p: p[1]["host_time_ns"])

        def on_sample(sample: Any) -> None:
            item = (str(sample.key_expr), json.loads(sample.payload.to_bytes()), loop.time())
            loop.call_soon_threadsafe(take, item)

        def take(item: tuple[str, dict[str, Any], float]) -> None:
            arrived.append(item)
            if len(arrived) >= len(expected):
                done.set()

        sub = session.declare_subscriber(f"{CELL}/**", on_sample)
        await asyncio.wait_for(done.wait(), 30)
        sub.undeclare()
        run = await asyncio.wait_for(command, 30)
    finally:
        session.close()
    assert run.code == 0, run.stderr
    assert [key for key, _, _ in arrived] == [key for key, _ in expected]
    for (_, got, _), (_, sent) in zip(arrived, expected, strict=True):
        for field in ("names", "position", "velocity", "lifecycle", "goal_id", "status", "host_time_ns"):
            if field in sent:
                assert got[field] == sent[field], field
    span = arrived[-1][2] - arrived[0][2]
    recorded_span = (expected[-1][1]["host_time_ns"] - expected[0][1]["host_time_ns"]) * 1e-9
    assert span >= 0.9 * recorded_span / 2, (
        f"published over {span:.3f} s, recorded over {recorded_span:.3f} s"
    )


async def test_publishing_over_a_served_cell_is_refused_naming_it(tmp_path: Path) -> None:
    recording = _recording(tmp_path / "cell.mcap")
    async with running_daemon(TWO_MOCKS) as (_daemon, client):
        run = await run_cli_in_thread(
            "replay",
            str(recording),
            "--publish",
            "--connect",
            client.endpoint,
            "--listen",
            f"tcp/127.0.0.1:{free_tcp_port()}",
        )
    assert run.code == 1, run.stderr
    assert "cell 'testcell' is served by a daemon (robots alive: alice, bob" in run.stderr
    assert "publishing" not in run.stderr


async def test_urdaemon_view_shows_a_published_recording(recorded: tuple[Path, Path, Any]) -> None:
    """The view finds the recorded robots, draws the recorded URDF, follows the recorded joint states,
    and refuses to enable a robot, naming the recording."""
    from urdaemon.view.app import running_view

    _config, recording, original = recorded
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    command = asyncio.create_task(
        run_cli_in_thread("replay", str(recording), "--publish", "--listen", endpoint, "--wait", timeout=120)
    )
    positions = {s.positions for s in original.states("alice")}
    async with running_view(endpoint, port=0) as view:
        assert sorted(view.feeds) == ["alice", "bob"]
        seen = 0
        for _ in range(300):
            sample = view.feeds["alice"].joints()
            if sample is not None and sample.positions in positions:
                seen += 1
            if seen >= 20 and view.moves > 0:
                break
            await view.drawn(10.0)
        assert seen >= 20
        assert view.moves > 0
        assert not await view.controls["alice"].enable()
        assert "is a recording replayed by `urdaemon replay --publish`" in view.controls["alice"].refusal
    run = await asyncio.wait_for(command, 60)
    assert run.code == 0, run.stderr
