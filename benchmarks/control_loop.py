"""The control loop measured: the daemon driving N fake UR controllers over loopback (issue 5).

    python benchmarks/control_loop.py                      # 1, 2, 4, 8, 16 robots, 10 s each
    python benchmarks/control_loop.py --robots 8 --seconds 60

Every process is separate: the fake controllers (``urdaemon fake-robot``, one process, one shared
timing thread, each robot at its own phase unless ``--phases aligned``), the daemon
(``urdaemon serve``), a Zenoh subscriber of every robot's ``joint_states`` (and ``tcp_pose`` with
``--tcp-pose``; benchmarks/state_subscriber.py) and, for the comparison, SDU's ur_rtde
(benchmarks/ur_rtde_receive.py).

Printed, with the machine:
1. per robot count: the turnaround per cycle (RTDE package in → servoj frame out, from the daemon's
   ``cycle_stats`` service: the worst robot's median, p99, p99.9 and max), missed and late cycles,
   cycles per second, while every robot streams a trajectory with servoj;
2. the daemon's CPU-seconds per second (utime + stime of /proc/<pid>/stat, every thread) per robot
   and its memory; the fake's and the subscriber's CPU too (they share the machine);
3. a read-only urdaemon robot (state received and published) against ur_rtde's
   ``RTDEReceiveInterface`` on the same fake in the same window: CPU, memory and the ratio;
4. the state latency from RTDE arrival in the daemon to the subscriber (median, p99);
5. ruckig planning time for a 10-waypoint trajectory, and the final tracking error of that
   trajectory executed on the fake.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import math
import os
import platform
import shutil
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import AsyncIterator, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from urdaemon.backends.ur.rtde_link import output_recipe
from urdaemon.cell import parse_cell
from urdaemon.client import Client, GoalHandle, RobotClient
from urdaemon.control import TrajectoryPoint
from urdaemon.control.trajectory import TrajectoryPlanner
from urdaemon.daemon import describe_cell
from urdaemon.errors import UrDaemonError

HERE = Path(__file__).resolve().parent
TARGET_CPU_PER_ROBOT = 0.04
"""CPU-seconds per second per robot, for the whole cycle including Zenoh."""
TARGET_READ_ONLY_RATIO = 0.25
"""A read-only robot: at most a quarter of ur_rtde's CPU."""
TARGET_P99_US, TARGET_P999_US = 500.0, 2000.0
TARGET_LATENCY_P50_US, TARGET_LATENCY_P99_US = 300.0, 1000.0
FIRST_ADDRESS = 5
"""Robots at 127.0.0.5, 127.0.0.6, … (each fake listens on UR's standard ports at its own address)."""
READY_TIMEOUT_S = 90.0
CONNECT_ATTEMPTS = 60
STOP_TIMEOUT_S = 10.0
WARMUP_S = 2.0
AMPLITUDE = 0.2
"""rad, every joint: q0 + A·(1 - cos(2πt/T))/2, at rest at both ends."""
PERIOD_S = 5.0
POINT_SPACING_S = 0.1
HOME = [0.0, -1.57, 1.57, -1.57, -1.57, 0.0]
CLK_TCK = os.sysconf("SC_CLK_TCK")
KEEP_LOGS: Path | None = None
"""``--logs``: where every run's process logs are copied to (they are deleted otherwise)."""

PY_SPY = ("py-spy", "record", "-d", "5", "-r", "1000", "-f", "raw", "--nonblocking")


@dataclass
class Row:
    """The figures for one robot count."""

    robots: int
    daemon_cpu: float
    fake_cpu: float
    subscriber_cpu: float
    rss_mib: float
    hwm_mib: float
    rate_min: float
    rate_mean: float
    missed: int
    late: int
    goals_active: int
    turnaround: dict[str, float]
    latency: dict[str, Any]
    ended: list[str] = field(default_factory=list)
    """How the goals that ended before the window closed ended (status: reason)."""


@dataclass
class Comparison:
    """A read-only urdaemon robot against ur_rtde's receive interface, same fake, same window."""

    daemon_cpu: float
    daemon_rss_mib: float
    ur_rtde_cpu: float
    ur_rtde_rss_mib: float
    ur_rtde_variables: str
    latency: dict[str, Any]


@dataclass
class Tracking:
    """Planning a 10-waypoint trajectory and executing it on the fake."""

    plan_ms: list[float]
    status: str
    final_error: list[float]
    duration: float


@dataclass
class Processes:
    """The processes of one measurement, their logs, and how to stop them all."""

    logs: Path
    procs: dict[str, subprocess.Popen[bytes]] = field(default_factory=dict)

    def start(self, name: str, argv: list[str]) -> subprocess.Popen[bytes]:
        """Start ``argv`` in its own process group, output to ``<logs>/<name>.log``."""
        with open(self.logs / f"{name}.log", "wb") as out:
            proc = subprocess.Popen(argv, stdout=out, stderr=subprocess.STDOUT, start_new_session=True)
        self.procs[name] = proc
        return proc

    def pid(self, name: str) -> int:
        """The process id of ``name``."""
        return self.procs[name].pid

    def check(self) -> None:
        """Raise with the log's tail if a process has ended."""
        for name, proc in self.procs.items():
            if proc.poll() is not None:
                tail = (self.logs / f"{name}.log").read_text(errors="replace")[-2000:]
                raise RuntimeError(f"the {name} process ended (exit {proc.returncode}):\n{tail}")

    async def wait_line(self, name: str, text: str, timeout: float = 60.0) -> None:
        """Until ``text`` appears in the log of ``name`` (polled every 0.1 s, bounded by ``timeout``)."""
        for _ in range(int(timeout / 0.1)):
            self.check()
            if text in (self.logs / f"{name}.log").read_text(errors="replace"):
                return
            await asyncio.sleep(0.1)
        raise RuntimeError(f"{name} did not print {text!r} within {timeout} s")

    def stop_all(self) -> None:
        """SIGINT every process (daemon first: it hands control back), SIGKILL what is still running."""
        order = sorted(self.procs, key=lambda n: n != "daemon")
        for name in order:
            proc = self.procs[name]
            if proc.poll() is None:
                with contextlib.suppress(ProcessLookupError):
                    proc.send_signal(signal.SIGINT)
            try:
                proc.wait(STOP_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(proc.pid, signal.SIGKILL)
                proc.wait(STOP_TIMEOUT_S)


# ---- machine and processes ------------------------------------------------------------------------


def machine() -> str:
    """Cores, CPU model and Python version."""
    model = platform.processor() or platform.machine()
    with contextlib.suppress(OSError), open("/proc/cpuinfo") as cpuinfo:
        for line in cpuinfo:
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    loop = os.environ.get("URDAEMON_LOOP") or "default"
    return (
        f"{os.cpu_count()} cores, {model}, Python {platform.python_version()} ({platform.system()}), "
        f"daemon event loop: {loop}"
    )


def cpu_seconds(pid: int) -> float:
    """utime + stime of the whole process (every thread), in seconds."""
    text = Path(f"/proc/{pid}/stat").read_text()
    fields = text[text.rindex(")") + 2 :].split()  # after "pid (comm) ": fields 3.. of proc(5)
    return (int(fields[11]) + int(fields[12])) / CLK_TCK


def memory_mib(pid: int) -> tuple[float, float]:
    """(VmRSS, VmHWM) of the process in MiB."""
    values = {"VmRSS": 0.0, "VmHWM": 0.0}
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        key, _, rest = line.partition(":")
        if key in values:
            values[key] = int(rest.split()[0]) / 1024.0
    return values["VmRSS"], values["VmHWM"]


_PORTS_GIVEN: set[int] = set()


def free_port() -> int:
    """A TCP port nobody listens on at the moment, never the same one twice (the kernel may hand a
    just-closed ephemeral port out again, and two roles of one robot must not share a port)."""
    for _ in range(1000):
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
            sock.bind(("127.0.0.1", 0))
            port: int = sock.getsockname()[1]
        if port not in _PORTS_GIVEN:
            _PORTS_GIVEN.add(port)
            return port
    raise RuntimeError("no fresh free TCP port in 1000 attempts")


def cell_yaml(
    robots: int,
    *,
    read_only: bool = False,
    decimation: int = 1,
    low_latency: bool = False,
    realtime_priority: int = 0,
) -> str:
    """A cell of ``robots`` UR10e on the ur backend, each with its own four callback ports."""
    lines = [
        "cell: bench",
        f"realtime_priority: {realtime_priority}",
        f"zenoh: {{mode: peer, multicast_scouting: false, low_latency: {str(low_latency).lower()}}}",
        f"publish: {{joint_states_decimation: {decimation}}}",
        "robots:",
    ]
    ur = "{read_only: true}" if read_only else "{startup: true, listen_address: 127.0.0.1}"
    for i in range(robots):
        p = [free_port() for _ in range(4)]
        lines += [
            f"  - name: r{i}",
            "    model: ur10e",
            "    backend: ur",
            f"    address: 127.0.0.{FIRST_ADDRESS + i}",
            "    headless: true",
            f"    ports: {{reverse: {p[0]}, script_sender: {p[1]}, trajectory: {p[2]}, "
            f"script_command: {p[3]}}}",
            f"    pose: {{parent: world, xyz: [{i}.0, 0.0, 0.0], rpy: [0.0, 0.0, 0.0]}}",
            f"    ur: {ur}",
        ]
    return "\n".join(lines) + "\n"


def urdaemon(*args: str) -> list[str]:
    """The command line of ``urdaemon <args>`` with this interpreter."""
    return [sys.executable, "-m", "urdaemon", *args]


# ---- pieces of a run --------------------------------------------------------------------------------


def sinusoid(start: list[float], duration: float) -> list[dict[str, Any]]:
    """Trajectory points of q0 + A·(1 - cos(2πt/T))/2 every POINT_SPACING_S, at least ``duration``
    long and a whole number of periods (so that it ends at rest, as a trajectory must)."""
    periods = max(1, math.ceil(duration / PERIOD_S))
    count = round(periods * PERIOD_S / POINT_SPACING_S)
    points = []
    for k in range(1, count + 1):
        t = k * POINT_SPACING_S
        offset = AMPLITUDE * (1.0 - math.cos(2.0 * math.pi * t / PERIOD_S)) / 2.0
        points.append({"positions": [q + offset for q in start], "time_from_start": round(t, 6)})
    return points


def ten_waypoints(start: list[float]) -> list[dict[str, Any]]:
    """A 10-waypoint trajectory from ``start``: every joint out and back, 0.6 s apart, ending at rest."""
    offsets = [0.1, 0.25, 0.4, 0.5, 0.45, 0.3, 0.2, 0.1, 0.05, 0.0]
    return [
        {
            "positions": [q + (-1) ** j * o for j, q in enumerate(start)],
            "time_from_start": round(0.6 * (k + 1), 6),
        }
        for k, o in enumerate(offsets)
    ]


async def connect(endpoint: str, procs: Processes) -> Client:
    """A client of the daemon, retried while the daemon starts."""
    for _ in range(CONNECT_ATTEMPTS):
        procs.check()
        with contextlib.suppress(UrDaemonError):
            return await Client.connect(endpoint, timeout=2.0)
        await asyncio.sleep(0.5)
    raise RuntimeError(f"cannot connect to the daemon at {endpoint}")


@contextlib.contextmanager
def running_cell(cell: str, *fake_args: str, unix: bool = False) -> Iterator[tuple[Processes, str]]:
    """The fakes and the daemon for ``cell`` in their own processes (logs in a temporary directory);
    yields the processes and the daemon's Zenoh endpoint (on loopback TCP, or with ``unix`` a Unix
    socket in that directory), and stops every process started meanwhile."""
    with tempfile.TemporaryDirectory(prefix="urdaemon-bench-") as tmp:
        procs = Processes(Path(tmp))
        config = procs.logs / "cell.yaml"
        config.write_text(cell)
        endpoint = f"unixsock-stream/{procs.logs}/zenoh.sock" if unix else f"tcp/127.0.0.1:{free_port()}"
        try:
            procs.start("fake", urdaemon("fake-robot", "--config", str(config), "--powered", *fake_args))
            procs.start("daemon", urdaemon("serve", "--config", str(config), "--listen", endpoint))
            yield procs, endpoint
        finally:
            procs.stop_all()
            if KEEP_LOGS is not None:
                run = KEEP_LOGS / f"{time.strftime('%H%M%S')}-{cell.count('- name:')}-robots"
                shutil.copytree(procs.logs, run, dirs_exist_ok=True)
                print(f"  logs: {run}", file=sys.stderr)


@contextlib.asynccontextmanager
async def daemon_client(endpoint: str, procs: Processes) -> AsyncIterator[Client]:
    """A client of the daemon (retried while it starts), closed afterwards whatever happens."""
    client = await connect(endpoint, procs)
    try:
        yield client
    finally:
        with contextlib.suppress(Exception):
            await asyncio.wait_for(client.close(), 5.0)


async def wait_status(robot: RobotClient, procs: Processes, predicate: Any, what: str) -> dict[str, Any]:
    """Until ``predicate(status)`` (polled every 0.2 s, bounded by READY_TIMEOUT_S)."""
    status: dict[str, Any] = {}
    for _ in range(int(READY_TIMEOUT_S / 0.2)):
        procs.check()
        with contextlib.suppress(UrDaemonError):
            status = await robot.status(timeout=2.0)
            if predicate(status):
                return status
        await asyncio.sleep(0.2)
    raise RuntimeError(f"{robot.name} not {what} within {READY_TIMEOUT_S} s: {status.get('reason')}")


async def first_position(robot: RobotClient) -> list[float]:
    """The robot's current joint positions."""
    sub = robot.joint_states(10)
    try:
        return [float(q) for q in (await sub.get_json(timeout=10.0))["position"]]
    finally:
        sub.close()


def latency_file(procs: Processes) -> Path:
    """Where the state subscriber writes its figures."""
    return procs.logs / "latency.json"


def start_subscriber(procs: Processes, endpoint: str, keys: list[str], low_latency: bool = False) -> None:
    """The state subscriber in its own process (figures in ``latency_file(procs)``)."""
    flags = ["--low-latency"] if low_latency else []
    script = str(HERE / "state_subscriber.py")
    procs.start("subscriber", [sys.executable, script, *flags, endpoint, str(latency_file(procs)), *keys])


def signal_subscriber(procs: Processes, signum: int) -> None:
    """SIGUSR1: start the latency window; SIGUSR2: write it."""
    os.kill(procs.pid("subscriber"), signum)


def _figures(result: Path) -> dict[str, Any] | None:
    """The subscriber's figures once its file is complete."""
    if not result.exists() or not result.stat().st_size:
        return None
    figures: dict[str, Any] = json.loads(result.read_text())
    return figures


async def read_latency(procs: Processes) -> dict[str, Any]:
    """Ask the subscriber for its window's figures and wait for the file (bounded)."""
    result = latency_file(procs)
    result.unlink(missing_ok=True)
    signal_subscriber(procs, signal.SIGUSR2)
    for _ in range(100):
        figures = _figures(result)
        if figures is not None:
            return figures
        await asyncio.sleep(0.05)
    raise RuntimeError("the subscriber wrote no figures")


async def _ending(goal: GoalHandle) -> str:
    """``status: reason`` of a goal that has ended."""
    try:
        result = await goal.result(timeout=5.0)
    except UrDaemonError as err:
        return f"no result: {err}"
    return f"{result['status']}: {result.get('reason', '')}"


async def _stamped(reply: Any) -> dict[str, Any]:
    """The reply of a cycle_stats query with the monotonic time it arrived as ``at``."""
    stats: dict[str, Any] = await reply
    stats["at"] = time.monotonic()
    return stats


def worst(stats: list[dict[str, Any]]) -> dict[str, float]:
    """The worst robot's turnaround figures (each figure's maximum over robots)."""
    keys = ("p50_us", "p99_us", "p999_us", "max_us")
    return {k: max(s["turnaround"][k] for s in stats) for k in keys}


# ---- 1, 2, 4: N robots under servoj control -----------------------------------------------------------


async def measure_control(robots: int, seconds: float, endpoint: str, procs: Processes) -> Row:
    """Wait for ready, start the trajectories and the subscriber window, measure for ``seconds``."""
    goals: list[GoalHandle] = []
    async with daemon_client(endpoint, procs) as client:
        handles = [await client.robot(f"r{i}", cell="bench", timeout=30.0) for i in range(robots)]
        for handle in handles:
            await wait_status(handle, procs, lambda s: s["ready"], "ready")
        for handle in handles:
            start = await first_position(handle)
            goals.append(await handle.send_trajectory(sinusoid(start, seconds + 30.0)))
        await asyncio.sleep(WARMUP_S)
        procs.check()

        daemon, fake, sub = procs.pid("daemon"), procs.pid("fake"), procs.pid("subscriber")
        before = [await _stamped(h.cycle_stats(reset=True)) for h in handles]
        signal_subscriber(procs, signal.SIGUSR1)
        t0 = time.monotonic()
        cpu0 = cpu_seconds(daemon), cpu_seconds(fake), cpu_seconds(sub)
        await asyncio.sleep(seconds)
        t1 = time.monotonic()
        cpu1 = cpu_seconds(daemon), cpu_seconds(fake), cpu_seconds(sub)
        rss, hwm = memory_mib(daemon)
        latency = await read_latency(procs)
        after = [await _stamped(h.cycle_stats()) for h in handles]
        statuses = [await h.status() for h in handles]
        procs.check()
        wall = t1 - t0
        # each robot's rate over the time between its own two replies (the queries run one by one)
        rates = [
            (a["cycles"] - b["cycles"]) / (a["at"] - b["at"]) for a, b in zip(after, before, strict=True)
        ]
        return Row(
            robots=robots,
            daemon_cpu=(cpu1[0] - cpu0[0]) / wall,
            fake_cpu=(cpu1[1] - cpu0[1]) / wall,
            subscriber_cpu=(cpu1[2] - cpu0[2]) / wall,
            rss_mib=rss,
            hwm_mib=hwm,
            rate_min=min(rates),
            rate_mean=sum(rates) / len(rates),
            missed=sum(a["missed_cycles"] - b["missed_cycles"] for a, b in zip(after, before, strict=True)),
            late=sum(a["late_cycles"] - b["late_cycles"] for a, b in zip(after, before, strict=True)),
            goals_active=sum(s["active_goal"] is not None for s in statuses),
            ended=[
                await _ending(g) for g, st in zip(goals, statuses, strict=True) if st["active_goal"] is None
            ],
            turnaround=worst(after),
            latency=latency,
        )


def run_control(
    robots: int,
    seconds: float,
    phases: str,
    tcp_pose: bool,
    decimation: int,
    low_latency: bool,
    profile: Path | None,
    unix: bool = False,
    realtime_priority: int = 0,
) -> Row:
    """Fakes, daemon and subscriber for ``robots`` robots; measure; stop them all."""
    cell = cell_yaml(
        robots, decimation=decimation, low_latency=low_latency, realtime_priority=realtime_priority
    )
    with running_cell(cell, "--phases", phases, unix=unix) as (procs, endpoint):
        keys = ["bench/*/joint_states", *(["bench/*/tcp_pose"] if tcp_pose else [])]
        start_subscriber(procs, endpoint, keys, low_latency)
        row: Row = asyncio.run(_with_subscriber(procs, measure_control(robots, seconds, endpoint, procs)))
        if profile is not None:  # after the window, so that sampling does not disturb the figures
            profile.parent.mkdir(parents=True, exist_ok=True)
            out = profile.with_name(f"{profile.stem}-{robots}{profile.suffix or '.txt'}")
            for part in ("daemon", "fake"):
                out_part = out.with_name(f"{out.stem}-{part}{out.suffix}")
                pid = str(procs.pid(part))
                subprocess.run(
                    [*PY_SPY, "-o", str(out_part), "-p", pid], check=False, timeout=60, capture_output=True
                )
                print(f"  py-spy profile of the {part} ({robots} robots): {out_part}", file=sys.stderr)
        return row


async def _with_subscriber(procs: Processes, work: Any) -> Any:
    await procs.wait_line("subscriber", "subscribed")
    return await work


# ---- 3: read-only robot against ur_rtde ------------------------------------------------------------


async def measure_read_only(seconds: float, endpoint: str, procs: Processes, address: str) -> Comparison:
    """A read-only robot in the daemon and ur_rtde on the same fake, measured in the same window."""
    async with daemon_client(endpoint, procs) as client:
        robot = await client.robot("r0", cell="bench", timeout=30.0)
        await wait_status(robot, procs, lambda s: s["lifecycle"] == "running", "streaming")
        variables = list(output_recipe())
        procs.start("ur_rtde", [sys.executable, str(HERE / "ur_rtde_receive.py"), address, *variables])
        try:
            await procs.wait_line("ur_rtde", "receiving", timeout=30.0)
        except RuntimeError:  # a variable ur_rtde does not know: fall back to its default recipe
            variables = []
            procs.procs.pop("ur_rtde").wait(STOP_TIMEOUT_S)
            procs.start("ur_rtde", [sys.executable, str(HERE / "ur_rtde_receive.py"), address])
            await procs.wait_line("ur_rtde", "receiving", timeout=30.0)
        await asyncio.sleep(WARMUP_S)
        daemon, urr = procs.pid("daemon"), procs.pid("ur_rtde")
        signal_subscriber(procs, signal.SIGUSR1)
        t0 = time.monotonic()
        cpu0 = cpu_seconds(daemon), cpu_seconds(urr)
        await asyncio.sleep(seconds)
        t1 = time.monotonic()
        cpu1 = cpu_seconds(daemon), cpu_seconds(urr)
        latency = await read_latency(procs)
        procs.check()
        wall = t1 - t0
        return Comparison(
            daemon_cpu=(cpu1[0] - cpu0[0]) / wall,
            daemon_rss_mib=memory_mib(daemon)[0],
            ur_rtde_cpu=(cpu1[1] - cpu0[1]) / wall,
            ur_rtde_rss_mib=memory_mib(urr)[0],
            ur_rtde_variables=f"the daemon's {len(variables)} outputs" if variables else "ur_rtde's default",
            latency=latency,
        )


def run_read_only(seconds: float, low_latency: bool, unix: bool = False) -> Comparison:
    """One fake, a daemon with the robot read-only, the subscriber and ur_rtde."""
    cell = cell_yaml(1, read_only=True, low_latency=low_latency)
    with running_cell(cell, unix=unix) as (procs, endpoint):
        start_subscriber(procs, endpoint, ["bench/*/joint_states"], low_latency)
        work = measure_read_only(seconds, endpoint, procs, f"127.0.0.{FIRST_ADDRESS}")
        comparison: Comparison = asyncio.run(_with_subscriber(procs, work))
        return comparison


# ---- 5: planning time and tracking on the fake ----------------------------------------------------------


def planning_times(runs: int = 50) -> list[float]:
    """Milliseconds to plan the 10-waypoint trajectory completely (tail and first segment), ``runs`` times."""
    cell = parse_cell(cell_yaml(1), base_dir=Path.cwd())
    limits = describe_cell(cell).limits["r0"]
    points = [
        TrajectoryPoint(positions=tuple(p["positions"]), time_from_start=p["time_from_start"])
        for p in ten_waypoints(HOME)
    ]
    zeros = [0.0] * limits.dof
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        TrajectoryPlanner(points, limits, HOME).finish(HOME, zeros, zeros)
        times.append((time.perf_counter() - start) * 1e3)
    return times


async def measure_tracking(endpoint: str, procs: Processes) -> tuple[str, list[float], float]:
    """Execute the 10-waypoint trajectory on the fake: (status, final error per joint, duration)."""
    async with daemon_client(endpoint, procs) as client:
        robot = await client.robot("r0", cell="bench", timeout=30.0)
        await wait_status(robot, procs, lambda s: s["ready"], "ready")
        goal = await robot.send_trajectory(ten_waypoints(await first_position(robot)))
        result = await goal.result(timeout=60.0)
        return result["status"], [float(e) for e in result["final_error"]], float(result["duration"])


def run_tracking() -> Tracking:
    """Planning in this process; execution by a daemon on one fake."""
    plan_ms = planning_times()
    with running_cell(cell_yaml(1)) as (procs, endpoint):
        status, error, duration = asyncio.run(measure_tracking(endpoint, procs))
    return Tracking(plan_ms, status, error, duration)


# ---- output ---------------------------------------------------------------------------------------------


def yes(ok: bool) -> str:
    return "yes" if ok else "NO"


def control_table(
    rows: list[Row],
    seconds: float,
    phases: str,
    tcp_pose: bool,
    decimation: int,
    low_latency: bool,
    unix: bool = False,
    realtime_priority: int = 0,
) -> str:
    """Tables 1, 2 and 4 for every robot count."""
    streams = "joint_states and tcp_pose" if tcp_pose else "joint_states"
    streams += f" at {500 / decimation:g} Hz" + (", Zenoh low-latency transport" if low_latency else "")
    streams += ", Zenoh over a Unix socket" if unix else ""
    streams += f", daemon loop at SCHED_FIFO {realtime_priority}" if realtime_priority else ""
    lines = [
        f"## Full control: servoj streamed to every robot, {seconds:g} s window, fakes' phases: {phases}, "
        f"subscriber of every robot's {streams}",
        "",
        "| robots | turnaround p50 / p99 / p99.9 / max µs (worst robot) | missed | late "
        "| cycles/s min / mean "
        "| daemon CPU-s/s | per robot (≤ 0.04) | RSS (peak) MiB | state latency p50 / p99 µs (≤ 300 / 1000) "
        "| fake CPU-s/s | subscriber CPU-s/s | goals active at end |",
        "|" + " --- |" * 12,
    ]
    for r in rows:
        t, lat = r.turnaround, r.latency
        per = r.daemon_cpu / r.robots
        lat_text = (
            f"{lat['p50_us']:.0f} / {lat['p99_us']:.0f} ({lat['samples']} samples)"
            if lat.get("samples")
            else "no samples"
        )
        lines.append(
            f"| {r.robots} | {t['p50_us']:.0f} / {t['p99_us']:.0f} / {t['p999_us']:.0f} / {t['max_us']:.0f} "
            f"| {r.missed} | {r.late} | {r.rate_min:.1f} / {r.rate_mean:.1f} | {r.daemon_cpu:.3f} "
            f"| {per:.3f} {yes(per <= TARGET_CPU_PER_ROBOT)} "
            f"| {r.rss_mib:.0f} ({r.hwm_mib:.0f}) | {lat_text} "
            f"| {r.fake_cpu:.3f} | {r.subscriber_cpu:.3f} | {r.goals_active}/{r.robots} |"
        )
    for r in rows:
        if r.ended:
            lines += ["", f"{r.robots} robots, goals that ended early: " + "; ".join(sorted(set(r.ended)))]
    eight = [r for r in rows if r.robots == 8]
    for r in eight:
        ok = (
            r.missed == 0
            and r.turnaround["p99_us"] < TARGET_P99_US
            and r.turnaround["p999_us"] < TARGET_P999_US
        )
        lines += [
            "",
            f"8 robots: zero missed cycles, p99 < 0.5 ms, p99.9 < 2 ms over {seconds:g} s: {yes(ok)}",
        ]
    return "\n".join(lines)


def comparison_table(c: Comparison, seconds: float) -> str:
    """Table 3."""
    ratio = c.daemon_cpu / c.ur_rtde_cpu if c.ur_rtde_cpu > 0 else math.inf
    lat = c.latency
    return "\n".join(
        [
            f"## Read-only robot against ur_rtde on the same fake, same {seconds:g} s window",
            "",
            "| receiver | CPU-s/s | RSS MiB | what it does |",
            "| --- | --- | --- | --- |",
            f"| urdaemon (read-only robot) | {c.daemon_cpu:.3f} | {c.daemon_rss_mib:.0f} | RTDE at 500 Hz, "
            "joint_states published to a subscriber in another process "
            f"(latency p50 {lat.get('p50_us') or 0:.0f} µs) |",
            f"| ur_rtde RTDEReceiveInterface | {c.ur_rtde_cpu:.3f} | {c.ur_rtde_rss_mib:.0f} "
            "| RTDE at 500 Hz "
            f"({c.ur_rtde_variables}), kept in memory |",
            "",
            f"ratio urdaemon / ur_rtde: {ratio:.2f} "
            f"(target ≤ {TARGET_READ_ONLY_RATIO}: {yes(ratio <= TARGET_READ_ONLY_RATIO)})",
        ]
    )


def tracking_table(t: Tracking) -> str:
    """Table 5."""
    plan = sorted(t.plan_ms)
    worst_error = max(abs(e) for e in t.final_error) if t.final_error else math.nan
    return "\n".join(
        [
            "## Planning and tracking: 10 waypoints, 6 s",
            "",
            f"ruckig planning (whole trajectory, {len(plan)} runs): median {statistics.median(plan):.2f} ms, "
            f"max {plan[-1]:.2f} ms",
            f"executed on the fake: {t.status} in {t.duration:.3f} s, "
            f"final error max |e| = {worst_error:.2e} rad "
            f"({', '.join(f'{e:+.1e}' for e in t.final_error)})",
        ]
    )


def main() -> None:
    """Parse the arguments, run everything asked for, print the tables."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0] if __doc__ else None)
    parser.add_argument(
        "--robots", default="1,2,4,8,16", help="comma-separated robot counts (default 1,2,4,8,16)"
    )
    parser.add_argument("--seconds", type=float, default=10.0, help="measuring window per run (default 10)")
    parser.add_argument(
        "--phases",
        choices=("spread", "aligned"),
        default="spread",
        help="the fakes' RTDE packages: each at its own phase (default, like independent robots) "
        "or all at once",
    )
    parser.add_argument(
        "--decimation",
        type=int,
        default=1,
        help="publish.joint_states_decimation of the cell (default 1: every cycle, 500 Hz)",
    )
    parser.add_argument(
        "--low-latency",
        action="store_true",
        help="zenoh.low_latency in the cell and the subscriber (the ur_rtde comparison too)",
    )
    parser.add_argument(
        "--unix",
        action="store_true",
        help="the daemon's Zenoh endpoint is a Unix socket (the subscriber's and clients' too)",
    )
    parser.add_argument(
        "--realtime",
        type=int,
        default=0,
        metavar="PRIORITY",
        help="realtime_priority of the cell: the daemon's loop thread under SCHED_FIFO (1-99)",
    )
    parser.add_argument(
        "--tcp-pose", action="store_true", help="subscribe to tcp_pose too (forward kinematics every cycle)"
    )
    parser.add_argument(
        "--no-compare", action="store_true", help="skip the read-only comparison with ur_rtde"
    )
    parser.add_argument("--no-tracking", action="store_true", help="skip planning and tracking")
    parser.add_argument(
        "--profile",
        type=Path,
        help="after each control window, py-spy the daemon, then the fake, 5 s each, "
        "into PATH-<N>-daemon.txt and PATH-<N>-fake.txt",
    )
    parser.add_argument(
        "--logs", type=Path, help="copy every run's process logs (fakes, daemon, subscriber) into PATH"
    )
    args = parser.parse_args()
    global KEEP_LOGS
    KEEP_LOGS = args.logs
    counts = [int(n) for n in args.robots.split(",") if n.strip()]
    if counts and (min(counts) < 1 or max(counts) > 200):
        parser.error("--robots: counts between 1 and 200")
    if not 0 <= args.realtime <= 99:
        parser.error("--realtime: a priority between 1 and 99 (0: normal scheduling)")
    if not 0 < args.seconds <= 600:
        parser.error("--seconds: between 0 and 600")
    print(f"machine: {machine()}\n")
    try:
        rows = []
        for n in counts:
            print(f"measuring {n} robot(s) for {args.seconds:g} s …", file=sys.stderr)
            rows.append(
                run_control(
                    n,
                    args.seconds,
                    args.phases,
                    args.tcp_pose,
                    args.decimation,
                    args.low_latency,
                    args.profile,
                    args.unix,
                    args.realtime,
                )
            )
        if rows:
            print(
                control_table(
                    rows,
                    args.seconds,
                    args.phases,
                    args.tcp_pose,
                    args.decimation,
                    args.low_latency,
                    args.unix,
                    args.realtime,
                )
                + "\n"
            )
        if not args.no_compare:
            print("measuring a read-only robot against ur_rtde …", file=sys.stderr)
            print(
                comparison_table(run_read_only(args.seconds, args.low_latency, args.unix), args.seconds)
                + "\n"
            )
        if not args.no_tracking:
            print("planning and tracking …", file=sys.stderr)
            print(tracking_table(run_tracking()))
    except KeyboardInterrupt:
        print("interrupted; the processes are stopped", file=sys.stderr)


if __name__ == "__main__":
    main()
