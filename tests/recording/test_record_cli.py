"""``urdaemon record`` against a mock cell served in the test's loop: the file read back with the mcap
library's reader and compared with what the test itself received on the same keys; the ``--ros2``
bag read with rosbags; and bad input (an unwritable path, a ``--key`` that matches nothing)."""

from __future__ import annotations

import asyncio
import errno
import io
import json
import signal
import subprocess
import sys
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import pytest
import zenoh
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader

from tests.helpers import run_cli, run_cli_in_thread
from tests.integration.conftest import TWO_MOCKS, running_daemon
from urdaemon.client import Client
from urdaemon.daemon import Daemon
from urdaemon.recording import record_command
from urdaemon.recording.channels import recorded_keys
from urdaemon.recording.mcap_file import URDF_ATTACHMENT, key_of, read_recording
from urdaemon.recording.output import Output
from urdaemon.recording.recover import scan

pytestmark = pytest.mark.timeout(120)

TARGET = [0.4, -1.2, 1.3, -1.6, -1.4, 0.3]


@pytest.fixture
async def cell() -> AsyncIterator[tuple[Daemon, Client, str]]:
    async with running_daemon(TWO_MOCKS) as (daemon, client):
        yield daemon, client, daemon.listen_endpoints[0]


class Heard:
    """Every message the daemon publishes on the recorded keys, decoded, by key (after ``close``).

    The subscribers are the daemon's own session's, each filling a Zenoh FIFO channel: a put reaches
    a subscriber of its own session without a link, so nothing is dropped on the way, and the
    channel is filled on Zenoh's side without Python. A subscriber of another session is no
    reference: the daemon's state publishers drop a sample rather than wait when a link's queue is
    full, which on a loaded machine happens on every link, the recorder's and a test client's alike
    (``complete`` checks that none was lost here).
    """

    CAPACITY = 1_000_000

    def __init__(self, daemon: Daemon) -> None:
        assert daemon.node is not None
        self.by_key: dict[str, list[dict[str, Any]]] = {}
        self._subs = [
            daemon.node.session.declare_subscriber(k, zenoh.handlers.FifoChannel(self.CAPACITY))
            for k in recorded_keys("testcell")
        ]

    def close(self) -> None:
        """Take everything received so far, then stop receiving."""
        for sub in self._subs:
            for _ in range(self.CAPACITY):
                sample = sub.try_recv()
                if sample is None:
                    break
                message = json.loads(sample.payload.to_bytes())
                self.by_key.setdefault(str(sample.key_expr), []).append(message)
            sub.undeclare()

    def complete(self, robot: str) -> bool:
        """Whether the robot's joint states heard carry every cycle from the first to the last."""
        cycles = [m["cycle"] for m in self.by_key[f"testcell/{robot}/joint_states"]]
        return cycles == list(range(cycles[0], cycles[0] + len(cycles)))


def _same_links(heard: dict[str, Any], recorded: dict[str, Any]) -> bool:
    """Every link of the heard tf but its root frame is in the recorded one, at the same pose."""
    links = {name: pose for name, pose in heard["links"].items() if name != heard["frame"]}
    return links.keys() == recorded["links"].keys() and all(
        max(abs(a - b) for a, b in zip(pose, recorded["links"][name], strict=True)) < 1e-9
        for name, pose in links.items()
    )


def _compare(recorded: dict[str, Any], heard: list[dict[str, Any]], kind: str) -> str:
    """``same`` when ``recorded`` (read back from the file) is one of the messages heard on its key,
    ``differs`` when one heard has its time but other values, ``absent`` when none has its time."""
    if kind == "tf":  # recorded per URDF joint, read back composed into world poses again
        return "same" if any(_same_links(h, recorded) for h in heard) else "absent"
    if kind not in ("joint_states", "tcp_pose"):
        return "same" if recorded in heard else "absent"
    fields: tuple[str, ...] = ("names", "position", "velocity", "effort")
    if kind == "tcp_pose":
        fields = ("position", "orientation")
    at_time = [h for h in heard if h["host_time_ns"] == recorded["host_time_ns"]]
    if not at_time:
        return "absent"
    return "same" if any(all(h[f] == recorded[f] for f in fields) for h in at_time) else "differs"


async def test_a_recording_holds_every_message_published_while_it_ran(
    cell: tuple[Daemon, Client, str], tmp_path: Path
) -> None:
    daemon, client, endpoint = cell
    heard = Heard(daemon)
    out = tmp_path / "run.mcap"
    recording = run_cli_in_thread("record", "--connect", endpoint, "-o", str(out), "--duration", "4")
    alice = await client.robot("alice")
    goal = await alice.move(TARGET, duration=5.0)
    result = await recording
    heard.close()
    await goal.result(timeout=30.0)
    assert result.code == 0, result.stderr
    assert "dropped 0" in result.stderr, result.stderr
    assert heard.complete("alice"), "the reference heard every joint state alice published"
    assert heard.complete("bob"), "the reference heard every joint state bob published"

    with out.open("rb") as stream:
        read = list(read_recording(stream))
    urdf = [r for r in read if r.kind is None]
    assert [r.message["urdf"] for r in urdf] == [daemon.description.urdf]
    kinds: dict[str, int] = {}
    for record in read:
        if record.kind is None:
            continue
        key = key_of(record.topic, record.message)
        kinds[record.kind.name] = kinds.get(record.kind.name, 0) + 1
        # every message recorded was published, as it was published
        outcome = _compare(record.message, heard.by_key.get(key, []), record.kind.name)
        assert outcome == "same", (outcome, key, record.message)
    assert {"joint_states", "tcp_pose", "status", "tf", "goal_feedback"} <= set(kinds), kinds

    # the recording holds what was published while it ran: of alice's joint states published between
    # the first and the last recorded, all but a few per thousand (what Zenoh drops on the recorder's
    # link rather than wait: the daemon's state publishers never block) are there
    times = [r.message["host_time_ns"] for r in read if r.topic == "/testcell/alice/joint_states"]
    first, last = min(times), max(times)
    published = {m["host_time_ns"] for m in heard.by_key["testcell/alice/joint_states"]}
    window = {t for t in published if first <= t <= last}
    assert len(times) == len(set(times))
    assert len(window - set(times)) <= len(window) // 100, (len(window), len(window - set(times)))
    positions = {tuple(r.message["position"]) for r in read if r.topic == "/testcell/alice/joint_states"}
    assert len(positions) > 100, "alice moved while recorded"

    with out.open("rb") as stream:
        reader = make_reader(stream)
        for _schema, _channel, message in reader.iter_messages(topics=["/testcell/alice/joint_states"]):
            assert message.log_time == message.publish_time
        assert [a.name for a in reader.iter_attachments()] == [URDF_ATTACHMENT]


async def test_a_ros2_bag_reads_with_rosbags(cell: tuple[Daemon, Client, str], tmp_path: Path) -> None:
    _, _, endpoint = cell
    bag = tmp_path / "bag"
    result = await run_cli_in_thread(
        "record", "--connect", endpoint, "--ros2", "-o", str(bag), "--robot", "bob", "--duration", "2"
    )
    assert result.code == 0, result.stderr
    assert sorted(p.name for p in bag.iterdir()) == ["bag_0.mcap", "metadata.yaml"]
    seen: dict[str, list[Any]] = {}
    with AnyReader([bag]) as reader:
        for connection, timestamp, raw in reader.messages():
            message = reader.deserialize(raw, connection.msgtype)
            seen.setdefault(connection.topic, []).append((timestamp, message))
    assert set(seen) == {
        "/testcell/bob/joint_states",
        "/testcell/bob/tcp_pose",
        "/testcell/tf",
        "/robot_description",
    }
    states = seen["/testcell/bob/joint_states"]
    assert len(states) > 100  # bob publishes at 125 Hz
    assert states[0][1].name == [f"bob_{j}" for j in _UR_JOINTS]
    for timestamp, message in states:
        assert message.header.stamp.sec * 10**9 + message.header.stamp.nanosec == timestamp
    assert "<robot" in seen["/robot_description"][0][1].data


_UR_JOINTS = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)


async def test_a_key_that_matches_nothing_is_named_with_what_publishes(
    cell: tuple[Daemon, Client, str], tmp_path: Path
) -> None:
    _, _, endpoint = cell
    out = tmp_path / "k.mcap"
    result = await run_cli_in_thread(
        "record", "--connect", endpoint, "-o", str(out), "--key", "alice/joint_statez", "--duration", "4"
    )
    assert result.code == 0, result.stderr
    assert "warning: --key testcell/alice/joint_statez matched nothing" in result.stderr, result.stderr
    assert "testcell/alice/joint_states" in result.stderr.split("matched nothing", 1)[1]


async def test_an_unknown_robot_or_cell_is_refused_naming_what_is_served(
    cell: tuple[Daemon, Client, str], tmp_path: Path
) -> None:
    _, _, endpoint = cell
    out = tmp_path / "r.mcap"
    result = await run_cli_in_thread("record", "--connect", endpoint, "-o", str(out), "--robot", "carol")
    assert result.code == 2
    assert "no robot 'carol' in cell 'testcell'; its robots: alice, bob" in result.stderr
    assert not out.exists()
    result = await run_cli_in_thread("record", "--connect", endpoint, "-o", str(out), "--cell", "other")
    assert result.code == 2
    assert "no cell 'other' is served" in result.stderr
    assert "served: testcell" in result.stderr


async def test_asking_a_cell_without_a_flight_recorder_says_so(cell: tuple[Daemon, Client, str]) -> None:
    _, _, endpoint = cell
    result = await run_cli_in_thread("record", "--flight", "--connect", endpoint)
    assert result.code == 1
    assert "error: cell 'testcell' has no flight recorder (no 'record' in its cell file)" in result.stderr


def test_an_unwritable_path_is_named(tmp_path: Path) -> None:
    target = tmp_path / "missing" / "x.mcap"
    result = run_cli("record", "-o", str(target), "--duration", "1")
    assert result.code == 2
    assert f"error: cannot write {target}: No such file or directory" in result.stderr


def test_an_existing_bag_directory_is_refused(tmp_path: Path) -> None:
    result = run_cli("record", "--ros2", "-o", str(tmp_path), "--duration", "1")
    assert result.code == 2
    assert f"cannot write {tmp_path}: the bag directory exists" in result.stderr


class FillingDisk(io.RawIOBase):
    """A file on a disk that fills up after the recorder's first chunk: every later write raises
    ENOSPC (what a full disk does), what was written before stays in the file."""

    def __init__(self, path: Path) -> None:
        super().__init__()
        self._file = path.open("wb")
        self.chunks = 0

    def writable(self) -> bool:
        return True

    def tell(self) -> int:
        return self._file.tell()

    def write(self, data: Any) -> int:
        if self.chunks:
            raise OSError(errno.ENOSPC, "No space left on device")
        written = self._file.write(data)
        self.chunks += bytes(data[:1]) == b"\x06"  # a chunk record's opcode: not the header, nor the URDF
        self._file.flush()
        return written

    def close(self) -> None:
        self._file.close()
        super().close()


async def test_a_full_disk_stops_the_recording_and_says_how_much_was_kept(
    cell: tuple[Daemon, Client, str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    _, _, endpoint = cell
    out = tmp_path / "full.mcap"
    monkeypatch.setattr(
        record_command,
        "open_output",
        lambda target, ros2: Output(target, FillingDisk(target)),  # type: ignore[arg-type]
    )
    result = await run_cli_in_thread("record", "--connect", endpoint, "-o", str(out), "--duration", "60")
    assert result.code == 1, result.stderr
    with out.open("rb") as stream:
        kept = scan(stream)
    assert kept.messages > 0
    assert f"error: writing {out} failed (the disk is full) after " in result.stderr
    assert f"The file holds the {kept.messages} messages of its complete chunks" in result.stderr
    assert f"urdaemon record --recover {out} -o " in result.stderr


async def test_ctrl_c_ends_the_file_cleanly(cell: tuple[Daemon, Client, str], tmp_path: Path) -> None:
    _, _, endpoint = cell
    out = tmp_path / "interrupted.mcap"
    argv = [sys.executable, "-m", "urdaemon", "record", "--connect", endpoint, "-o", str(out)]
    proc = subprocess.Popen(argv, stderr=subprocess.PIPE, text=True)
    try:
        for _ in range(600):  # until its first chunk is in the file (60 s at most)
            if out.exists() and _scan(out).messages > 0:
                break
            await asyncio.sleep(0.1)
        proc.send_signal(signal.SIGINT)
        _, stderr = await asyncio.to_thread(proc.communicate, timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, stderr
    assert "recorded " in stderr
    assert "dropped 0" in stderr
    with out.open("rb") as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None
    assert summary.statistics is not None
    assert summary.statistics.message_count >= _scan(out).messages > 0


def _scan(path: Path) -> Any:
    with path.open("rb") as stream:
        return scan(stream)
