"""Shared test helpers: free loopback ports and fake-robot addresses, waiting on a subprocess's log lines."""

from __future__ import annotations

import asyncio
import contextlib
import secrets
import socket
import subprocess
import time
from collections.abc import Iterator

__all__ = ["UR_PORTS", "drain_in_background", "fake_address", "free_tcp_port", "wait_for_line"]


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


UR_PORTS = (29999, 30001, 30002, 30003, 30004)
"""The controller's fixed ports (dashboard, primary, secondary, real-time, RTDE) a fake robot listens on."""


def _addresses() -> Iterator[str]:
    """This process's fake-robot addresses: 127.a.b.1 to .254 of a /24 chosen at random (1 <= a, b <= 254,
    so never 127.0.0.x), then on through the next /24s. Chosen by the OS (not ``random``, which
    pytest-randomly seeds alike in every run), so two runs side by side almost never meet, and
    ``fake_address`` checks the ports anyway."""
    first = secrets.randbelow(254 * 254)
    for index in range(254 * 254):
        a, b = divmod((first + index) % (254 * 254), 254)
        for c in range(1, 255):
            yield f"127.{a + 1}.{b + 1}.{c}"


_ADDRESSES = _addresses()


def _ur_ports_free(address: str) -> bool:
    """Whether a fake robot could listen on all of UR's ports at ``address`` right now."""
    with contextlib.ExitStack() as stack:
        for port in UR_PORTS:
            sock = stack.enter_context(socket.socket(socket.AF_INET, socket.SOCK_STREAM))
            # As asyncio's servers do: a lingering TIME_WAIT does not block, a listener does.
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            try:
                sock.bind((address, port))
            except OSError:
                return False
    return True


def fake_address() -> str:
    """A loopback address for one fake robot, never handed out before in this process.

    It lies in this run's own 127.a.b.0/24 (never 127.0.0.x) and UR's fixed ports (``UR_PORTS``)
    were free on it a moment ago: pass it as ``FakeController(address=...)`` and as the robot's
    ``address`` in the cell, so two runs of the suite on one machine never meet on a port.
    """
    for _, address in zip(range(10_000), _ADDRESSES, strict=False):
        if _ur_ports_free(address):
            return address
    raise RuntimeError("no free fake-robot address in 10000 tries")


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
