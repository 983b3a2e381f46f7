"""The longest the daemon's event loop is held by one client message, for each kind of bad or big input.

    python benchmarks/input_stalls.py            # every input 3 times, the full sizes
    python benchmarks/input_stalls.py --repeat 5

A daemon serving two mock robots runs in this process (they also take passthrough goals, encoding
their points with the trajectory-point protocol as the ``ur`` backend does); a client process
connected over loopback TCP sends the inputs (its own encoding and sending are not counted).
A probe task turns the loop as fast as it can (``await asyncio.sleep(0)``) and records the longest
gap between two of its turns: the longest any one callback (or a thread holding the GIL) kept every
robot's cycle waiting. Each input is sent ``--repeat`` times; for each send the worst gap while it
is received, answered and fully processed (a query: until its reply; a put: 50 ms after) is taken.
The table gives the least of these (the stall the input causes every time; on a busy machine a
send's worst gap also holds the moments the OS ran another process) and the greatest, against the
same for windows with no input (the baseline). Every robot cycle is 2 ms at 500 Hz: a stall must
stay well below that.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import secrets
import socket
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from urdaemon import daemon as daemon_module
from urdaemon.backends.mock import MockBackend
from urdaemon.cell import parse_cell
from urdaemon.client import Client
from urdaemon.daemon import Daemon
from urdaemon.protocols import trajectory_point
from urdaemon.publish.envelope import SMALL_MESSAGE_BYTES
from urdaemon.publish.lease_request import LeaseRequest, lease_body

ROOT = Path(__file__).resolve().parents[1]
HOME = [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]
CELL = """
cell: stalls
robots:
  - name: alice
    model: ur10e
    backend: mock
    mock: {initial_positions: [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]}
  - name: bob
    model: ur10e
    backend: mock
    pose: {xyz: [1.0, 0.0, 0.0]}
    mock: {initial_positions: [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]}
"""
LARGEST_READ = f"{SMALL_MESSAGE_BYTES // 1024} KiB garbage move (largest read)"
"""The largest garbage message still read (the size limit of every message but a trajectory)."""
PUT_SETTLE_S = 0.05
BASELINE_WINDOW_S = 0.3
"""Length of a window with no input (as long as the longest input takes to be processed)."""


@dataclass(frozen=True)
class Input:
    """One kind of input: a query (``get``) or a put on ``key`` with ``payload``."""

    name: str
    key: str
    payload: bytes
    put: bool = False


def trajectory(points: int, *, passthrough: bool = False) -> bytes:
    """A valid trajectory goal of ``points`` points with velocities and accelerations, 10 ms apart (a
    slow swing of 0.05 rad from rest), its last point at rest a second after the one before."""
    body: list[dict[str, object]] = []
    for k in range(points - 1):
        t = 0.5 + k * 0.01
        body.append(
            {
                "positions": [round(h + 0.05 * (1 - math.cos(t)), 6) for h in HOME],
                "velocities": [round(0.05 * math.sin(t), 6)] * 6,
                "accelerations": [round(0.05 * math.cos(t), 6)] * 6,
                "time_from_start": round(t, 6),
            }
        )
    end = round(0.5 + (points - 2) * 0.01 + 1.0, 6)
    rest = body[-1]["positions"] if body else HOME
    body.append(
        {"positions": rest, "velocities": [0.0] * 6, "accelerations": [0.0] * 6, "time_from_start": end}
    )
    goal: dict[str, object] = {"points": body}
    if passthrough:
        goal["passthrough"] = True
    return json.dumps(goal, separators=(",", ":")).encode()


def inputs(scale: float = 1.0) -> list[Input]:
    """Every kind of input measured; ``scale`` shrinks the big ones (1.0: the full sizes)."""
    base = "stalls/alice"

    def n(count: int) -> int:
        return max(1, int(count * scale))

    return [
        Input("1 MB garbage move", f"{base}/goal/move", b"x" * n(1_000_000)),
        Input(
            "1 MB move of 250 000 positions", f"{base}/goal/move", _numbers("positions", n(250_000), "0.1")
        ),
        Input(LARGEST_READ, f"{base}/goal/move", b"[" + b"1," * n((SMALL_MESSAGE_BYTES - 3) // 2) + b"1]"),
        Input("64 KiB move of 7 000 positions", f"{base}/goal/move", _numbers("positions", n(7_000))),
        Input(
            f"valid {n(5000)}-point trajectory (pos, vel, acc)",
            f"{base}/goal/trajectory",
            trajectory(n(5000)),
        ),
        Input(
            f"valid {n(5000)}-point passthrough trajectory",
            f"{base}/goal/trajectory",
            trajectory(n(5000), passthrough=True),
        ),
        Input("2 MiB trajectory, one huge point", f"{base}/goal/trajectory", _one_huge_point(n(2_000_000))),
        Input(
            "2 MiB of whitespace and garbage",
            f"{base}/goal/trajectory",
            b'{"points": [' + b" " * n(2_000_000),
        ),
        Input(
            "200 000-value stream command",
            f"{base}/command/joint_position",
            _numbers("positions", n(200_000)),
            put=True,
        ),
        Input(
            "64 KiB stream command (7 000 values)",
            f"{base}/command/joint_position",
            _numbers("positions", n(7_000)),
            put=True,
        ),
        Input("64 KiB deeply nested JSON (service)", f"{base}/service/set_payload", _nested(n(30_000))),
        Input("64 KiB of unknown fields (service)", f"{base}/service/startup", _fields(n(3_500))),
        Input("wildcard get ** (every queryable)", "**", b""),
    ]


def _numbers(field: str, count: int, text: str = "0.123456") -> bytes:
    return f'{{"{field}":[{",".join([text] * count)}]}}'.encode()


def _one_huge_point(size: int) -> bytes:
    values = ",".join(["0.1"] * (size // 4))
    return f'{{"points":[{{"positions":[{values}],"time_from_start":1}}]}}'.encode()


def _nested(depth: int) -> bytes:
    return b'{"mass":' + b"[" * depth + b"]" * depth + b"}"


def _fields(count: int) -> bytes:
    return json.dumps({f"field_{i}": i for i in range(count)}, separators=(",", ":")).encode()


class PassthroughMock(MockBackend):
    """A mock robot that takes passthrough goals: their points are encoded as the ``ur`` backend
    encodes them (84-byte trajectory-point frames), then dropped; the robot "runs" the goal until it is
    canceled."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.running: str | None = None

    def passthrough_problem(self) -> str | None:
        return None if self.running is None else f"passthrough goal {self.running} is still running"

    def encode_passthrough_point(self, *point: Any) -> bytes:
        return trajectory_point.encode_point(trajectory_point.SplinePoint(*point))

    def start_encoded_passthrough(self, goal_id: str, frames: bytes, count: int, on_result: Any) -> None:
        self.running = goal_id

    def cancel_passthrough(self) -> None:
        self.running = None


class Probe:
    """Turns the loop as fast as it can; ``worst`` is the longest gap between two turns since ``reset``."""

    def __init__(self) -> None:
        self.worst = 0.0
        self._task: asyncio.Task[None] | None = None

    def reset(self) -> None:
        self.worst = 0.0

    async def _run(self) -> None:
        last = time.perf_counter()
        while True:
            await asyncio.sleep(0)
            now = time.perf_counter()
            self.worst = max(self.worst, now - last)
            last = now

    def start(self) -> None:
        self._task = asyncio.get_running_loop().create_task(self._run())

    async def stop(self) -> None:
        if self._task is not None:
            self._task.cancel()
            await asyncio.gather(self._task, return_exceptions=True)


def sender(endpoint: str, scale: float) -> None:
    """The client, in a process of its own (its own encoding and sending must not count): reads the
    index of an input on stdin, sends it, waits for the reply (a put: ``PUT_SETTLE_S``), cancels any
    goal it started, and prints ``done``."""
    import sys

    import zenoh

    from urdaemon.publish.session_config import zenoh_config

    items = inputs(scale)
    session: Any = zenoh.open(zenoh_config("peer", [], [endpoint]))
    try:
        # the sender holds alice's command lease, so its inputs are read as the holder's would be
        # (a client without it is refused on Zenoh's thread before anything reads the payload)
        token, _held = _lease(session)
        print("ready", flush=True)
        for line in sys.stdin:
            item = items[int(line)]
            if item.put:
                session.put(item.key, item.payload, attachment=token)
                time.sleep(PUT_SETTLE_S)
            else:
                list(session.get(item.key, payload=item.payload or None, attachment=token, timeout=10.0))
                # an accepted goal must not run on
                list(session.get("stalls/alice/goal/cancel", attachment=token, timeout=10.0))
            print("done", flush=True)
    finally:
        session.close()


def _lease(session: Any) -> tuple[bytes, Any]:
    """Acquire alice's command lease as a client does (its liveliness token first); the token to
    attach, and the liveliness token to keep while it is held."""
    secret = secrets.token_hex(16)  # the lease's session id: only its holder knows it
    held = session.liveliness().declare_token(f"stalls/alice/lease/{secret}")
    body = json.dumps(lease_body(LeaseRequest("acquire", secret, "input_stalls benchmark")))
    replies = [
        r.ok.payload.to_bytes() for r in session.get("stalls/alice/lease", payload=body, timeout=10.0) if r.ok
    ]
    grant = json.loads(replies[0]) if replies else {}
    if grant.get("ok") is not True:
        raise RuntimeError(f"alice's command lease was not granted: {grant or 'no answer'}")
    return str(grant["token"]).encode(), held


async def measure(
    scale: float = 1.0,
    repeat: int = 3,
    on_row: Callable[[str, float, float], None] | None = None,
) -> dict[str, float]:
    """Run the daemon and the probe here, the sender in a subprocess; for each input (and
    ``baseline``) the worst stall (s) it caused in every one of ``repeat`` sends (the least of the
    sends' worst stalls: what the machine's own hiccups add to a send is not in it)."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        endpoint = f"tcp/127.0.0.1:{sock.getsockname()[1]}"
    daemon = Daemon(parse_cell(CELL, base_dir=ROOT / "configs"), listen=(endpoint,))
    stop = asyncio.Event()
    # the mock robots this daemon builds take passthrough goals (restored once it is built)
    mock = vars(daemon_module)["MockBackend"]
    setattr(daemon_module, "MockBackend", PassthroughMock)  # noqa: B010
    try:
        serving = asyncio.create_task(daemon.run(stop))
        for _ in range(1000):  # bounded: building is synchronous, at the task's first step
            if daemon.runtimes:
                break
            await asyncio.sleep(0)
    finally:
        setattr(daemon_module, "MockBackend", mock)  # noqa: B010
    results: dict[str, float] = {}
    probe = Probe()
    proc = await asyncio.create_subprocess_exec(
        sys.executable,
        __file__,
        "--sender",
        endpoint,
        "--scale",
        str(scale),
        stdin=asyncio.subprocess.PIPE,
        stdout=asyncio.subprocess.PIPE,
    )
    assert proc.stdin is not None
    assert proc.stdout is not None
    try:
        if (await asyncio.wait_for(proc.stdout.readline(), 30.0)).strip() != b"ready":
            raise RuntimeError("the sender did not start")
        client = await Client.connect(endpoint)
        try:
            for name in ("alice", "bob"):
                await client.robot(name, timeout=10.0)
        finally:
            await client.close()
        items = inputs(scale)  # before the probe starts: encoding them here is not what is measured
        probe.start()
        windows = []
        for _ in range(repeat):
            probe.reset()
            await asyncio.sleep(BASELINE_WINDOW_S)
            windows.append(probe.worst)
        results["baseline"] = min(windows)
        if on_row is not None:
            on_row("baseline (no input)", min(windows), max(windows))
        for index, item in enumerate(items):
            windows = []
            for _ in range(repeat):
                probe.reset()
                proc.stdin.write(f"{index}\n".encode())
                await proc.stdin.drain()
                if (await asyncio.wait_for(proc.stdout.readline(), 60.0)).strip() != b"done":
                    raise RuntimeError(f"the sender failed on {item.name}")
                windows.append(probe.worst)
            results[item.name] = min(windows)
            if on_row is not None:
                on_row(item.name, min(windows), max(windows))
    finally:
        await probe.stop()
        proc.stdin.close()
        await asyncio.wait_for(proc.wait(), 30.0)
        stop.set()
        await asyncio.wait_for(serving, 20.0)
    return results


def main() -> None:
    """Measure every input and print a table."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0] if __doc__ else None)
    parser.add_argument("--repeat", type=int, default=5, help="times each input is sent")
    parser.add_argument("--scale", type=float, default=1.0, help="size of the big inputs (1: full)")
    parser.add_argument("--sender", metavar="ENDPOINT", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.sender:
        sender(args.sender, args.scale)
        return
    items = inputs(args.scale)
    print(f"{'input':<48} {'bytes':>10} {'stall, every send':>18} {'worst send':>11}")

    sizes: dict[str, int] = {item.name: len(item.payload) for item in items}

    def row(name: str, every: float, worst: float) -> None:
        size = f"{sizes[name]:,}" if name in sizes else ""
        print(f"{name:<48} {size:>10} {every * 1e3:>15.2f} ms {worst * 1e3:>8.2f} ms", flush=True)

    asyncio.run(measure(args.scale, args.repeat, on_row=row))


if __name__ == "__main__":
    main()
