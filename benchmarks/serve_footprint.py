"""The serve process's footprint: time to serving and resident memory.

    python benchmarks/serve_footprint.py [--config FILE] [--runs N] [--hold SECONDS] [--imports] [--steps]

Starts ``urdaemon serve --config FILE --listen tcp/127.0.0.1:PORT`` (PORT free, from the OS) as a
subprocess, queries the cell's ``robot_description`` through that endpoint until it answers (the
moment the cell serves; the querying session retries its connection every 10 ms, so the time is
not rounded up to Zenoh's default 1 s retry), keeps it serving for ``--hold`` seconds, then reads
VmRSS and VmHWM from ``/proc/PID/status``. Prints each run and the medians.

As a diagnosis instead: ``--imports`` prints the serve modules' top imports by cumulative time
(``python -X importtime``); ``--steps`` prints VmRSS after each step of serve's start in a fresh
interpreter (the big imports in serve's order, loading and describing the cell, opening the
daemon's Zenoh session, building the robots), each with what it added.
"""

from __future__ import annotations

import argparse
import socket
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import yaml
import zenoh

from urdaemon.publish.session_config import zenoh_config

ROOT = Path(__file__).resolve().parent.parent


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


def _status_kib(pid: int) -> dict[str, int]:
    fields: dict[str, int] = {}
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        name, _, value = line.partition(":")
        if name in ("VmRSS", "VmHWM"):
            fields[name] = int(value.split()[0])
    return fields


def _wait_serving(endpoint: str, key: str, proc: subprocess.Popen[bytes], limit: float) -> None:
    conf = zenoh_config("peer", [], [endpoint])
    # serve is not listening yet: retry every 10 ms rather than after Zenoh's default 1 s
    conf.insert_json5(
        "connect/retry", '{"period_init_ms": 10, "period_max_ms": 10, "period_increase_factor": 1}'
    )
    session: Any = zenoh.open(conf)
    try:
        deadline = time.monotonic() + limit
        while time.monotonic() < deadline:
            if proc.poll() is not None:
                raise RuntimeError(f"serve exited with {proc.returncode}")
            for reply in session.get(key, timeout=0.2):
                if reply.ok is not None:
                    return
            time.sleep(0.01)
        raise RuntimeError(f"no answer on {key} within {limit} s")
    finally:
        session.close()


def one_run(config: Path, hold: float) -> tuple[float, dict[str, int]]:
    """Start serve, time it to serving, hold, read its memory; returns (seconds, kib fields)."""
    cell = yaml.safe_load(config.read_text())["cell"]
    endpoint = f"tcp/127.0.0.1:{_free_port()}"
    cmd = [sys.executable, "-m", "urdaemon", "serve", "--config", str(config), "--listen", endpoint]
    start = time.monotonic()
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        _wait_serving(endpoint, f"{cell}/robot_description", proc, 30.0)
        serving = time.monotonic() - start
        time.sleep(hold)
        return serving, _status_kib(proc.pid)
    finally:
        proc.terminate()
        proc.wait(timeout=10)


def print_imports(top: int) -> None:
    """The serve modules' imports, largest cumulative time first."""
    done = subprocess.run(
        [sys.executable, "-X", "importtime", "-c", "import urdaemon.cli, urdaemon.daemon"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
    )
    rows = []
    for line in done.stderr.splitlines():
        parts = line.split("|")
        if len(parts) == 3 and parts[1].strip().isdigit():
            rows.append((int(parts[1]), parts[2].rstrip()))
    for cumulative, name in sorted(rows, reverse=True)[:top]:
        print(f"{cumulative / 1000:8.1f} ms  {name}")


STEPS = """
import sys, time
def rss():
    with open("/proc/self/status") as status:
        return next(int(line.split()[1]) / 1024 for line in status if line.startswith("VmRSS"))
last = rss()
def step(name, start):
    global last
    now, took = rss(), (time.perf_counter() - start) * 1000
    print(f"{name:34s} {now:6.1f} MiB  +{now - last:5.1f}  {took:6.1f} ms")
    last = now
print(f"{'interpreter':34s} {last:6.1f} MiB")
MODULES = (
    "asyncio", "zenoh", "pydantic", "yaml", "xacro", "ruckig", "urdaemon.cell", "urdaemon.description",
    "urdaemon.control", "urdaemon.publish.node", "urdaemon.robot", "urdaemon.daemon", "urdaemon.cli",
)
for module in MODULES:
    start = time.perf_counter()
    __import__(module)
    step("import " + module, start)
import asyncio
from urdaemon.cell import load_cell
from urdaemon.daemon import Daemon
from urdaemon.publish.node import ZenohNode
start = time.perf_counter()
cell = load_cell(sys.argv[1])
step("load the cell file", start)
start = time.perf_counter()
daemon = Daemon(cell, listen=(sys.argv[2],))
step("describe the cell (URDF, limits)", start)
async def serve():
    start = time.perf_counter()
    node = ZenohNode(cell.zenoh, asyncio.get_running_loop(), listen=(sys.argv[2],))
    step("open the Zenoh session", start)
    start = time.perf_counter()
    daemon._build(node)
    step("build backends, controllers", start)
    await asyncio.sleep(2.0)
    step("after 2 s, nobody connected", time.perf_counter())
    node.close()
asyncio.run(serve())
print("numpy loaded:", "numpy" in sys.modules)
"""


def print_steps(config: Path) -> None:
    """VmRSS after each step of serve's start, in a fresh interpreter."""
    endpoint = f"tcp/127.0.0.1:{_free_port()}"
    subprocess.run([sys.executable, "-c", STEPS, str(config), endpoint], cwd=ROOT, check=True)


def main() -> None:
    """Parse the options and run."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", type=Path, default=ROOT / "configs" / "dual_robot_mock.yaml")
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--hold", type=float, default=5.0)
    parser.add_argument("--imports", action="store_true")
    parser.add_argument("--steps", action="store_true")
    args = parser.parse_args()
    if args.imports:
        print_imports(25)
        return
    if args.steps:
        print_steps(args.config)
        return
    times, rss, hwm = [], [], []
    for run in range(args.runs):
        serving, kib = one_run(args.config, args.hold)
        times.append(serving)
        rss.append(kib["VmRSS"] / 1024)
        hwm.append(kib["VmHWM"] / 1024)
        print(f"run {run}: serving after {serving:.2f} s, VmRSS {rss[-1]:.1f} MiB, VmHWM {hwm[-1]:.1f} MiB")
    print(
        f"median of {args.runs}: serving after {statistics.median(times):.2f} s, "
        f"VmRSS {statistics.median(rss):.1f} MiB, VmHWM {statistics.median(hwm):.1f} MiB"
    )


if __name__ == "__main__":
    main()
