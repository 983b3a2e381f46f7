"""The pure parts of list, info and echo: tables, verdicts on silent keys, field picking, thinning."""

from __future__ import annotations

import re
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from urdaemon.introspect.echo import FieldMissing, Thinner, pick_field
from urdaemon.introspect.sampling import HOST_TIME, RECEIVE_TIME, KeyTimes, message_time_ns
from urdaemon.introspect.silence import explain
from urdaemon.introspect.survey import Survey, find_robot
from urdaemon.introspect.tables import align, duration_text, info_lines, lease_text, list_lines

S = 1_000_000_000


def _robot(cell: str, name: str, **over: Any) -> dict[str, Any]:
    base = f"{cell}/{name}"
    robot: dict[str, Any] = {
        "name": name,
        "backend": "mock",
        "model": "ur5e",
        "rate_hz": 500.0,
        "lifecycle": "running",
        "reason": "",
        "lease": None,
        "publish_rates_hz": {"joint_states": 500.0, "status": 2.0, "io": 10.0},
        "keys": {
            "published": [f"{base}/joint_states", f"{base}/status", f"{base}/io", f"{base}/events"],
            "queryables": [f"{base}/lease", f"{base}/service/stop"],
            "subscribed": [f"{base}/command/twist"],
            "liveliness": [f"{base}/alive"],
        },
        "ports": None,
        "calibration": {"file": None, "expected_hash": None},
        "calibration_ok": None,
        "controller_version": None,
        "tcp": {"link": f"{name}_tool0", "pose": [0.0] * 6},
        "tcp_configured": [0.0] * 6,
        "joint_limits": {
            "names": [f"{name}_j1"],
            "min_position": [-3.0],
            "max_position": [3.0],
            "max_velocity": [2.0],
            "max_acceleration": [5.0],
        },
    }
    robot.update(over)
    return robot


def _daemon(cell: str, *robots: dict[str, Any]) -> dict[str, Any]:
    return {
        "cell": cell,
        "host": "box",
        "pid": 42,
        "version": "9.9",
        "started_at_ns": 0,
        "host_time_ns": 125 * S,
        "listen": ["tcp/127.0.0.1:7447"],
        "keys": {"published": [f"{cell}/tf", f"{cell}/goal/*/*"], "queryables": [f"{cell}/daemon"]},
        "robots": list(robots),
    }


TWO_CELLS = Survey(
    daemons={
        "north": _daemon(
            "north", _robot("north", "alice", lease={"holder": "ops", "since": 0}), _robot("north", "bob")
        ),
        "south": _daemon(
            "south", _robot("south", "alice", backend="ur", model="ur10e", lifecycle="connecting")
        ),
    },
    alive=[("north", "alice"), ("north", "bob"), ("south", "alice"), ("west", "carol")],
)


def test_list_shows_every_cell_with_its_daemon_and_robots() -> None:
    assert list_lines(TWO_CELLS) == [
        "cell north: urdaemon 9.9 on box (pid 42), up 2m05s, listening on tcp/127.0.0.1:7447",
        "  ROBOT  BACKEND  MODEL  RATE_HZ  LIFECYCLE  LEASE",
        "  alice  mock     ur5e   500      running    ops",
        "  bob    mock     ur5e   500      running    -",
        "cell south: urdaemon 9.9 on box (pid 42), up 2m05s, listening on tcp/127.0.0.1:7447",
        "  ROBOT  BACKEND  MODEL  RATE_HZ  LIFECYCLE   LEASE",
        "  alice  ur       ur10e  500      connecting  -",
        "cell west: no answer on west/daemon (a daemon older than this command, or this session may not "
        "read it)",
        "  ROBOT  BACKEND  MODEL  RATE_HZ  LIFECYCLE  LEASE",
        "  carol  ?        ?      ?        ?          ?",
    ]


def test_list_of_nothing_says_so() -> None:
    assert list_lines(Survey()) == ["nothing reachable: no daemon answered and no robot is alive"]


def test_a_robot_the_daemon_names_without_a_token_is_marked() -> None:
    found = Survey(daemons={"c": _daemon("c", _robot("c", "alice"))}, alive=[])
    assert "running (no liveliness token)" in "\n".join(list_lines(found))


@pytest.mark.parametrize(
    ("name", "cell", "answer"),
    [
        ("bob", None, ("north", None)),
        ("carol", None, ("west", None)),
        ("alice", "south", ("south", None)),
        (
            "alice",
            None,
            ("", "robot 'alice' is served in several cells (north, south); name one with --cell"),
        ),
        ("dave", None, ("", "no robot 'dave'; robots: north/alice, north/bob, south/alice, west/carol")),
        (
            "bob",
            "south",
            ("", "no robot 'bob' in cell 'south'; robots: north/alice, north/bob, south/alice, west/carol"),
        ),
    ],
)
def test_find_robot(name: str, cell: str | None, answer: tuple[str, str | None]) -> None:
    assert find_robot(TWO_CELLS, name, cell) == answer


@pytest.mark.parametrize(
    ("key", "published", "text"),
    [
        ("north/alice/joint_states", True, "still waiting: it is published as north/alice/joint_states"),
        ("north/*/status", True, "north/alice/status, north/bob/status"),
        ("north/carol/joint_states", False, "no robot 'carol' in cell north; robots: alice, bob"),
        (
            "north/alice/joint_state",
            False,
            "robot 'alice' publishes no such key; its keys: joint_states, status, io, events",
        ),
        ("east/alice/status", False, "no cell 'east' is reachable; cells: north, south, west"),
        ("west/carol/status", True, "no answer on west/daemon to tell whether anything publishes on it"),
        ("north/tff", False, "no robot 'tff' in cell north"),
        ("*/nobody/status", False, "no daemon reachable publishes on it; cells: north, south, west"),
        ("north/tf", True, "published as north/tf"),
        ("north/goal/g1/result", True, "published as north/goal/*/*"),
    ],
)
def test_a_silent_key_is_explained(key: str, published: bool, text: str) -> None:
    verdict = explain(key, TWO_CELLS, 3.0)
    assert verdict.published is published
    assert verdict.text.startswith(f"nothing on {key} within 3 s")
    assert text in verdict.text


@pytest.mark.parametrize(
    ("path", "value"),
    [("position", [1.0, 2.0]), ("position.1", 2.0), ("lease.holder", "ops"), ("tcp.pose.0", 0.5)],
)
def test_pick_field(path: str, value: object) -> None:
    message = {"position": [1.0, 2.0], "lease": {"holder": "ops"}, "tcp": {"pose": [0.5]}}
    assert pick_field(message, path) == value


@pytest.mark.parametrize(
    ("path", "error"),
    [
        ("positions", "no field 'positions' in the message (its fields: position, lease)"),
        ("lease.owner", "no field 'owner' in lease (its fields: holder)"),
        ("position.2", "field 'position.2': position has 2 items"),
        ("position.x", "no field 'x' in position (a list of 2: index it by number)"),
        ("lease.holder.name", "no field 'name' in lease.holder (a str, no fields)"),
    ],
)
def test_pick_field_names_what_is_missing_and_what_there_is(path: str, error: str) -> None:
    with pytest.raises(FieldMissing) as caught:
        pick_field({"position": [1.0, 2.0], "lease": {"holder": "ops"}}, path)
    assert str(caught.value) == error


def test_thinning_a_500_hz_stream_to_10_hz_passes_10_a_second_of_each_key() -> None:
    thinner = Thinner(10.0)
    passed = {"a": 0, "b": 0}
    for i in range(1000):  # 2 s at 500 Hz, two keys
        for key in passed:
            passed[key] += thinner.passes(key, i * 0.002)
    assert passed == {"a": 20, "b": 20}
    assert all(Thinner(None).passes("a", 0.0) for _ in range(3))


@given(rate=st.floats(min_value=0.5, max_value=400.0), period=st.floats(min_value=1e-4, max_value=0.5))
def test_thinning_never_passes_more_than_the_rate(rate: float, period: float) -> None:
    thinner = Thinner(rate)
    duration = 4.0
    steps = min(int(duration / period), 20_000)
    passed = sum(thinner.passes("k", i * period) for i in range(steps))
    assert passed <= rate * steps * period + 1 + 1e-9


@pytest.mark.parametrize(
    ("payload", "expected"),
    [
        (b'{"host_time_ns": 12}', 12),
        (b'{"host_time_ns": 1.5}', None),
        (b'{"host_time_ns": true}', None),
        (b'{"other": 1}', None),
        (b"[1]", None),
        (b"\xff", None),
        (b"not json", None),
    ],
)
def test_message_time(payload: bytes, expected: int | None) -> None:
    assert message_time_ns(payload) == expected


def test_a_key_falls_back_to_receive_times_once_a_message_lacks_its_own() -> None:
    times = KeyTimes()
    times.add(10, b'{"host_time_ns": 1}')
    times.add(20, b'{"host_time_ns": 3}')
    assert times.source == HOST_TIME
    times.add(30, b"{}")
    assert times.source == RECEIVE_TIME
    assert times.count == 3
    stats = times.times.stats()
    assert stats is not None
    assert stats.periods == 2


def test_info_lines_carry_every_fact() -> None:
    robot = _robot(
        "south",
        "alice",
        backend="ur",
        controller_version={
            "project": "URControl",
            "major": 5,
            "minor": 15,
            "bugfix": 0,
            "build": 0,
            "date": "d",
        },
        ports={
            "address": "10.0.0.2",
            "controller": {"primary": 30001},
            "callbacks": {"reverse": 50001},
        },
        calibration={"file": "cal.yaml", "expected_hash": "abc"},
        calibration_ok=False,
        lease={"holder": "ops", "since": 0, "fingerprint": "f00"},
    )
    text = "\n".join(
        info_lines(
            "south",
            robot,
            TWO_CELLS.daemons["south"],
            {"south/alice/joint_states": (499.5, 500, HOST_TIME)},
            1,
        )
    )
    for part in (
        "robot alice in cell south",
        "URControl 5.15.0 (build 0, d)",
        "cal.yaml; MISMATCH with the robot (expected hash abc)",
        "controller 10.0.0.2: primary 30001; callbacks (this host): reverse 50001",
        "held by ops since 1970-01-01T00:00:00+00:00 (fingerprint f00)",
        "alice_j1  -3.0000  3.0000   2.0000   5.0000",
        "south/alice/joint_states  500 Hz",
        "499.5 Hz (500 message(s), host_time_ns)",
        "on change, >= 2 Hz",
        "on change (looked at 10 Hz), >= 1 Hz",
        "queryables (under south/alice/): lease, service/stop",
    ):
        assert part in text, part
    assert re.search(r"south/alice/events +when it happens +0 message\(s\)", text), text


@pytest.mark.parametrize(
    ("seconds", "text"), [(0.4, "0s"), (42, "42s"), (307, "5m07s"), (3 * 3600 + 125, "3h02m"), (-1, "?")]
)
def test_durations(seconds: float, text: str) -> None:
    assert duration_text(seconds) == text


def test_align_and_lease_text() -> None:
    assert align([["a", "bb"], ["ccc", "d"]]) == ["  a    bb", "  ccc  d"]
    assert align([]) == []
    assert lease_text(None) == "-"
    assert lease_text({"holder": "x"}) == "x"
