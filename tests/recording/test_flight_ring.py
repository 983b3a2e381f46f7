"""The flight recorder's pure parts from tables: the ring's bounds, the triggers read from the stream,
the bursts (one file per incident), the file's name."""

from __future__ import annotations

import json

import pytest

from urdaemon.recording.flight_ring import ITEM_OVERHEAD, STREAM_WAIT_S, Bursts, Ring, Triggers, file_name

S = 1_000_000_000


def test_the_ring_keeps_the_last_seconds() -> None:
    ring = Ring(seconds=2.0, max_bytes=10**9)
    for i in range(50):
        ring.add("c/a/joint_states", b"x", i * S // 10)  # 10 per second for 5 s
    times = [t for _, _, t in ring.snapshot()]
    assert times[0] == 49 * S // 10 - 2 * S
    assert times[-1] == 49 * S // 10
    assert ring.size == len(times) * (len("c/a/joint_states") + 1 + ITEM_OVERHEAD)
    assert ring.dropped_for_size == 0


def test_a_window_is_what_came_since_its_start() -> None:
    ring = Ring(seconds=10.0, max_bytes=10**9)
    assert ring.newest_ns == 0
    for i in range(10):
        ring.add("k", b"x", i * S)
    assert [t for _, _, t in ring.snapshot(7 * S)] == [7 * S, 8 * S, 9 * S]
    assert len(ring.snapshot()) == 10, "the window takes a copy: the ring keeps everything"
    assert ring.newest_ns == 9 * S


def test_the_ring_drops_the_oldest_beyond_its_bytes() -> None:
    each = len("k") + 100 + ITEM_OVERHEAD
    ring = Ring(seconds=60.0, max_bytes=10 * each)
    for i in range(25):
        ring.add("k", bytes(100), i)
    assert [t for _, _, t in ring.snapshot()] == list(range(15, 25))
    assert ring.size == 10 * each
    assert ring.dropped_for_size == 15


def _status(lifecycle: str) -> bytes:
    return json.dumps({"robot": "alice", "lifecycle": lifecycle}).encode()


def _result(status: str) -> bytes:
    return json.dumps({"goal_id": "g", "status": status}).encode()


@pytest.mark.parametrize(
    ("stream", "reasons"),
    [
        (["connecting", "idle", "running", "protective_stop"], [None, None, None, "protective_stop_alice"]),
        (["running", "emergency_stop", "emergency_stop"], [None, "emergency_stop_alice", None]),
        (["idle", "disconnected"], [None, "lost_link_alice"]),
        (["running", "recovering", "disconnected"], [None, "lost_link_alice", None]),
        (["disconnected", "connecting", "disconnected"], [None, None, None]),  # never connected
        (["protective_stop"], ["protective_stop_alice"]),
    ],
)
def test_status_lifecycles_that_trigger(stream: list[str], reasons: list[str | None]) -> None:
    triggers = Triggers()
    assert [triggers.check("c/alice/status", _status(s)) for s in stream] == reasons


@pytest.mark.parametrize(
    ("key", "payload", "reason"),
    [
        ("c/alice/goal/g/result", _result("aborted"), "aborted_alice"),
        ("c/goal/g/result", _result("aborted"), "aborted_cell_goal"),
        ("c/alice/goal/g/result", _result("succeeded"), None),
        ("c/alice/goal/g/result", _result("canceled"), None),
        ("c/alice/goal/g/feedback", _result("aborted"), None),
        ("c/alice/joint_states", b"{}", None),
        ("c/alice/status", b"not json", None),
        ("c/alice/status", b"[1]", None),
    ],
)
def test_results_and_other_keys(key: str, payload: bytes, reason: str | None) -> None:
    assert Triggers().check(key, payload) == reason


def test_a_burst_is_written_after_its_seconds_after_and_gathers_what_came_meanwhile() -> None:
    bursts = Bursts(after_s=1.0, quiet_s=10.0)
    bursts.trigger("aborted_alice", 100 * S)
    bursts.trigger("protective_stop_alice", 100 * S + 5)
    bursts.trigger("request", 100 * S + 6, request="7")
    assert bursts.due(100 * S + S - 1, 100 * S + S - 1) is None
    burst = bursts.due(101 * S, 101 * S)
    assert burst is not None
    assert (burst.first_ns, burst.reasons, burst.requests) == (
        100 * S,
        ["aborted_alice", "protective_stop_alice", "request"],
        ["7"],
    )
    assert burst.reason == "protective_stop_alice", "the file is named after the gravest reason"
    assert bursts.due(200 * S, 200 * S) is None


def test_stream_triggers_of_the_same_incident_make_no_second_file_but_requests_do() -> None:
    bursts = Bursts(after_s=1.0, quiet_s=10.0)
    bursts.trigger("protective_stop_alice", 0)
    assert bursts.due(1 * S, 1 * S) is not None
    bursts.trigger("lost_link_alice", 5 * S)  # 5 s after: the same incident
    assert bursts.open is None
    assert bursts.merged == 1
    bursts.trigger("lost_link_alice", 14 * S)  # 9 s after the one before: still the same incident
    assert bursts.open is None
    assert bursts.merged == 2
    bursts.trigger("request", 15 * S, request="1")  # a request always gets a file
    burst = bursts.due(16 * S, 16 * S)
    assert burst is not None
    assert burst.requests == ["1"]
    bursts.trigger("protective_stop_alice", 40 * S)  # quiet long enough: a new incident
    assert bursts.open is not None


def test_a_file_is_named_with_the_cell_the_time_and_the_reason() -> None:
    first = 1_795_000_000 * S + 123_456_789
    assert file_name("demo_cell", first, "protective_stop_alice") == (
        "demo_cell_20261118-110640.123_protective_stop_alice.mcap"
    )
    assert file_name("c", 0, "../../x y") == "c_19700101-000000.000_x_y.mcap"


WAIT = int(STREAM_WAIT_S * S)


@pytest.mark.parametrize(
    ("stream_ns", "now_ns", "due"),
    [
        (100 * S + S - 1, 100 * S + S, False),  # the wall clock is there, the stream not yet
        (101 * S, 90 * S, True),  # the stream is there: the wall clock does not matter
        (100 * S, 101 * S + WAIT - 1, False),  # the stream lags: it waits for it...
        (100 * S, 101 * S + WAIT, True),  # ...but not for ever (the stream stopped)
    ],
)
def test_a_burst_ends_when_the_stream_gets_there_or_a_wait_later(
    stream_ns: int, now_ns: int, due: bool
) -> None:
    bursts = Bursts(after_s=1.0, quiet_s=10.0)
    bursts.trigger("protective_stop_alice", 100 * S)
    assert (bursts.due(stream_ns, now_ns) is not None) is due
