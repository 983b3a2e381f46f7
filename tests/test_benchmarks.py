"""The benchmark scripts stay runnable: their pure parts (cell files, trajectories, tables) are checked
here; the measurements themselves run only by hand (docs/performance.md), never as timed tests."""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path
from types import ModuleType

import pytest

from urdaemon.cell import parse_cell
from urdaemon.publish.node import zenoh_config

ROOT = Path(__file__).resolve().parents[1]


def _load(name: str) -> ModuleType:
    spec = importlib.util.spec_from_file_location(f"bench_{name}", ROOT / "benchmarks" / f"{name}.py")
    assert spec is not None
    assert spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


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
    from urdaemon.cell.config import ZenohOptions
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
