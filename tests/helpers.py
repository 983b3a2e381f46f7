"""Shared test helpers: free loopback ports, waiting on a subprocess's log lines."""

from __future__ import annotations

import asyncio
import socket
import subprocess
import time

__all__ = ["drain_in_background", "free_tcp_port", "wait_for_line"]


_HANDED_OUT: set[int] = set()
"""Ports this test process was already given: the kernel may offer a released port again at once,
and two of a cell's callback ports must never be the same."""


def free_tcp_port(host: str = "127.0.0.1") -> int:
    """A TCP port on ``host`` that was free a moment ago and not handed out before in this process."""
    for _ in range(1000):
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
            sock.bind((host, 0))
            port: int = sock.getsockname()[1]
        if port not in _HANDED_OUT:
            _HANDED_OUT.add(port)
            return port
    raise RuntimeError("no fresh free TCP port in 1000 attempts")


async def wait_for_line(proc: subprocess.Popen[str], text: str, *, timeout: float) -> list[str]:
    """Read the process's stderr until a line contains ``text``; returns the lines read."""
    assert proc.stderr is not None
    stream = proc.stderr
    loop = asyncio.get_running_loop()
    deadline = time.monotonic() + timeout
    lines: list[str] = []
    while time.monotonic() < deadline:
        line = await asyncio.wait_for(
            loop.run_in_executor(None, stream.readline), deadline - time.monotonic()
        )
        if not line:
            raise AssertionError(
                f"process exited ({proc.poll()}) before printing {text!r}:\n{''.join(lines)}"
            )
        lines.append(line)
        if text in line:
            return lines
    raise AssertionError(f"{text!r} not printed within {timeout} s:\n{''.join(lines)}")


def drain_in_background(proc: subprocess.Popen[str], sink: list[str]) -> None:
    """Keep reading the process's stderr into ``sink`` so its pipe never fills up."""
    import threading

    assert proc.stderr is not None
    stream = proc.stderr

    def pump() -> None:
        for line in stream:
            sink.append(line)

    threading.Thread(target=pump, name="stderr-drain", daemon=True).start()
