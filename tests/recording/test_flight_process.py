"""The flight recorder's process fed from a pipe in-process (``FlightProcess`` with a byte stream as
its stdin): the URDF, samples and a request in, a file out at the pipe's end; a frame that is none
stops it with exit code 1."""

from __future__ import annotations

import argparse
import io
import json
import time
from pathlib import Path

from urdaemon.recording.flight import FlightProcess
from urdaemon.recording.flight_frames import REQUEST, URDF, encode_frame, encode_samples
from urdaemon.recording.mcap_file import read_recording

URDF_TEXT = '<robot name="c"><link name="world"/></robot>'
S = 1_000_000_000


def _args(directory: Path) -> argparse.Namespace:
    return argparse.Namespace(cell="c", dir=str(directory), ring_s=5.0, after_s=0.0, max_mb=64)


def _joint_states(i: int, now: int) -> bytes:
    message = {"v": 1, "robot": "alice", "names": ["j"], "position": [i * 0.001], "host_time_ns": now}
    return json.dumps(message).encode()


def _run(data: bytes, directory: Path) -> tuple[int, list[dict[str, object]]]:
    out = io.StringIO()
    code = FlightProcess(_args(directory), out).run(io.BytesIO(data))
    return code, [json.loads(line) for line in out.getvalue().splitlines()]


def test_a_request_writes_what_the_pipe_brought(tmp_path: Path) -> None:
    now = time.time_ns()
    key = "c/alice/joint_states"
    batches = [
        encode_samples([(key, _joint_states(i, now + i)) for i in range(10 * b, 10 * b + 10)], now)
        for b in range(5)
    ]
    request = encode_frame(REQUEST, "", json.dumps({"reason": "request", "id": "7"}).encode(), now)
    data = encode_frame(URDF, "", URDF_TEXT.encode(), now) + b"".join(batches) + request
    code, said = _run(data, tmp_path)
    assert code == 0
    assert said[0] == {"ready": True}
    [written] = [m for m in said if "written" in m]
    assert written["requests"] == ["7"]
    assert written["reasons"] == ["request"]
    with open(str(written["written"]), "rb") as stream:
        read = list(read_recording(stream))
    states = [r for r in read if r.topic == "/c/alice/joint_states"]
    assert len(states) == 50
    assert [r.message["position"] for r in states] == [[i * 0.001] for i in range(50)]
    assert [r.message for r in read if r.kind is None] == [{"urdf": URDF_TEXT}], "the URDF sent first"


def test_a_file_holds_the_seconds_around_its_trigger_by_the_streams_own_times(tmp_path: Path) -> None:
    """The samples' times are the daemon's, here 1000 s ahead of this process's clock (as they are
    behind it when the pipe lags): the burst ends when the stream reaches its ``after_s``, and the file
    is the ``ring_s`` before the trigger and the ``after_s`` after it, not the ring's last seconds."""
    start = time.time_ns() + 1000 * S
    key = "c/alice/joint_states"
    batches = []
    for b in range(100):  # 10 s of samples, 10 batches of 10 a second
        at = start + b * S // 10
        items = [(key, _joint_states(i, at)) for i in range(10 * b, 10 * b + 10)]
        if b == 0:
            items.insert(0, ("c/alice/status", b'{"lifecycle": "running"}'))
        if b == 50:
            items.append(("c/alice/status", b'{"lifecycle": "protective_stop"}'))  # at 5 s
        batches.append(encode_samples(items, at))
    args = argparse.Namespace(cell="c", dir=str(tmp_path), ring_s=2.0, after_s=1.0, max_mb=64)
    out = io.StringIO()
    assert FlightProcess(args, out).run(io.BytesIO(b"".join(batches))) == 0
    [written] = [m for m in map(json.loads, out.getvalue().splitlines()) if "written" in m]
    assert written["reasons"] == ["protective_stop_alice"]
    with open(str(written["written"]), "rb") as stream:
        times = [r.log_time_ns - start for r in read_recording(stream) if r.topic == "/c/alice/joint_states"]
    assert (min(times), max(times)) == (3 * S, 6 * S), "2 s before the stop at 5 s, 1 s after it"


def test_a_frame_that_is_none_stops_it_with_code_1(tmp_path: Path) -> None:
    now = time.time_ns()
    good = encode_samples([("c/alice/status", b'{"lifecycle": "idle"}')], now)
    code, said = _run(good + b"\x09" + bytes(40), tmp_path)
    assert code == 1
    assert said == [{"ready": True}]
    assert list(tmp_path.iterdir()) == [], "nothing was asked for: no file"


def test_the_pipe_ending_inside_a_frame_ends_it_normally(tmp_path: Path) -> None:
    frame = encode_samples([("c/alice/status", b'{"lifecycle": "idle"}')], time.time_ns())
    code, said = _run(frame + frame[:9], tmp_path)
    assert code == 0
    assert said == [{"ready": True}]
