"""What one Zenoh publication costs the publishing process, with a subscriber in another process.

    python benchmarks/zenoh_put.py

Publishes a 400-byte sample (the size of a joint_states message) every 2 ms for a few seconds, as the
daemon does for every robot, and prints the CPU the publishing process spends per sample (the
calling thread's ``put`` and Zenoh's own threads), for the publisher settings worth comparing:
express or batched, real-time or data priority, drop or block when congested, Zenoh's low-latency
transport (at both ends, or at the publisher only), and a Unix socket instead of loopback TCP
between the two processes.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from typing import Any

import zenoh

from urdaemon.publish.session_config import zenoh_config

SAMPLES = 2500
PERIOD_S = 0.002
PAYLOAD = b"x" * 400


def subscribe(endpoint: str, low_latency: bool, seconds: float) -> None:
    """The subscriber process: count samples for ``seconds``."""
    session: Any = zenoh.open(zenoh_config("peer", [], [endpoint], low_latency=low_latency))
    received = [0]
    session.declare_subscriber("bench/**", lambda _: received.__setitem__(0, received[0] + 1))
    time.sleep(seconds)
    print(f"subscriber received {received[0]}", file=sys.stderr, flush=True)
    os._exit(0)


@dataclass(frozen=True)
class Setting:
    """One publisher configuration to measure (the defaults are urdaemon's state streams)."""

    label: str
    express: bool = True
    real_time_priority: bool = True
    drop: bool = True
    low_latency: bool = False
    subscriber_low_latency: bool = False
    unix: bool = False


SETTINGS = (
    Setting("express, real-time priority, drop (urdaemon's state streams)"),
    Setting("batched (express off)", express=False),
    Setting("data priority (Zenoh's default) instead of real-time", real_time_priority=False),
    Setting("block instead of drop when congested", drop=False),
    Setting("express + low-latency transport at both ends", low_latency=True, subscriber_low_latency=True),
    Setting("express + low-latency transport at the publisher only", low_latency=True),
    Setting("express, over a Unix socket", unix=True),
    Setting(
        "express + low-latency transport at both ends, over a Unix socket",
        low_latency=True,
        subscriber_low_latency=True,
        unix=True,
    ),
)


def publish(setting: Setting) -> None:
    """Publish SAMPLES samples at 500 Hz to a subscriber in another process; print the costs."""
    sockets = tempfile.mkdtemp(prefix="zenoh-put-")
    if setting.unix:
        endpoint = f"unixsock-stream/{sockets}/zenoh.sock"
    else:
        endpoint = f"tcp/127.0.0.1:{17600 + os.getpid() % 300}"
    session: Any = zenoh.open(zenoh_config("peer", [endpoint], [], low_latency=setting.low_latency))
    pub = session.declare_publisher(
        "bench/state",
        express=setting.express,
        congestion_control=zenoh.CongestionControl.DROP if setting.drop else zenoh.CongestionControl.BLOCK,
        priority=zenoh.Priority.REAL_TIME if setting.real_time_priority else zenoh.Priority.DATA,
    )
    seconds = SAMPLES * PERIOD_S + 3.0
    subscriber_flag = str(int(setting.subscriber_low_latency))
    sub = subprocess.Popen([sys.executable, __file__, "--subscribe", endpoint, subscriber_flag, str(seconds)])
    time.sleep(1.5)  # the subscriber connects and declares
    put_ns = 0
    idle_cpu = 0.0
    cpu0 = time.process_time()
    start = time.monotonic()
    for k in range(SAMPLES):
        before = time.thread_time_ns()
        pub.put(PAYLOAD)
        put_ns += time.thread_time_ns() - before
        before_sleep = time.thread_time()
        delay = start + (k + 1) * PERIOD_S - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        idle_cpu += time.thread_time() - before_sleep
    total = time.process_time() - cpu0 - idle_cpu  # without the pacing loop's own sleeps
    print(
        f"| {setting.label} | {put_ns / SAMPLES / 1e3:.1f} | {total / SAMPLES * 1e6:.1f} "
        f"| {total / SAMPLES * 500:.4f} |",
        flush=True,
    )
    sub.wait(seconds + 10)
    shutil.rmtree(sockets, ignore_errors=True)
    os._exit(0)


def main() -> None:
    """Each setting in its own process (a fresh session each time)."""
    if len(sys.argv) > 1 and sys.argv[1] == "--subscribe":
        subscribe(sys.argv[2], sys.argv[3] == "1", float(sys.argv[4]))
    if len(sys.argv) > 1 and sys.argv[1] == "--publish":
        publish(SETTINGS[int(sys.argv[2])])
    from importlib.metadata import version

    print(
        f"{SAMPLES} samples of {len(PAYLOAD)} B at 500 Hz, a subscriber in another process; "
        f"eclipse-zenoh {version('eclipse-zenoh')}"
    )
    print(
        "| publisher | put() µs (calling thread) | µs per sample (whole process) "
        "| CPU-s/s per 500 Hz stream |"
    )
    print("| --- | --- | --- | --- |")
    for index in range(len(SETTINGS)):
        subprocess.run([sys.executable, __file__, "--publish", str(index)], check=False, timeout=120)


if __name__ == "__main__":
    main()
