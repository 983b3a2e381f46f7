"""benchmarks/input_stalls.py stays runnable: its inputs are what they say, and a tiny run measures
every one of them (the figures are for docs/performance.md, never asserted here)."""

from __future__ import annotations

import json
from types import ModuleType

import pytest

from tests.helpers import load_benchmark
from urdaemon.publish.envelope import MAX_MESSAGE_BYTES, SMALL_MESSAGE_BYTES
from urdaemon.publish.trajectory_json import decode_trajectory_goal

pytestmark = pytest.mark.timeout(120)


@pytest.fixture(scope="module")
def bench() -> ModuleType:
    return load_benchmark("input_stalls")


def test_the_inputs_are_the_worst_of_each_kind(bench: ModuleType) -> None:
    items = {item.name: item for item in bench.inputs()}
    assert len(items["1 MB garbage move"].payload) == 1_000_000
    (largest_read,) = (item for name, item in items.items() if name.endswith("(largest read)"))
    assert SMALL_MESSAGE_BYTES - 200 < len(largest_read.payload) <= SMALL_MESSAGE_BYTES
    trajectory = items["valid 5000-point trajectory (pos, vel, acc)"].payload
    assert len(trajectory) < MAX_MESSAGE_BYTES
    goal = decode_trajectory_goal(trajectory)
    assert len(goal.points) == 5000
    assert all(p.velocities is not None and p.accelerations is not None for p in goal.points)
    assert len(json.loads(items["200 000-value stream command"].payload)["positions"]) == 200_000
    assert items["200 000-value stream command"].put


async def test_a_tiny_run_measures_every_input(bench: ModuleType) -> None:
    rows: list[tuple[str, float, float]] = []
    results = await bench.measure(scale=0.001, repeat=1, on_row=lambda *row: rows.append(row))
    names = ["baseline", *(item.name for item in bench.inputs(0.001))]
    assert list(results) == names
    assert len(rows) == len(names)
    assert all(0.0 < every <= worst for _, every, worst in rows), rows
