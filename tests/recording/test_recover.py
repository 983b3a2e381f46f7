"""A recording cut short: recovered up to its last complete chunk (``recover.py``, ``record --recover``),
and a full disk while writing stops the writer with the error kept (``write_loop.py``)."""

from __future__ import annotations

import asyncio
import errno
import io
import json
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader
from mcap.records import Chunk, Message
from mcap.stream_reader import StreamReader, breakup_chunk

from tests.helpers import run_cli
from tests.integration.conftest import TWO_MOCKS, running_daemon
from urdaemon.recording.mcap_file import RecordingWriter
from urdaemon.recording.recover import Recovered, recover, scan
from urdaemon.recording.subscription import Inbox
from urdaemon.recording.write_loop import WriteLoop

T0 = 1_764_000_000_000_000_000
NAMES = [f"alice_j{i}" for i in range(6)]


def _state(i: int) -> bytes:
    message: dict[str, Any] = {
        "robot": "alice",
        "names": NAMES,
        "position": [0.001 * i + j for j in range(6)],
        "velocity": [0.0] * 6,
        "effort": [0.0] * 6,
        "host_time_ns": T0 + 2_000_000 * i,
    }
    return json.dumps(message).encode()


def _status(i: int) -> bytes:
    return json.dumps(
        {"robot": "alice", "lifecycle": "running", "host_time_ns": T0 + 2_000_000 * i + 1}
    ).encode()


def _recording(count: int = 3000) -> bytes:
    buffer = io.BytesIO()
    writer = RecordingWriter(buffer, cell="c", urdf="<robot name='c'/>", chunk_size=8_000)
    for i in range(count):
        writer.add("c/alice/joint_states", _state(i), 0)
        if i % 50 == 0:
            writer.add("c/alice/status", _status(i), 0)
    writer.finish()
    return buffer.getvalue()


def _chunks(data: bytes) -> list[tuple[int, list[tuple[int, int, bytes]]]]:
    """Each chunk's end offset and its messages (channel, log time, data), in file order."""
    out = []
    stream = io.BytesIO(data)
    for record in StreamReader(stream, emit_chunks=True).records:
        if isinstance(record, Chunk):
            messages = [
                (m.channel_id, m.log_time, m.data) for m in breakup_chunk(record) if isinstance(m, Message)
            ]
            out.append((stream.tell(), messages))
    return out


def _messages(data: bytes) -> list[tuple[str, int, bytes]]:
    reader = make_reader(io.BytesIO(data))
    return sorted((c.topic, m.log_time, m.data) for _, c, m in reader.iter_messages(log_time_order=False))


def test_a_file_cut_mid_chunk_keeps_every_message_of_its_whole_chunks() -> None:
    data = _recording()
    chunks = _chunks(data)
    assert len(chunks) > 10
    cut_chunk = len(chunks) // 2
    end_before = chunks[cut_chunk - 1][0]
    cut = (end_before + chunks[cut_chunk][0]) // 2  # halfway into the next chunk
    broken = data[:cut]
    with pytest.raises(Exception):  # noqa: B017,PT011 (any error: the library's readers refuse it)
        make_reader(io.BytesIO(broken)).get_summary()

    fixed = io.BytesIO()
    kept = recover(io.BytesIO(broken), fixed)
    assert not kept.complete
    assert "ends" in kept.stopped, kept.stopped
    expected_count = sum(len(m) for _, m in chunks[:cut_chunk])
    assert kept.messages == expected_count
    assert scan(io.BytesIO(broken)).messages == expected_count

    whole = _messages(data)
    recovered = _messages(fixed.getvalue())
    assert len(recovered) == expected_count
    assert set(recovered) <= set(whole)
    latest = max(t for _, t, _ in recovered)
    assert [m for m in whole if m[1] <= latest and m[0].endswith("joint_states")] == [
        m for m in recovered if m[0].endswith("joint_states")
    ], "no joint state before the last recovered one is missing"
    attachments = list(make_reader(io.BytesIO(fixed.getvalue())).iter_attachments())
    assert [a.name for a in attachments] == ["robot_description.urdf"]


def test_record_recover_command_writes_a_complete_file(tmp_path: Path) -> None:
    data = _recording()
    broken = tmp_path / "broken.mcap"
    broken.write_bytes(data[: len(data) // 2])
    fixed = tmp_path / "fixed.mcap"
    result = run_cli("record", "--recover", str(broken), "-o", str(fixed))
    assert result.code == 0, result.stderr
    kept = scan(io.BytesIO(broken.read_bytes())).messages
    assert f"recovered {kept} messages" in result.stdout
    summary = make_reader(fixed.open("rb")).get_summary()
    assert summary is not None
    assert summary.statistics is not None
    assert summary.statistics.message_count == kept > 0


def test_recovering_a_file_that_is_not_mcap_fails_saying_so(tmp_path: Path) -> None:
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not an mcap file at all")
    result = run_cli("record", "--recover", str(junk), "-o", str(tmp_path / "out.mcap"))
    assert result.code == 1
    assert "reading stopped" in result.stdout
    assert "magic" in result.stdout


class FullDisk(io.RawIOBase):
    """A file whose disk fills up: every write after the first ``room`` bytes raises ENOSPC."""

    def __init__(self, room: int) -> None:
        self.data = bytearray()
        self.room = room

    def writable(self) -> bool:
        return True

    def tell(self) -> int:
        return len(self.data)

    def write(self, data: Any) -> int:
        if len(self.data) + len(data) > self.room:
            raise OSError(errno.ENOSPC, "No space left on device")
        self.data += data
        return len(data)


def test_a_full_disk_stops_the_writer_and_keeps_the_error() -> None:
    disk = FullDisk(room=30_000)
    inbox = Inbox()
    writer = RecordingWriter(disk, cell="c", chunk_size=4_000)  # type: ignore[arg-type]
    loop = WriteLoop(inbox, writer, flush_s=3600.0)
    for i in range(5000):
        inbox.offer("c/alice/joint_states", _state(i), 0)
    loop.start()
    loop.stop(timeout=30.0)
    assert not loop.alive
    assert loop.error is not None
    assert loop.error.errno == errno.ENOSPC
    kept = scan(io.BytesIO(bytes(disk.data)))
    assert 0 < kept.messages < 5000, kept


async def test_a_recorder_killed_outright_leaves_a_file_that_recovers(tmp_path: Path) -> None:
    """``urdaemon record`` in a process of its own, killed with SIGKILL once its file holds a chunk:
    the file is recovered up to its last whole chunk, every message in it readable."""
    async with running_daemon(TWO_MOCKS) as (daemon, _client):
        out = tmp_path / "killed.mcap"
        argv = [sys.executable, "-m", "urdaemon", "record", "--connect", daemon.listen_endpoints[0]]
        proc = subprocess.Popen([*argv, "-o", str(out), "--duration", "120"], stderr=subprocess.DEVNULL)
        try:
            for _ in range(600):  # the first chunk ends 2 s after the start (60 s at most)
                if out.exists() and scan_file(out).messages > 0:
                    break
                await asyncio.sleep(0.1)
        finally:
            proc.kill()
            proc.wait(10)
    assert proc.returncode == -signal.SIGKILL
    kept = scan_file(out)
    assert kept.messages > 0
    assert not kept.complete
    fixed = tmp_path / "fixed.mcap"
    result = run_cli("record", "--recover", str(out), "-o", str(fixed))
    assert result.code == 0, result.stderr
    messages = _messages(fixed.read_bytes())
    assert len(messages) == kept.messages
    assert any(topic == "/testcell/alice/joint_states" for topic, _, _ in messages)


def scan_file(path: Path) -> Recovered:
    with path.open("rb") as stream:
        return scan(stream)
