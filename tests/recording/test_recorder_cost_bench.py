"""benchmarks/recorder_cost.py stays runnable: its cells are valid cell files (with and without the
flight recorder) and it reads ``urdaemon record``'s summary line as the command prints it."""

from __future__ import annotations

from pathlib import Path
from types import ModuleType

import pytest

from tests.helpers import load_benchmark
from urdaemon.cell import parse_cell

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def bench() -> ModuleType:
    return load_benchmark("recorder_cost")


def test_the_cells_are_valid_with_and_without_the_ring(bench: ModuleType, tmp_path: Path) -> None:
    plain = parse_cell(bench.cell_yaml(4, None), base_dir=ROOT)
    assert len(plain.robots) == 4
    assert plain.record is None
    ring = parse_cell(bench.cell_yaml(2, tmp_path), base_dir=ROOT)
    assert ring.record is not None
    assert ring.record.ring_s == 60
    assert ring.record.dir == str(tmp_path.resolve())


def test_the_record_summary_is_read(bench: ModuleType) -> None:
    line = (
        "recording cell 'view_bench' to x.mcap (Ctrl-C to stop)\n"
        "recorded 61234 messages on 9 topics in 26.0 s to x.mcap (3.4 MB); dropped 7 (inbox full)\n"
    )
    summary = bench.parse_summary(line)
    assert (summary.messages, summary.seconds, summary.dropped) == (61234, 26.0, 7)
    assert bench.parse_summary("error: no cell is served at tcp/127.0.0.1:1") is None
