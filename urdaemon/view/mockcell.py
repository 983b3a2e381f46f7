"""The cell ``urdaemon view --config cell.yaml`` starts: the cell file with every robot on the mock
backend (it never drives a real robot), served by a daemon in a child process on a loopback port.

A child process, so the viewer's threads (viser's server, its callbacks) never share the daemon's
interpreter with the robots' cycles. ``python -m urdaemon.view.mockcell CELL --listen ENDPOINT``
is that child: it imports no viser and no numpy beyond what ``serve`` does.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import signal
import socket
import subprocess
import sys
from collections.abc import AsyncIterator, Sequence
from pathlib import Path
from typing import Any

import yaml

from urdaemon.errors import ConfigError, UrDaemonError

__all__ = ["START_TIMEOUT_S", "mock_cell", "mock_cell_text"]

START_TIMEOUT_S = 60.0
"""How long the child may take to serve (it builds the cell URDF first)."""
STOP_TIMEOUT_S = 15.0
"""How long the child may take to stop after SIGTERM before it is killed."""
PORT_TRIES = 3
"""A port free a moment ago may be taken before the child listens on it: try another."""
_DROPPED = ("ur", "servo", "address", "ports", "headless")
"""Robot fields only a real backend uses."""


def mock_cell_text(path: str | Path) -> str:
    """The cell file at ``path`` with every robot on the mock backend and no Zenoh section (the child
    listens where it is told); raises ``ConfigError`` when the file is not a valid cell."""
    from urdaemon.cell import load_cell

    load_cell(path)  # the user's own file first: its errors name its lines
    data: Any = yaml.safe_load(Path(path).read_text(encoding="utf-8"))
    data.pop("zenoh", None)
    for robot in data.get("robots") or []:
        if isinstance(robot, dict):
            robot["backend"] = "mock"
            for field in _DROPPED:
                robot.pop(field, None)
    return yaml.safe_dump(data, sort_keys=False)


@contextlib.asynccontextmanager
async def mock_cell(path: str | Path) -> AsyncIterator[str]:
    """Serve the mock copy of the cell at ``path`` in a child process; yield its Zenoh endpoint once
    a client can connect; stop the child (SIGTERM, then kill) however the block ends."""
    mock_cell_text(path)  # refuse a bad cell file here, with its reasons, before any child starts
    for attempt in range(1, PORT_TRIES + 1):
        endpoint = f"tcp/127.0.0.1:{_free_port()}"
        child = await asyncio.create_subprocess_exec(
            *_child_command(path, endpoint), stdin=subprocess.DEVNULL
        )
        try:
            if await _serving(child, endpoint):
                yield endpoint
                return
            if attempt == PORT_TRIES:
                raise UrDaemonError(f"the mock cell did not start (exit code {child.returncode})")
        finally:
            await _stop(child)


def _child_command(path: str | Path, endpoint: str) -> list[str]:
    return [sys.executable, "-m", "urdaemon.view.mockcell", str(Path(path).resolve()), "--listen", endpoint]


async def _serving(child: asyncio.subprocess.Process, endpoint: str) -> bool:
    """Wait until a client connects to ``endpoint``: True; False when the child ended first."""
    from urdaemon.client import Client

    loop = asyncio.get_running_loop()
    deadline = loop.time() + START_TIMEOUT_S
    while child.returncode is None:
        if loop.time() > deadline:
            raise UrDaemonError(f"the mock cell did not serve at {endpoint} within {START_TIMEOUT_S:g} s")
        try:
            client = await Client.connect(endpoint, timeout=1.0)
        except UrDaemonError:
            continue
        await client.close()
        return True
    return False


async def _stop(child: asyncio.subprocess.Process) -> None:
    if child.returncode is None:
        child.send_signal(signal.SIGTERM)
        try:
            await asyncio.wait_for(child.wait(), STOP_TIMEOUT_S)
        except TimeoutError:
            child.kill()
            await child.wait()


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
    return port


def main(argv: Sequence[str] | None = None) -> int:
    """The child: serve the mock copy of a cell file until SIGTERM or SIGINT."""
    from urdaemon.cell import parse_cell
    from urdaemon.daemon import Daemon

    parser = argparse.ArgumentParser(prog="python -m urdaemon.view.mockcell")
    parser.add_argument("config")
    parser.add_argument("--listen", required=True)
    args = parser.parse_args(argv)
    try:
        cell = parse_cell(mock_cell_text(args.config), base_dir=Path(args.config).resolve().parent)
    except ConfigError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2

    async def run() -> None:
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, stop.set)
        await Daemon(cell, listen=(args.listen,)).run(stop)

    asyncio.run(run())
    return 0


if __name__ == "__main__":
    sys.exit(main())
