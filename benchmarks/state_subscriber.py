"""A Zenoh subscriber in its own process, for benchmarks/control_loop.py: state latency.

    python benchmarks/state_subscriber.py [--low-latency] ENDPOINT RESULT_FILE KEY [KEY ...]

Subscribes to every KEY (e.g. ``bench/*/joint_states``) through ENDPOINT and, for every sample that
carries ``host_time_ns`` (the daemon's ``time.time_ns()`` when the RTDE package arrived), records
``time.time_ns()`` on arrival here minus that: the latency from RTDE arrival in the daemon to this
process (same machine, same clock). SIGUSR1 starts a new window; SIGUSR2 writes the window's
figures to RESULT_FILE as JSON; SIGINT or SIGTERM ends the process. Prints ``subscribed`` when ready.
"""

from __future__ import annotations

import json
import signal
import sys
import threading
import time
from typing import Any

import zenoh

from urdaemon.publish.session_config import zenoh_config

MARK = b'"host_time_ns":'


def main() -> None:
    """Subscribe and serve the signals until told to stop."""
    args = sys.argv[1:]
    low_latency = "--low-latency" in args
    endpoint, result_file, *keys = [a for a in args if a != "--low-latency"]
    session: Any = zenoh.open(zenoh_config("peer", [], [endpoint], low_latency=low_latency))
    latencies: list[int] = []
    counts: dict[str, int] = {}

    def on_sample(sample: Any) -> None:
        now = time.time_ns()
        payload = sample.payload.to_bytes()
        at = payload.find(MARK)
        if at < 0:
            return
        end = payload.find(b",", at)
        latencies.append(now - int(payload[at + len(MARK) : end]))
        key = str(sample.key_expr)
        counts[key] = counts.get(key, 0) + 1

    subscribers: list[Any] = [session.declare_subscriber(key, on_sample) for key in keys]
    stop = threading.Event()

    def reset(*_: object) -> None:
        latencies.clear()
        counts.clear()

    def write(*_: object) -> None:
        window = sorted(latencies)
        n = len(window)
        figures = {
            "samples": n,
            "keys": len(counts),
            "p50_us": window[n // 2] / 1e3 if n else None,
            "p99_us": window[min(n - 1, int(n * 0.99))] / 1e3 if n else None,
            "max_us": window[-1] / 1e3 if n else None,
        }
        with open(result_file, "w") as out:
            json.dump(figures, out)

    signal.signal(signal.SIGUSR1, reset)
    signal.signal(signal.SIGUSR2, write)
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    print("subscribed", flush=True)
    while not stop.wait(0.5):
        pass
    for subscriber in subscribers:
        subscriber.undeclare()
    session.close()


if __name__ == "__main__":
    main()
