"""What recording costs: the daemon's CPU per robot with and without ``urdaemon record`` and with and
without the flight recorder's ring (cell file ``record``), the recorder's own CPU, its drops, and the
file's size per robot-minute (issue 29).

    python benchmarks/recorder_cost.py                          # 1, 4 and 8 mock robots, 20 s windows
    python benchmarks/recorder_cost.py --robots 4 --window 10 --cases idle,record

Per robot count it starts ``urdaemon serve`` on a generated mock cell (UR10e and UR3e in turn: every
arm at 500 Hz, benchmarks/view_cost.py's cell) on a free loopback endpoint, lets it settle, and
measures these cases, each over one window of ``--window`` seconds:

- ``idle``: nobody subscribed (the daemon skips ``tcp_pose`` and ``tf`` while nobody wants them);
- ``record``: ``urdaemon record`` of every channel running (its own process): the daemon's CPU and
  the recorder's; then its summary line gives the messages written and dropped, and the file's size;
- ``ring``: the same cell with ``record: {ring_s: 60}``: the daemon's CPU (with its tap feeding the
  flight recorder's process through a pipe) and that process's (and its resident memory at the end
  of the window), nobody subscribed;
- ``both``: the ring and ``urdaemon record`` together.

CPU is utime + stime from /proc/PID/stat over the window (every thread), printed as % of one core per
robot. A 2-core machine shared with other work makes single windows noisy: compare cases measured
back to back, and repeat.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib.util
import os
import re
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType

ROOT = Path(__file__).resolve().parent.parent
CASES = ("idle", "record", "ring", "both")
SETTLE_S = 5.0
"""After a daemon or a recorder starts, before its window (imports, subscriptions, the JIT of caches)."""
START_TIMEOUT_S = 60.0
SUMMARY = re.compile(
    r"recorded (?P<messages>\d+) messages on (?P<topics>\d+) topics in (?P<seconds>[\d.]+) s .*"
    r"dropped (?P<dropped>\d+)"
)
"""``urdaemon record``'s last line on stderr."""


def _view_cost() -> ModuleType:
    """benchmarks/view_cost.py: its /proc readers, its mock cell, how it starts processes."""
    spec = importlib.util.spec_from_file_location("bench_view_cost", ROOT / "benchmarks" / "view_cost.py")
    assert spec is not None
    assert spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


VIEW = _view_cost()


def cell_yaml(robots: int, ring_dir: Path | None) -> str:
    """The mock cell of ``robots`` arms, with the flight recorder writing to ``ring_dir`` if given."""
    text: str = VIEW.mock_cell_yaml(robots)
    if ring_dir is not None:
        text = text.replace("robots:\n", f"record: {{ring_s: 60, dir: {ring_dir}}}\nrobots:\n", 1)
    return text


@dataclass
class Summary:
    """What ``urdaemon record`` said at the end."""

    messages: int
    seconds: float
    dropped: int


def parse_summary(stderr: str) -> Summary | None:
    """``urdaemon record``'s summary line, if it printed one."""
    match = SUMMARY.search(stderr)
    if match is None:
        return None
    return Summary(int(match["messages"]), float(match["seconds"]), int(match["dropped"]))


def resident_mb(pid: int) -> float:
    """VmRSS of ``pid`` in MB (0 when it is gone)."""
    with contextlib.suppress(OSError):
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return 0.0


@dataclass
class Row:
    case: str
    robots: int
    daemon: float
    """CPU-seconds per second."""
    recorder: float | None
    ring: float | None
    ring_mb: float | None
    dropped: int | None
    mb_per_robot_minute: float | None


@contextlib.contextmanager
def served(robots: int, ring: bool, logs: Path) -> Iterator[tuple[int, str]]:
    """``urdaemon serve`` of the mock cell (with the ring if asked): its pid and endpoint."""
    config = logs / f"cell_{robots}_{'ring' if ring else 'plain'}.yaml"
    config.write_text(cell_yaml(robots, logs / "flight" if ring else None))
    endpoint = f"tcp/127.0.0.1:{VIEW.free_port()}"
    argv = VIEW.urdaemon("serve", "--config", str(config), "--listen", endpoint)
    proc = VIEW.spawn(argv, logs / "serve.log")
    try:
        time.sleep(SETTLE_S)
        if proc.poll() is not None:
            raise RuntimeError(f"urdaemon serve ended: see {logs / 'serve.log'}")
        yield proc.pid, endpoint
    finally:
        VIEW._stop(proc)  # SIGTERM, then SIGKILL after 10 s


def flight_pid(daemon: int) -> int | None:
    """The daemon's flight recorder process (its one child), if it runs."""
    children = [p for p in VIEW.process_tree(daemon) if p != daemon]
    return children[0] if children else None


def measure(case: str, robots: int, daemon: int, endpoint: str, window: float, logs: Path) -> Row:
    """One window of ``case`` on a daemon that runs (with the ring for ``ring`` and ``both``)."""
    recorder: subprocess.Popen[bytes] | None = None
    out = logs / f"{case}_{robots}.mcap"
    err = logs / f"{case}_{robots}.log"
    if case in ("record", "both"):
        seconds = SETTLE_S + window + 1.0
        argv = VIEW.urdaemon("record", "--connect", endpoint, "-o", str(out), "--duration", f"{seconds:g}")
        recorder = VIEW.spawn(argv, err)
        time.sleep(SETTLE_S)
    ring = flight_pid(daemon) if case in ("ring", "both") else None
    watched = [p for p in (daemon, None if recorder is None else recorder.pid, ring) if p is not None]
    before = [VIEW.cpu_seconds(p) for p in watched]
    start = time.monotonic()
    time.sleep(window)
    after = [VIEW.cpu_seconds(p) for p in watched]
    elapsed = time.monotonic() - start
    rates = dict(zip(watched, [(a - b) / elapsed for a, b in zip(after, before, strict=True)], strict=True))
    ring_mb = resident_mb(ring) if ring is not None else None
    summary = None
    if recorder is not None:
        try:
            recorder.wait(START_TIMEOUT_S)
        finally:  # a recorder that did not end on its --duration is not left running
            if recorder.poll() is None:
                VIEW._stop(recorder)
        summary = parse_summary(err.read_text(errors="replace"))
    size = out.stat().st_size if out.exists() else 0
    minutes = summary.seconds / 60 if summary else 0
    return Row(
        case,
        robots,
        rates[daemon],
        None if recorder is None else rates[recorder.pid],
        None if ring is None else rates[ring],
        ring_mb,
        None if summary is None else summary.dropped,
        size / 1e6 / robots / minutes if minutes else None,
    )


def _pct(value: float | None, robots: int) -> str:
    return "-" if value is None else f"{100 * value / robots:5.1f}"


def table(rows: list[Row]) -> str:
    """The rows as a Markdown table."""
    lines = [
        "| robots | case | daemon %/robot | record %/robot | ring %/robot | ring RSS MB | dropped "
        "| MB/robot-min |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in rows:
        ring_mb = "-" if r.ring_mb is None else f"{r.ring_mb:.0f}"
        dropped = "-" if r.dropped is None else str(r.dropped)
        size = "-" if r.mb_per_robot_minute is None else f"{r.mb_per_robot_minute:.1f}"
        lines.append(
            f"| {r.robots} | {r.case} | {_pct(r.daemon, r.robots)} | {_pct(r.recorder, r.robots)} | "
            f"{_pct(r.ring, r.robots)} | {ring_mb} | {dropped} | {size} |"
        )
    return "\n".join(lines)


def run(robot_counts: list[int], cases: list[str], window: float, logs: Path) -> list[Row]:
    """Every case at every robot count."""
    rows: list[Row] = []
    for robots in robot_counts:
        for ring in (False, True):
            mine = [c for c in cases if (c in ("ring", "both")) == ring]
            if not mine:
                continue
            with served(robots, ring, logs) as (daemon, endpoint):
                for case in mine:
                    row = measure(case, robots, daemon, endpoint, window, logs)
                    print(table([row]).splitlines()[-1], flush=True)
                    rows.append(row)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0] if __doc__ else None)
    parser.add_argument("--robots", default="1,4,8", help="robot counts (default 1,4,8)")
    parser.add_argument("--cases", default=",".join(CASES), help=f"cases (default {','.join(CASES)})")
    parser.add_argument("--window", type=float, default=20.0, help="seconds per window (default 20)")
    args = parser.parse_args()
    cases = [c for c in args.cases.split(",") if c]
    unknown = sorted(set(cases) - set(CASES))
    if unknown:
        parser.error(f"unknown case(s) {', '.join(unknown)}; cases: {', '.join(CASES)}")
    print(VIEW.machine())
    print(_load("before"))
    with tempfile.TemporaryDirectory(prefix="recorder_cost_") as tmp:
        rows = run([int(n) for n in args.robots.split(",")], cases, args.window, Path(tmp))
    print()
    print(table(rows))
    print(_load("after"))


def _load(when: str) -> str:
    one, five, fifteen = os.getloadavg()
    return f"load average {when}: {one:.2f} {five:.2f} {fifteen:.2f}"


if __name__ == "__main__":
    main()
