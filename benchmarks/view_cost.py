"""What a viewer costs the daemon: its CPU per robot with and without ``urdaemon view`` (issue 18).

    python benchmarks/view_cost.py                          # the demo cell, then 4 and 8 mock robots
    python benchmarks/view_cost.py --robots 2 --window 10 --windows 5
    python benchmarks/view_cost.py --cases idle,view,page --browser /usr/bin/chromium
    python benchmarks/view_cost.py --backend ur --robots 2  # UR10e arms on fake controllers

Starts ``urdaemon serve`` on a free loopback endpoint: for 2 robots the demo cell
(configs/dual_robot_mock.yaml), for other counts a generated mock cell of the same shape (UR10e and
UR3e in turn, a metre apart); with ``--backend ur`` the cell of benchmarks/control_loop.py (UR10e arms
on ``urdaemon fake-robot``, which also gives the turnaround). It lets the cell settle, then measures
these cases back to back, each over ``--windows`` windows of ``--window`` seconds:

- ``idle``: nobody but the benchmark's own client (which only asks ``cycle_stats``);
- ``joints``, ``poses``, ``subscribed``: a bare Zenoh subscriber (no-op callbacks, in this process)
  of every robot's ``joint_states``; of its ``tcp_pose`` (which the view no longer follows: it draws
  the TCP from the joints and the status's ``tcp``); of everything the view subscribes to
  (``joint_states``, ``status``, ``events``): what the subscriptions alone cost;
- ``view``: ``urdaemon view --connect ENDPOINT --port 0`` running, no page open;
- ``shared``: the view and the bare subscribers of ``subscribed`` together: what a view adds when
  another client already follows the same keys;
- ``page``: the same view with one headless Chromium page open on it (WebGL in software);
- ``stream``: a view in this process (``running_view``) with a page open, every robot enabled as
  the page's switch does (the lease, then the sliders' joint stream at 50 Hz) and one slider per
  robot swept (±0.2 rad on the last joint, 4 s period), so the robots move.

Per window: the daemon's CPU (utime + stime of /proc/PID/stat, every thread), the viewer's (the
view's process; in ``stream`` this process, which is the viewer) and the browser's (its whole
process tree); and from each robot's ``cycle_stats`` service the missed and late cycles and the
turnaround (reset at each window's start; the mock backend has none). Printed: per case the median
window, the daemon's CPU as % of one core per robot, and per robot cycle run (a starved daemon skips
cycles: on a busy machine the CPU per cycle compares cases fairly, the CPU per second does not), and
the worst robot's figures. The daemon's CPU is also split: its main thread (the asyncio loop, where
every robot's cycle, encoding and ``put`` run) and the rest (Zenoh's threads, which send).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import importlib.util
import logging
import math
import os
import platform
import shutil
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import AsyncIterator, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from urdaemon.client import Client, RobotClient
from urdaemon.errors import UrDaemonError
from urdaemon.publish.keys import RobotKeys

ROOT = Path(__file__).resolve().parent.parent
DEMO_CELL = ROOT / "configs" / "dual_robot_mock.yaml"
CLK_TCK = os.sysconf("SC_CLK_TCK")
CASES = ("idle", "joints", "poses", "subscribed", "view", "shared", "page", "stream")
VIEW_KEYS = ("joint_states", "status", "events")
"""What ``urdaemon view`` subscribes to per robot (urdaemon/view/feed.py)."""
SUBSCRIBED = {"joints": ("joint_states",), "poses": ("tcp_pose",), "subscribed": VIEW_KEYS}
"""The keys of each robot the bare-subscriber cases subscribe to."""
START_TIMEOUT_S = 60.0
"""Bound on the daemon, the view or the page starting (the machine may be busy)."""
SETTLE_S = 5.0
"""After a case starts, before its first window (the page loads its scene, the JIT warms)."""
SWEEP = (0.2, 4.0, 0.1)
"""The ``stream`` case's slider sweep: amplitude (rad), period (s), update interval (s)."""
CHROMIUM_FLAGS = (
    "--headless=new",
    "--no-sandbox",
    "--use-gl=angle",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
    "--mute-audio",
)


# ---- /proc ---------------------------------------------------------------------------------------------


def stat_fields(text: str) -> list[str]:
    """The fields of a /proc/PID/stat line after ``pid (comm)`` (comm may hold spaces and parentheses):
    index 0 is field 3 (state) of proc(5), 1 the parent pid, 11 utime, 12 stime."""
    return text[text.rindex(")") + 2 :].split()


def cpu_seconds(pid: int) -> float:
    """utime + stime of the whole process (every thread), in seconds."""
    fields = stat_fields(Path(f"/proc/{pid}/stat").read_text())
    return (int(fields[11]) + int(fields[12])) / CLK_TCK


def main_thread_cpu_seconds(pid: int) -> float:
    """utime + stime of the process's main thread (the daemon's asyncio loop, where every robot's
    cycle runs); the rest of the process's CPU is its other threads' (Zenoh's runtime, callbacks)."""
    fields = stat_fields(Path(f"/proc/{pid}/task/{pid}/stat").read_text())
    return (int(fields[11]) + int(fields[12])) / CLK_TCK


def process_tree(pid: int) -> list[int]:
    """``pid`` and every process descended from it, as /proc shows them now."""
    parents: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        with contextlib.suppress(OSError, ValueError, IndexError):
            ppid = int(stat_fields((entry / "stat").read_text())[1])
            parents.setdefault(ppid, []).append(int(entry.name))
    tree, todo = [], [pid]
    while todo:
        current = todo.pop()
        tree.append(current)
        todo.extend(parents.get(current, ()))
    return tree


def tree_cpu_seconds(pids: list[int]) -> float:
    """utime + stime summed over ``pids`` (those that ended meanwhile count as 0)."""
    total = 0.0
    for pid in pids:
        with contextlib.suppress(OSError):
            total += cpu_seconds(pid)
    return total


def established(tcp_table: str, port: int) -> int:
    """Connections accepted on local ``port`` in a /proc/net/tcp (or tcp6) table, ESTABLISHED now."""
    count = 0
    for line in tcp_table.splitlines()[1:]:
        fields = line.split()
        if len(fields) > 3 and fields[3] == "01" and int(fields[1].rsplit(":", 1)[1], 16) == port:
            count += 1
    return count


def page_connections(port: int) -> int:
    """Established connections to the view's page on ``port`` (HTTP and its websocket)."""
    total = 0
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        with contextlib.suppress(OSError):
            total += established(Path(table).read_text(), port)
    return total


def machine() -> str:
    """Cores, CPU model and Python version."""
    model = platform.machine()
    with contextlib.suppress(OSError), open("/proc/cpuinfo") as cpuinfo:
        for line in cpuinfo:
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    return f"{os.cpu_count()} cores, {model}, Python {platform.python_version()}, {platform.system()}"


# ---- the cell ------------------------------------------------------------------------------------------


def free_port() -> int:
    """A TCP port nobody listens on at the moment."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


def mock_cell_yaml(robots: int) -> str:
    """A cell of ``robots`` mock arms shaped like the demo cell: UR10e and UR3e in turn, a metre apart
    along x, at the demo's start joints, tf at 50 Hz (the Zenoh section is replaced by ``--listen``)."""
    lines = [
        "cell: view_bench",
        "zenoh: {mode: peer, multicast_scouting: false}",
        "publish: {tf_rate_hz: 50}",
        "robots:",
    ]
    for i in range(robots):
        lines += [
            f"  - name: r{i}",
            f"    model: {'ur10e' if i % 2 == 0 else 'ur3e'}",
            "    backend: mock",
            f"    pose: {{parent: world, xyz: [{i - (robots - 1) / 2:.1f}, 0.0, 0.0], rpy: [0.0, 0.0, 0.0]}}",
            "    mock: {initial_positions: [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]}",
        ]
    return "\n".join(lines) + "\n"


def urdaemon(*args: str) -> list[str]:
    """The command line of ``urdaemon <args>`` with this interpreter."""
    return [sys.executable, "-m", "urdaemon", *args]


def _control_loop() -> Any:
    """benchmarks/control_loop.py, for its fake-robot cell (``--backend ur``)."""
    spec = importlib.util.spec_from_file_location(
        "bench_control_loop", ROOT / "benchmarks" / "control_loop.py"
    )
    assert spec is not None
    assert spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


@dataclass
class Cell:
    """A served cell: its daemon's pid, endpoint, name and robots."""

    pid: int
    endpoint: str
    name: str
    robots: list[str]


@contextlib.contextmanager
def served(robots: int, backend: str, logs: Path) -> Iterator[Cell]:
    """``urdaemon serve`` (and for ``ur`` the fake controllers) until the block ends."""
    if backend == "ur":
        bench = _control_loop()
        with bench.running_cell(bench.cell_yaml(robots)) as (procs, endpoint):
            yield Cell(procs.pid("daemon"), endpoint, "bench", [f"r{i}" for i in range(robots)])
        return
    if robots == 2:
        config, name, names = DEMO_CELL, "demo_cell", ["alice", "bob"]
    else:
        config, name, names = logs / "cell.yaml", "view_bench", [f"r{i}" for i in range(robots)]
        config.write_text(mock_cell_yaml(robots))
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    proc = spawn(urdaemon("serve", "--config", str(config), "--listen", endpoint), logs / "serve.log")
    try:
        yield Cell(proc.pid, endpoint, name, names)
    finally:
        _stop(proc)


async def connect(endpoint: str) -> Client:
    """A client of the daemon, retried while it starts (bounded by START_TIMEOUT_S)."""
    deadline = time.monotonic() + START_TIMEOUT_S
    while True:
        try:
            return await Client.connect(endpoint, timeout=2.0)
        except UrDaemonError:
            if time.monotonic() > deadline:
                raise
            await asyncio.sleep(0.5)


async def ready_robots(client: Client, cell: Cell) -> list[RobotClient]:
    """Every robot of the cell once its status says ready (bounded)."""
    handles = [await client.robot(name, cell=cell.name, timeout=START_TIMEOUT_S) for name in cell.robots]
    deadline = time.monotonic() + START_TIMEOUT_S
    for handle in handles:
        while not (await handle.status(timeout=5.0)).get("ready"):
            if time.monotonic() > deadline:
                raise RuntimeError(f"{handle.name} is not ready after {START_TIMEOUT_S:g} s")
            await asyncio.sleep(0.2)
    return handles


# ---- measuring -----------------------------------------------------------------------------------------


@dataclass
class Window:
    """One measuring window: CPU-seconds per second of each process, cycle figures over robots."""

    daemon: float
    loop: float
    """The daemon's main thread (its asyncio loop) alone."""
    viewer: float | None
    browser: float | None
    cycles: float
    """Cycles run per second, summed over robots (a starved cycle is skipped, not run)."""
    missed: int
    late: int
    p99_us: float | None
    """The worst robot's turnaround p99 (None: the backend records none)."""


@dataclass
class Watched:
    """The processes of a case besides the daemon: the viewer's pid, the browser's root pid."""

    viewer: int | None = None
    browser: int | None = None


async def measure_window(handles: list[RobotClient], daemon: int, watched: Watched, seconds: float) -> Window:
    """Reset the robots' turnarounds, measure ``seconds`` of CPU, read the cycle figures."""
    before = [await h.cycle_stats(reset=True) for h in handles]
    browser = process_tree(watched.browser) if watched.browser is not None else []
    t0 = time.monotonic()
    loop0 = main_thread_cpu_seconds(daemon)
    cpu0 = (
        cpu_seconds(daemon),
        cpu_seconds(watched.viewer) if watched.viewer else 0.0,
        tree_cpu_seconds(browser),
    )
    await asyncio.sleep(seconds)
    loop1 = main_thread_cpu_seconds(daemon)
    cpu1 = (
        cpu_seconds(daemon),
        cpu_seconds(watched.viewer) if watched.viewer else 0.0,
        tree_cpu_seconds(browser),
    )
    wall = time.monotonic() - t0
    after = [await h.cycle_stats() for h in handles]
    pairs = list(zip(after, before, strict=True))
    p99s = [a["turnaround"].get("p99_us") for a in after if a["turnaround"].get("count")]
    return Window(
        daemon=(cpu1[0] - cpu0[0]) / wall,
        loop=(loop1 - loop0) / wall,
        viewer=(cpu1[1] - cpu0[1]) / wall if watched.viewer else None,
        browser=(cpu1[2] - cpu0[2]) / wall if watched.browser else None,
        cycles=sum(a["cycles"] - b["cycles"] for a, b in pairs) / wall,
        missed=sum(a["missed_cycles"] - b["missed_cycles"] for a, b in pairs),
        late=sum(a["late_cycles"] - b["late_cycles"] for a, b in pairs),
        p99_us=max(p99s) if p99s else None,
    )


@dataclass
class Row:
    """One case of one cell: the median window's figures, the cycle figures summed over windows."""

    case: str
    robots: int
    daemon: float
    daemon_spread: tuple[float, float]
    loop: float
    """The daemon's loop thread's CPU (median window); the rest is Zenoh's threads'."""
    viewer: float | None
    browser: float | None
    cycle_rate: float
    """Cycles run per second per robot (median window)."""
    us_per_cycle: float
    """The daemon's CPU per robot cycle run, µs (median window): robust to skipped cycles."""
    missed: int
    late: int
    p99_us: float | None


def summarize(case: str, robots: int, windows: list[Window]) -> Row:
    """The row of a case: medians of the CPU figures, the sums of missed and late, the worst p99."""

    def median(values: list[float | None]) -> float | None:
        known = [v for v in values if v is not None]
        return statistics.median(known) if known else None

    daemon = [w.daemon for w in windows]
    p99 = [w.p99_us for w in windows if w.p99_us is not None]
    per_cycle = [1e6 * w.daemon / w.cycles for w in windows if w.cycles]
    return Row(
        case=case,
        robots=robots,
        daemon=statistics.median(daemon),
        daemon_spread=(min(daemon), max(daemon)),
        loop=statistics.median(w.loop for w in windows),
        viewer=median([w.viewer for w in windows]),
        browser=median([w.browser for w in windows]),
        cycle_rate=statistics.median(w.cycles for w in windows) / robots,
        us_per_cycle=statistics.median(per_cycle) if per_cycle else math.nan,
        missed=sum(w.missed for w in windows),
        late=sum(w.late for w in windows),
        p99_us=max(p99) if p99 else None,
    )


def _percent(value: float | None) -> str:
    return "-" if value is None else f"{100 * value:.1f}"


def table(rows: list[Row]) -> str:
    """The rows as a Markdown table (CPU as % of one core)."""
    lines = [
        "| robots | case | daemon CPU % (min-max) | of which its loop % | per robot % | µs per robot cycle "
        "| cycles/s per robot | viewer % | browser % | missed / late cycles | turnaround p99 µs (worst) |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in rows:
        low, high = r.daemon_spread
        p99 = "-" if r.p99_us is None else f"{r.p99_us:.0f}"
        lines.append(
            f"| {r.robots} | {r.case} | {_percent(r.daemon)} ({_percent(low)}-{_percent(high)}) "
            f"| {_percent(r.loop)} | {_percent(r.daemon / r.robots)} | {r.us_per_cycle:.1f} "
            f"| {r.cycle_rate:.0f} | {_percent(r.viewer)} | {_percent(r.browser)} "
            f"| {r.missed} / {r.late} | {p99} |"
        )
    return "\n".join(lines)


# ---- the cases -----------------------------------------------------------------------------------------


@contextlib.contextmanager
def subscribed(client: Client, cell: Cell, keys: tuple[str, ...]) -> Iterator[Watched]:
    """No-op subscribers of ``keys`` of every robot on the benchmark's own session."""
    subs = []
    for name in cell.robots:
        robot_keys = RobotKeys(cell.name, name)
        for key in keys:
            subs.append(client.session.declare_subscriber(getattr(robot_keys, key), lambda _sample: None))
    try:
        yield Watched()
    finally:
        for sub in subs:
            with contextlib.suppress(Exception):
                sub.undeclare()


def spawn(argv: list[str], log: Path, *, pipe: bool = False) -> subprocess.Popen[bytes]:
    """Start ``argv`` with its stderr (and its stdout unless ``pipe``) in the file ``log``."""
    with open(log, "wb") as out:
        return subprocess.Popen(argv, stdout=subprocess.PIPE if pipe else out, stderr=out)


def _stop(proc: subprocess.Popen[bytes]) -> None:
    proc.terminate()
    try:
        proc.wait(10)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait(10)


@contextlib.asynccontextmanager
async def view_process(cell: Cell, logs: Path) -> AsyncIterator[tuple[int, str]]:
    """``urdaemon view --connect`` in its own process; yields its pid and page address."""
    proc = spawn(urdaemon("view", "--connect", cell.endpoint, "--port", "0"), logs / "view.log", pipe=True)
    try:
        assert proc.stdout is not None
        loop = asyncio.get_running_loop()
        deadline = loop.time() + START_TIMEOUT_S
        text = ""
        while "urdaemon view of cell" not in text:  # viser prints its banner first
            line = await asyncio.wait_for(
                loop.run_in_executor(None, proc.stdout.readline), max(0.1, deadline - loop.time())
            )
            if not line:
                raise RuntimeError(f"urdaemon view ended before serving (see {logs / 'view.log'})")
            text = line.decode()
        threading.Thread(target=proc.stdout.read, daemon=True).start()  # keep its pipe drained
        yield proc.pid, text[text.index("http://") :].strip()
    finally:
        _stop(proc)


def chromium_command(browser: str, url: str, profile: Path) -> list[str]:
    """Headless Chromium on ``url`` with software WebGL and a profile of its own."""
    return [browser, *CHROMIUM_FLAGS, f"--user-data-dir={profile}", url]


@contextlib.asynccontextmanager
async def page(browser: str, url: str, logs: Path) -> AsyncIterator[int]:
    """A headless Chromium page on ``url`` until the block ends; yields the browser's pid once the
    page holds a connection to the view (bounded by START_TIMEOUT_S)."""
    port = int(url.rsplit(":", 1)[1].split("/")[0])
    profile = Path(tempfile.mkdtemp(prefix="view-cost-chromium-"))
    proc = spawn(chromium_command(browser, url, profile), logs / "chromium.log")
    try:
        deadline = time.monotonic() + START_TIMEOUT_S
        while page_connections(port) == 0:
            if proc.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"no page connected to {url} (see {logs / 'chromium.log'})")
            await asyncio.sleep(0.2)
        yield proc.pid
    finally:
        _stop(proc)
        shutil.rmtree(profile, ignore_errors=True)


async def _sweep(view: Any) -> None:
    """Sweep the last slider of every enabled robot, as a hand on the page would."""
    amplitude, period, step = SWEEP
    start = {name: list(c.targets or []) for name, c in view.controls.items()}
    t0 = time.monotonic()
    while True:
        offset = amplitude * math.sin(2 * math.pi * (time.monotonic() - t0) / period)
        for name, panel in view.panels.items():
            if start[name]:
                last = list(panel.sliders)[-1]
                panel.sliders[last].value = start[name][-1] + offset
        await asyncio.sleep(step)


@contextlib.asynccontextmanager
async def streaming_view(cell: Cell, browser: str, logs: Path) -> AsyncIterator[Watched]:
    """A view in this process with a page open, every robot enabled and a slider sweeping."""
    from urdaemon.view.app import running_view

    # a browser's speculative connection that sends no request is logged with a traceback: not ours
    logging.getLogger("websockets").setLevel(logging.CRITICAL)
    async with running_view(cell.endpoint, port=0) as view, page(browser, view.url, logs) as chromium:
        deadline = time.monotonic() + START_TIMEOUT_S
        while not view.server.get_clients():
            if time.monotonic() > deadline:
                raise RuntimeError("the page did not connect to the view")
            await asyncio.sleep(0.2)
        for panel in view.panels.values():
            panel.enable.value = True  # as the page's switch does
        while not all(c.enabled for c in view.controls.values()):
            refused = [f"{n}: {c.refusal}" for n, c in view.controls.items() if c.refusal]
            if refused or time.monotonic() > deadline:
                raise RuntimeError(f"enabling failed: {refused or 'timed out'}")
            await asyncio.sleep(0.1)
        sweeping = asyncio.create_task(_sweep(view))
        try:
            yield Watched(viewer=os.getpid(), browser=chromium)
        finally:
            sweeping.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await sweeping
            if not all(c.enabled for c in view.controls.values()):
                print(f"  warning: a robot was disabled during the stream: {view.controls}", file=sys.stderr)


@contextlib.asynccontextmanager
async def case(name: str, client: Client, cell: Cell, browser: str, logs: Path) -> AsyncIterator[Watched]:
    """What runs besides the daemon in case ``name``."""
    if name == "idle":
        yield Watched()
    elif name in SUBSCRIBED:
        with subscribed(client, cell, SUBSCRIBED[name]) as watched:
            yield watched
    elif name == "view":
        async with view_process(cell, logs) as (pid, _url):
            yield Watched(viewer=pid)
    elif name == "shared":
        with subscribed(client, cell, VIEW_KEYS):
            async with view_process(cell, logs) as (pid, _url):
                yield Watched(viewer=pid)
    elif name == "page":
        async with view_process(cell, logs) as (pid, url), page(browser, url, logs) as chromium:
            yield Watched(viewer=pid, browser=chromium)
    elif name == "stream":
        async with streaming_view(cell, browser, logs) as watched:
            yield watched
    else:
        raise ValueError(f"no case {name!r}")


async def measure_cell(cell: Cell, cases: list[str], args: argparse.Namespace, logs: Path) -> list[Row]:
    """Every case on one served cell, back to back."""
    client = await connect(cell.endpoint)
    try:
        handles = await ready_robots(client, cell)
        await asyncio.sleep(SETTLE_S)
        rows = []
        for name in cases:
            async with case(name, client, cell, args.browser, logs) as watched:
                await asyncio.sleep(SETTLE_S)
                windows = [
                    await measure_window(handles, cell.pid, watched, args.window) for _ in range(args.windows)
                ]
            rows.append(summarize(name, len(cell.robots), windows))
            print(table(rows[-1:]).splitlines()[-1], flush=True)
        return rows
    finally:
        await client.close()


def main() -> None:
    """Parse the options and run."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", default="2,4,8", help="robot counts, comma-separated (2: the demo cell)")
    parser.add_argument("--backend", choices=("mock", "ur"), default="mock")
    parser.add_argument("--cases", default=",".join(CASES), help=f"any of {', '.join(CASES)}")
    parser.add_argument("--window", type=float, default=10.0, help="seconds per window")
    parser.add_argument("--windows", type=int, default=3)
    parser.add_argument("--browser", default=shutil.which("chromium") or "/usr/bin/chromium")
    args = parser.parse_args()
    cases = [c for c in args.cases.split(",") if c]
    unknown = sorted(set(cases) - set(CASES))
    if unknown:
        parser.error(f"unknown case(s): {', '.join(unknown)}")
    print(f"{machine()}; {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}")
    print(f"{args.windows} windows of {args.window:g} s per case, {args.backend} backend")
    print(table([]))
    rows = []
    for robots in (int(n) for n in args.robots.split(",")):
        with (
            tempfile.TemporaryDirectory(prefix="view-cost-") as tmp,
            served(robots, args.backend, Path(tmp)) as cell,
        ):
            rows += asyncio.run(measure_cell(cell, cases, args, Path(tmp)))
    print()
    print(table(rows))


if __name__ == "__main__":
    main()
