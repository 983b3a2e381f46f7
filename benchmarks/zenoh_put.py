"""What one Zenoh publication costs the publishing process, with a subscriber in another process.

    python benchmarks/zenoh_put.py

Publishes a 400-byte sample (the size of a joint_states message) every 2 ms for a few seconds, as the
daemon does for every robot, and prints the CPU the publishing process spends per sample (the
calling thread's ``put`` and Zenoh's own threads), for the publisher settings worth comparing:
express or batched, Zenoh's low-latency transport (at both ends, or at the publisher only), and a
Unix socket instead of loopback TCP between the two processes.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import time
from typing import Any

import zenoh

from urdaemon.publish.node import zenoh_config

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


def publish(label: str, express: bool, low_latency: bool, subscriber_low_latency: bool, unix: bool) -> None:
    """Publish SAMPLES samples at 500 Hz to a subscriber in another process; print the costs."""
    sockets = tempfile.mkdtemp(prefix="zenoh-put-")
    if unix:
        endpoint = f"unixsock-stream/{sockets}/zenoh.sock"
    else:
        endpoint = f"tcp/127.0.0.1:{17600 + os.getpid() % 300}"
    session: Any = zenoh.open(zenoh_config("peer", [endpoint], [], low_latency=low_latency))
    pub = session.declare_publisher(
        "bench/state",
        express=express,
        congestion_control=zenoh.CongestionControl.DROP,
        priority=zenoh.Priority.REAL_TIME,
    )
    seconds = SAMPLES * PERIOD_S + 3.0
    sub = subprocess.Popen(
        [sys.executable, __file__, "--subscribe", endpoint, str(int(subscriber_low_latency)), str(seconds)]
    )
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
        f"| {label} | {put_ns / SAMPLES / 1e3:.1f} | {total / SAMPLES * 1e6:.1f} "
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
        publish(sys.argv[2], *(flag == "1" for flag in sys.argv[3:7]))
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
    for label, express, low_latency, subscriber_low_latency, unix in (
        ("express, real-time priority, drop (urdaemon's state streams)", True, False, False, False),
        ("batched (express off)", False, False, False, False),
        ("express + low-latency transport at both ends", True, True, True, False),
        ("express + low-latency transport at the publisher only", True, True, False, False),
        ("express, over a Unix socket", True, False, False, True),
        ("express + low-latency transport at both ends, over a Unix socket", True, True, True, True),
    ):
        flags = [str(int(flag)) for flag in (express, low_latency, subscriber_low_latency, unix)]
        subprocess.run(
            [sys.executable, __file__, "--publish", label, *flags],
            check=False,
            timeout=120,
        )


if __name__ == "__main__":
    main()
