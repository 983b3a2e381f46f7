"""The benchmark scripts stay runnable: their pure parts (cell files, trajectories, tables) are checked
here; the measurements themselves run only by hand (docs/performance.md), never as timed tests."""

from __future__ import annotations

import math
import sys
from pathlib import Path
from types import ModuleType

import pytest

from tests.helpers import load_benchmark
from urdaemon.cell import parse_cell
from urdaemon.publish.session_config import zenoh_config

ROOT = Path(__file__).resolve().parents[1]


def _load(name: str) -> ModuleType:
    return load_benchmark(name)


@pytest.fixture(scope="module")
def bench() -> ModuleType:
    return _load("control_loop")


def test_generated_cells_are_valid(bench: ModuleType) -> None:
    cell = parse_cell(bench.cell_yaml(3, decimation=5, low_latency=True), base_dir=ROOT)
    assert [r.address for r in cell.robots] == ["127.0.0.5", "127.0.0.6", "127.0.0.7"]
    assert cell.publish.joint_states_decimation == 5
    assert cell.zenoh.low_latency is True
    assert all(r.ur is not None and r.ur.startup for r in cell.robots)
    read_only = parse_cell(bench.cell_yaml(1, read_only=True), base_dir=ROOT)
    assert read_only.robots[0].ur is not None
    assert read_only.robots[0].ur.read_only is True


def test_trajectories_end_at_rest_where_they_started(bench: ModuleType) -> None:
    start = [0.0, -1.57, 1.57, -1.57, -1.57, 0.0]
    points = bench.sinusoid(start, 12.0)
    assert points[-1]["time_from_start"] == pytest.approx(15.0)  # whole periods of 5 s
    assert points[-1]["positions"] == pytest.approx(start, abs=1e-12)
    waypoints = bench.ten_waypoints(start)
    assert len(waypoints) == 10
    assert waypoints[-1]["positions"] == pytest.approx(start)
    times = [p["time_from_start"] for p in waypoints]
    assert times == sorted(times)


def test_planning_times_are_measured_for_the_ten_waypoints(bench: ModuleType) -> None:
    times = bench.planning_times(runs=2)
    assert len(times) == 2
    assert all(t > 0.0 for t in times)


def _row(bench: ModuleType, robots: int, cpu: float, p99: float, missed: int) -> object:
    return bench.Row(
        robots=robots,
        daemon_cpu=cpu,
        fake_cpu=0.1,
        subscriber_cpu=0.05,
        rss_mib=150.0,
        hwm_mib=151.0,
        rate_min=499.0,
        rate_mean=500.0,
        missed=missed,
        late=0,
        goals_active=robots,
        turnaround={"p50_us": 60.0, "p99_us": p99, "p999_us": 900.0, "max_us": 1500.0},
        latency={"samples": 100, "p50_us": 150.0, "p99_us": 600.0},
    )


def test_control_table_judges_each_target(bench: ModuleType) -> None:
    rows = [_row(bench, 1, 0.03, 200.0, 0), _row(bench, 8, 0.8, 200.0, 0)]
    table = bench.control_table(rows, 10.0, "spread", False, 1, False)
    assert "| 1 | 60 / 200 / 900 / 1500 |" in table
    assert "0.030 yes" in table
    assert "0.100 NO" in table  # 0.8 CPU-s/s over 8 robots
    assert "p99.9 < 2 ms over 10 s: yes" in table
    missed = bench.control_table([_row(bench, 8, 0.3, 600.0, 3)], 60.0, "spread", False, 1, False)
    assert "over 60 s: NO" in missed


def test_comparison_table_ratio(bench: ModuleType) -> None:
    comparison = bench.Comparison(
        daemon_cpu=0.03,
        daemon_rss_mib=150.0,
        ur_rtde_cpu=0.15,
        ur_rtde_rss_mib=17.0,
        ur_rtde_variables="ur_rtde's default",
        latency={"p50_us": 120.0},
    )
    assert "ratio urdaemon / ur_rtde: 0.20 (target ≤ 0.25: yes)" in bench.comparison_table(comparison, 10.0)
    tracking = bench.tracking_table(bench.Tracking([0.5, 0.7, 0.6], "succeeded", [1e-6, -2e-6], 6.0))
    assert "median 0.60 ms" in tracking
    assert "final error max |e| = 2.00e-06 rad" in tracking
    assert not math.isnan(float(tracking.split("|e| = ")[1].split(" rad")[0]))


def test_micro_benchmarks_import(bench: ModuleType) -> None:
    floor = _load("event_loop_floor")
    assert len(floor.PACKAGE) == 560
    assert len(floor.REPLY) == 28
    zput = _load("zenoh_put")
    assert zput.zenoh_config is zenoh_config  # the daemon's own session settings, low latency included
    conf = zenoh_config("peer", ["tcp/127.0.0.1:7447"], [], low_latency=True)
    assert (
        conf.get_json("transport/unicast/lowlatency"),
        conf.get_json("transport/unicast/qos/enabled"),
    ) == (
        "true",
        "false",
    )


def test_zenoh_put_measures_the_daemons_own_state_stream_settings_first() -> None:
    import asyncio

    import zenoh

    from tests.helpers import free_tcp_port
    from urdaemon.cell.zenoh_options import ZenohOptions
    from urdaemon.publish.node import ZenohNode

    zput = _load("zenoh_put")
    first = zput.SETTINGS[0]
    assert (first.express, first.real_time_priority, first.drop) == (True, True, True)
    assert (first.low_latency, first.unix) == (False, False)
    assert len({setting.label for setting in zput.SETTINGS}) == len(zput.SETTINGS)
    loop = asyncio.new_event_loop()
    node = ZenohNode(ZenohOptions(listen=(f"tcp/127.0.0.1:{free_tcp_port()}",)), loop)
    try:
        state = node.publisher("bench/state", realtime=True)
        assert (state.congestion_control, state.priority) == (
            zenoh.CongestionControl.DROP,
            zenoh.Priority.REAL_TIME,
        )
    finally:
        node.close()
        loop.close()


@pytest.mark.parametrize("transport", ["loopback TCP", "low latency + Unix socket"])
def test_event_loop_floor_publishes_to_a_subscriber_in_another_process(transport: str) -> None:
    floor = _load("event_loop_floor")
    assert transport in floor.TRANSPORTS
    assert len(floor.SAMPLE) == len(_load("zenoh_put").PAYLOAD)  # the size of a joint_states message
    publishers = floor.Publishers(transport, 2, seconds=1.0)  # returns once both publishers match
    try:
        assert len(publishers.publishers) == 2
        assert all(p.matching_status.matching for p in publishers.publishers)
        for pub in publishers.publishers:
            pub.put(floor.SAMPLE)
    finally:
        assert publishers.close() == 0


@pytest.fixture(scope="module")
def view_cost() -> ModuleType:
    return _load("view_cost")


def test_view_cost_cells_are_valid(view_cost: ModuleType) -> None:
    cell = parse_cell(view_cost.mock_cell_yaml(4), base_dir=ROOT)
    assert [r.name for r in cell.robots] == ["r0", "r1", "r2", "r3"]
    assert [r.model for r in cell.robots] == ["ur10e", "ur3e", "ur10e", "ur3e"]
    assert all(r.backend == "mock" for r in cell.robots)
    assert len({r.pose.xyz for r in cell.robots}) == 4  # nobody stands in another's place
    assert (
        cell.publish.tf_rate_hz
        == parse_cell(view_cost.DEMO_CELL.read_text(), base_dir=ROOT).publish.tf_rate_hz
    )


def test_view_cost_subscribes_to_what_the_view_subscribes_to(view_cost: ModuleType) -> None:
    """The view follows no ``tcp_pose`` (the daemon would compute, encode and put it every cycle for
    it). Reproduction on 17fa302: the view subscribed to ``tcp_pose`` too, and so did ``VIEW_KEYS``."""
    import asyncio

    from urdaemon.publish.keys import RobotKeys
    from urdaemon.view.feed import RobotFeed

    declared: list[str] = []

    class Session:
        def declare_subscriber(self, key: str, _callback: object) -> object:
            declared.append(key)
            return object()

    loop = asyncio.new_event_loop()
    try:
        RobotFeed("alice").subscribe(Session(), RobotKeys("demo_cell", "alice"), loop)
    finally:
        loop.close()
    keys = RobotKeys("demo_cell", "alice")
    assert keys.tcp_pose not in declared
    assert sorted(declared) == sorted(getattr(keys, k) for k in view_cost.VIEW_KEYS)
    assert view_cost.SUBSCRIBED["subscribed"] == view_cost.VIEW_KEYS
    assert set(view_cost.SUBSCRIBED) < set(view_cost.CASES)


def test_view_cost_reads_proc_of_this_process_and_its_child(view_cost: ModuleType) -> None:
    import os
    import subprocess

    fields = view_cost.stat_fields("42 (a) b (c)) S 7 42 42 0 -1 4194304 1 0 0 0 250 130 0 0 20 0 1 0")
    assert (fields[0], fields[1], fields[11], fields[12]) == ("S", "7", "250", "130")
    assert view_cost.cpu_seconds(os.getpid()) > 0.0  # pytest has run: some CPU was used
    assert 0.0 < view_cost.main_thread_cpu_seconds(os.getpid()) <= view_cost.cpu_seconds(os.getpid())
    child = subprocess.Popen([sys.executable, "-c", "import sys; sys.stdin.read()"], stdin=subprocess.PIPE)
    try:
        tree = view_cost.process_tree(os.getpid())
        assert tree[0] == os.getpid()
        assert child.pid in tree
        own = view_cost.cpu_seconds(os.getpid())  # read first: the process runs on between the reads
        assert view_cost.tree_cpu_seconds([*tree, 2**22 + 1]) >= own
    finally:
        child.communicate(b"")
    assert child.returncode == 0


def test_view_cost_counts_connections_to_the_page(view_cost: ModuleType) -> None:
    import socket

    table = (
        "  sl  local_address rem_address   st tx_queue rx_queue tr tm->when retrnsmt   uid\n"
        "   0: 0100007F:1F90 00000000:0000 0A 00000000:00000000 00:00000000 00000000     0\n"
        "   1: 0100007F:1F90 0100007F:A1B2 01 00000000:00000000 00:00000000 00000000     0\n"
        "   2: 0100007F:A1B2 0100007F:1F90 01 00000000:00000000 00:00000000 00000000     0\n"
        "   3: 0100007F:1F90 0100007F:A1B4 06 00000000:00000000 00:00000000 00000000     0\n"
    )
    assert view_cost.established(table, 8080) == 1  # the listener, the client's side, TIME_WAIT: no
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen()
        port = server.getsockname()[1]
        assert view_cost.page_connections(port) == 0
        with socket.create_connection(("127.0.0.1", port)):
            accepted, _ = server.accept()
            with accepted:
                assert view_cost.page_connections(port) == 1


def test_view_cost_table(view_cost: ModuleType) -> None:
    window = view_cost.Window
    windows = [window(0.10, 0.06, 0.05, None, 1000.0, 1, 0, None)]
    windows.append(window(0.08, 0.05, 0.07, None, 400.0, 2, 1, None))
    windows.append(window(0.12, 0.07, None, None, 0.0, 0, 0, None))  # no cycle ran: no figure per cycle
    row = view_cost.summarize("view", 2, windows)
    assert (row.daemon, row.daemon_spread, row.browser) == (0.10, (0.08, 0.12), None)
    assert row.viewer == pytest.approx(0.06)
    assert (row.missed, row.late, row.p99_us) == (3, 1, None)
    assert (row.cycle_rate, row.us_per_cycle) == (200.0, 150.0)  # medians over the windows
    assert row.loop == 0.06
    line = "| 2 | view | 10.0 (8.0-12.0) | 6.0 | 5.0 | 150.0 | 200 | 6.0 | - | 3 / 1 | - |"
    assert line in view_cost.table([row])
    timed = view_cost.summarize(
        "idle",
        1,
        [
            window(0.02, 0.01, None, None, 500.0, 0, 0, 80.0),
            window(0.02, 0.01, None, None, 500.0, 0, 0, 95.0),
        ],
    )
    assert view_cost.table([timed]).endswith("| 0 / 0 | 95 |")
    command = view_cost.chromium_command("/usr/bin/chromium", "http://127.0.0.1:8080", ROOT / "profile")
    assert command[0] == "/usr/bin/chromium"
    assert command[-1] == "http://127.0.0.1:8080"
    assert "--headless=new" in command
    assert f"--user-data-dir={ROOT / 'profile'}" in command


@pytest.mark.timeout(600)
def test_hiccups_smoke_run_ends_every_goal_with_one_result() -> None:
    """benchmarks/hiccups.py stays runnable: its smallest run (``--goals 2 --seconds 2 --burners 0``)
    on fakes at this run's addresses. Counts only: every goal ended with one result; no durations."""
    from tests.helpers import fake_address

    hiccups = _load("hiccups")
    cell = parse_cell(hiccups.cell_yaml("127.0.0.5", "127.0.0.6"), base_dir=ROOT)
    assert [r.name for r in cell.robots] == ["alice", "bob"]
    goals, stream, killed = hiccups.run(0, 2, 2.0, pair=(fake_address(), fake_address()))
    assert goals.sent == 2
    assert goals.lost == 0
    assert sum(goals.statuses.values()) == 2
    assert set(goals.cycles) == {"alice", "bob"}
    assert stream.status != "lost"
    assert stream.feedback > 0
    assert len(killed.published) == 1, killed.published  # the killed program's goal: one result
    assert killed.result.split(":")[0] == killed.published[0].split(":")[0]
