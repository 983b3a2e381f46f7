"""CPU cost of the whole control loop: the daemon driving N fake UR controllers over loopback.

    python benchmarks/control_loop.py --robots 1,2,4 --seconds 10

For every N: the fake controllers run in their own process (``urdaemon fake-robot --powered``) and
the daemon in another (``urdaemon serve``), both from a generated cell file with N ``ur`` robots
(UR10e at 127.0.0.5, 127.0.0.6, …). Once every robot's status says ready, each robot gets a long
sinusoidal trajectory goal (servoj streamed at 500 Hz for the whole window), then the script
measures for ``--seconds``: the daemon's CPU-seconds per wall second (utime + stime of
/proc/<pid>/stat, all threads) per robot, its RSS, the fake process's CPU, and from the robots'
status messages the cycles achieved per second and the missed / late cycle counters.

The target is ≤ 0.04 CPU-s/s per robot (docs/performance.md).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import math
import os
import platform
import signal
import socket
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from urdaemon.client import Client, RobotClient, Subscription
from urdaemon.errors import UrDaemonError

TARGET_CPU_PER_ROBOT = 0.04
"""CPU-seconds per second per robot, for the whole cycle including Zenoh."""
RATE_HZ = 500.0
"""A UR10e (e-Series) streams RTDE at 500 Hz."""
FIRST_ADDRESS = 5
"""Robots at 127.0.0.5, 127.0.0.6, … (the fakes listen on UR's standard ports at their own address)."""
READY_TIMEOUT_S = 60.0
CONNECT_ATTEMPTS = 40
STOP_TIMEOUT_S = 10.0
WARMUP_S = 1.0
AMPLITUDE = 0.2
"""rad, every joint: q0 + A·(1 - cos(2πt/T))/2, at rest at both ends."""
PERIOD_S = 5.0
POINT_SPACING_S = 0.1
CLK_TCK = os.sysconf("SC_CLK_TCK")
PY_SPY = ("py-spy", "record", "-d", "5", "-r", "1000", "-f", "raw", "--nonblocking")


@dataclass
class Row:
    """The figures for one N."""

    robots: int
    daemon_cpu: float
    fake_cpu: float
    daemon_rss_mib: float
    daemon_hwm_mib: float
    rate_min: float
    rate_mean: float
    missed: int
    late: int
    goals_active: int


# ---- machine and processes ------------------------------------------------------------------------


def machine() -> str:
    """Cores, CPU model and Python version."""
    model = platform.processor() or platform.machine()
    with contextlib.suppress(OSError), open("/proc/cpuinfo") as cpuinfo:
        for line in cpuinfo:
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    return f"{os.cpu_count()} cores, {model}, Python {platform.python_version()} ({platform.system()})"


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


def free_port() -> int:
    """A TCP port nobody listens on at the moment."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


def cell_yaml(robots: int) -> str:
    """A cell of ``robots`` UR10e on the ur backend, each with its own four callback ports."""
    lines = ["cell: bench", "zenoh: {mode: peer, multicast_scouting: false}", "robots:"]
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
            "    ur: {startup: true, listen_address: 127.0.0.1}",
        ]
    return "\n".join(lines) + "\n"


def start(args: list[str], log: Path) -> subprocess.Popen[bytes]:
    """``python -m urdaemon <args>`` in its own process group, output to ``log``."""
    with open(log, "wb") as out:
        return subprocess.Popen(
            [sys.executable, "-m", "urdaemon", *args],
            stdout=out,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )


def stop(proc: subprocess.Popen[bytes]) -> None:
    """SIGINT (graceful), then SIGKILL if it has not ended within STOP_TIMEOUT_S."""
    if proc.poll() is not None:
        return
    with contextlib.suppress(ProcessLookupError):
        proc.send_signal(signal.SIGINT)
    try:
        proc.wait(STOP_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(STOP_TIMEOUT_S)


def check_alive(procs: dict[str, subprocess.Popen[bytes]], logs: Path) -> None:
    """Raise with the log's tail if a process has ended."""
    for name, proc in procs.items():
        if proc.poll() is not None:
            tail = (logs / f"{name}.log").read_text(errors="replace")[-2000:]
            raise RuntimeError(f"the {name} process ended (exit {proc.returncode}):\n{tail}")


# ---- the run ----------------------------------------------------------------------------------------


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


class StatusWatch:
    """The latest status message of every robot, with its arrival time (monotonic)."""

    def __init__(self, client: Client, robots: list[RobotClient]) -> None:
        self.latest: dict[str, tuple[float, dict[str, Any]]] = {}
        self._subs: dict[str, Subscription] = {r.name: client.subscribe(r.keys.status, 100) for r in robots}
        self._tasks = [
            asyncio.get_running_loop().create_task(self._pump(n, s)) for n, s in self._subs.items()
        ]

    async def _pump(self, name: str, sub: Subscription) -> None:
        while True:  # ends when cancelled by close()
            message = await sub.get_json()
            self.latest[name] = (time.monotonic(), message)

    async def fresh(self, after: float, timeout: float) -> dict[str, tuple[float, dict[str, Any]]]:
        """Every robot's first status that arrived after ``after`` (polls for up to ``timeout`` s)."""
        for _ in range(int(timeout / 0.02) + 1):
            if len(self.latest) == len(self._subs) and all(t > after for t, _ in self.latest.values()):
                return dict(self.latest)
            await asyncio.sleep(0.02)
        raise TimeoutError(f"no fresh status from every robot within {timeout} s")

    async def close(self) -> None:
        """Stop the pumps."""
        for task in self._tasks:
            task.cancel()
        for task in self._tasks:
            with contextlib.suppress(asyncio.CancelledError):
                await task


async def connect(endpoint: str, procs: dict[str, subprocess.Popen[bytes]], logs: Path) -> Client:
    """A client of the daemon, retried while the daemon starts."""
    for _ in range(CONNECT_ATTEMPTS):
        check_alive(procs, logs)
        with contextlib.suppress(UrDaemonError):
            return await Client.connect(endpoint, timeout=2.0)
        await asyncio.sleep(0.5)
    raise RuntimeError(f"cannot connect to the daemon at {endpoint}")


async def wait_ready(
    watch: StatusWatch, names: list[str], procs: dict[str, subprocess.Popen[bytes]], logs: Path
) -> None:
    """Until every robot's status says ready (bounded by READY_TIMEOUT_S)."""
    for _ in range(int(READY_TIMEOUT_S / 0.2)):
        check_alive(procs, logs)
        if all(n in watch.latest and watch.latest[n][1]["ready"] for n in names):
            return
        await asyncio.sleep(0.2)
    states = {n: watch.latest.get(n, (0.0, {}))[1].get("reason", "no status") for n in names}
    raise RuntimeError(f"not every robot became ready within {READY_TIMEOUT_S} s: {states}")


async def measure(
    robots: int, seconds: float, endpoint: str, procs: dict[str, subprocess.Popen[bytes]], logs: Path
) -> Row:
    """Connect, wait for ready, start the trajectories, and measure for ``seconds``."""
    daemon_pid, fake_pid = procs["daemon"].pid, procs["fake"].pid
    client = await connect(endpoint, procs, logs)
    watch: StatusWatch | None = None
    try:
        handles = [await client.robot(f"r{i}", cell="bench") for i in range(robots)]
        names = [h.name for h in handles]
        watch = StatusWatch(client, handles)
        await wait_ready(watch, names, procs, logs)
        for handle in handles:
            sub = handle.joint_states(10)
            try:
                start = (await sub.get_json(timeout=5.0))["position"]
            finally:
                client.unsubscribe(sub)
            await handle.send_trajectory(sinusoid([float(q) for q in start], seconds + 20.0))
        await asyncio.sleep(WARMUP_S)
        check_alive(procs, logs)

        t0 = time.monotonic()
        cpu0 = cpu_seconds(daemon_pid), cpu_seconds(fake_pid)
        first = await watch.fresh(t0, 2.0)
        await asyncio.sleep(seconds)
        t1 = time.monotonic()
        cpu1 = cpu_seconds(daemon_pid), cpu_seconds(fake_pid)
        rss, hwm = memory_mib(daemon_pid)
        last = await watch.fresh(t1, 2.0)
        check_alive(procs, logs)

        rates, missed, late, active = [], 0, 0, 0
        for name in names:
            (ta, a), (tb, b) = first[name], last[name]
            rates.append((b["cycles"] - a["cycles"]) / (tb - ta))
            missed += b["missed_cycles"] - a["missed_cycles"]
            late += b["late_cycles"] - a["late_cycles"]
            active += b["active_goal"] is not None
        wall = t1 - t0
        return Row(
            robots=robots,
            daemon_cpu=(cpu1[0] - cpu0[0]) / wall,
            fake_cpu=(cpu1[1] - cpu0[1]) / wall,
            daemon_rss_mib=rss,
            daemon_hwm_mib=hwm,
            rate_min=min(rates),
            rate_mean=sum(rates) / len(rates),
            missed=missed,
            late=late,
            goals_active=active,
        )
    finally:
        if watch is not None:
            await watch.close()
        with contextlib.suppress(Exception):
            await asyncio.wait_for(client.close(), 5.0)


def run_one(robots: int, seconds: float, profile: Path | None) -> Row:
    """Start the fakes and the daemon for ``robots`` robots, measure, stop both."""
    with tempfile.TemporaryDirectory(prefix="urdaemon-bench-") as tmp:
        logs = Path(tmp)
        config = logs / "cell.yaml"
        config.write_text(cell_yaml(robots))
        endpoint = f"tcp/127.0.0.1:{free_port()}"
        procs: dict[str, subprocess.Popen[bytes]] = {}
        try:
            procs["fake"] = start(["fake-robot", "--config", str(config), "--powered"], logs / "fake.log")
            procs["daemon"] = start(
                ["serve", "--config", str(config), "--listen", endpoint], logs / "daemon.log"
            )
            row = asyncio.run(measure(robots, seconds, endpoint, procs, logs))
            if profile is not None:  # after the window, so that sampling does not disturb the figures
                profile.parent.mkdir(parents=True, exist_ok=True)
                out = profile.with_name(f"{profile.stem}-{robots}{profile.suffix or '.txt'}")
                pid = str(procs["daemon"].pid)
                subprocess.run(
                    [*PY_SPY, "-o", str(out), "-p", pid],
                    check=False,
                    timeout=60,
                    capture_output=True,
                )
                print(f"  py-spy profile of the daemon ({robots} robots): {out}", file=sys.stderr)
            return row
        finally:
            for name in ("daemon", "fake"):  # the daemon first: it hands control back to the fakes
                if name in procs:
                    stop(procs[name])


def table(rows: list[Row], seconds: float) -> str:
    """The results as a Markdown table."""
    head = (
        "| robots | daemon CPU-s/s | per robot | target | met | daemon RSS (peak) MiB "
        "| fake CPU-s/s | cycles/s per robot (min / mean) | missed | late | goals active at end |"
    )
    lines = [head, "|" + " --- |" * 11]
    for r in rows:
        per = r.daemon_cpu / r.robots
        lines.append(
            f"| {r.robots} | {r.daemon_cpu:.3f} | {per:.3f} | ≤ {TARGET_CPU_PER_ROBOT:.2f} "
            f"| {'yes' if per <= TARGET_CPU_PER_ROBOT else 'NO'} "
            f"| {r.daemon_rss_mib:.0f} ({r.daemon_hwm_mib:.0f}) "
            f"| {r.fake_cpu:.3f} | {r.rate_min:.1f} / {r.rate_mean:.1f} of {RATE_HZ:.0f} "
            f"| {r.missed} | {r.late} | {r.goals_active}/{r.robots} |"
        )
    return (
        f"machine: {machine()}\nwindow: {seconds:g} s per row, servoj streaming on every robot\n\n"
        + "\n".join(lines)
    )


def main() -> None:
    """Parse the arguments, run every N, print the table."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0] if __doc__ else None)
    parser.add_argument("--robots", default="1,2,4", help="comma-separated robot counts (default 1,2,4)")
    parser.add_argument("--seconds", type=float, default=10.0, help="measuring window per count (default 10)")
    parser.add_argument(
        "--profile",
        type=Path,
        help="after each window, py-spy the daemon for 5 s into PATH-<N>.txt (raw collapsed stacks)",
    )
    args = parser.parse_args()
    counts = [int(n) for n in args.robots.split(",") if n.strip()]
    if not counts or min(counts) < 1 or max(counts) > 200:
        parser.error("--robots: counts between 1 and 200")
    if not 0 < args.seconds <= 600:
        parser.error("--seconds: between 0 and 600")
    rows = []
    try:
        for n in counts:
            print(f"measuring {n} robot(s) for {args.seconds:g} s …", file=sys.stderr)
            rows.append(run_one(n, args.seconds, args.profile))
    except KeyboardInterrupt:
        print("interrupted; the processes are stopped", file=sys.stderr)
    if rows:
        print(table(rows, args.seconds))


if __name__ == "__main__":
    main()
