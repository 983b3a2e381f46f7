"""The ``urdaemon foxglove`` command, in this process: it serves a running cell, prints its ws:// URL
and ends cleanly on Ctrl-C; without foxglove-sdk it names the extra to install; a bad port is bad
input."""

from __future__ import annotations

import asyncio
import io
import os
import re
import signal
import socket
import sys
import threading
from collections.abc import Iterator

import pytest

from tests.helpers import run_cli
from tests.integration.conftest import TWO_MOCKS, running_daemon
from urdaemon.foxglove_bridge.command import NEEDS_EXTRA


class _Recorder(io.StringIO):
    """Stands in for stdout: tells when the bridge's URL is printed."""

    def __init__(self) -> None:
        super().__init__()
        self.url: str | None = None
        self.printed = threading.Event()

    def write(self, text: str) -> int:
        written = super().write(text)
        found = re.search(r"ws://127\.0\.0\.1:(\d+)", self.getvalue())
        if found is not None and not self.printed.is_set():
            self.url = found.group(0)
            self.printed.set()
        return written


@pytest.fixture
def endpoint() -> Iterator[str]:
    """A mock cell served by a thread of its own (the command runs its own loop in this thread)."""
    ready: list[str] = []
    up, stop = threading.Event(), threading.Event()

    async def serve() -> None:
        async with running_daemon(TWO_MOCKS) as (_, client):
            ready.append(client.endpoint)
            up.set()
            await asyncio.get_running_loop().run_in_executor(None, stop.wait, 120)

    thread = threading.Thread(target=asyncio.run, args=(serve(),), daemon=True)
    thread.start()
    assert up.wait(60), "the mock cell did not start"
    try:
        yield ready[0]
    finally:
        stop.set()
        thread.join(30)


@pytest.mark.timeout(180)
def test_foxglove_serves_a_cell_and_ends_on_ctrl_c(
    endpoint: str, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from urdaemon.cli import main

    out = _Recorder()
    monkeypatch.setattr(sys, "stdout", out)
    connected: list[bool] = []

    def connect_then_interrupt() -> None:
        if not out.printed.wait(120):  # the command ends by itself then (an error): nothing to interrupt
            return
        assert out.url is not None
        try:
            port = int(out.url.rsplit(":", 1)[1])
            with socket.create_connection(("127.0.0.1", port), timeout=30):
                connected.append(True)
        finally:
            os.kill(os.getpid(), signal.SIGINT)  # Ctrl-C

    visitor = threading.Thread(target=connect_then_interrupt, daemon=True)
    visitor.start()
    code = main(["foxglove", "--connect", endpoint, "--port", "0"])
    visitor.join(30)
    assert code == 0, (out.getvalue(), capsys.readouterr().err)
    assert "urdaemon foxglove of cell 'testcell': ws://127.0.0.1:" in out.getvalue()
    assert out.url is not None
    assert not out.url.endswith(":0")
    assert connected == [True]


def test_foxglove_without_the_sdk_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "foxglove", None)  # `import foxglove` raises ImportError
    result = run_cli("foxglove", "--port", "0")
    assert result.code == 2
    assert NEEDS_EXTRA in result.stderr
    assert NEEDS_EXTRA == "urdaemon foxglove needs the foxglove extra: pip install 'urdaemon[foxglove]'"


@pytest.mark.parametrize("port", ["70000", "-1", "http"])
def test_a_bad_port_is_bad_input(port: str) -> None:
    result = run_cli("foxglove", "--port", port)
    assert result.code == 2
    assert "--port" in result.stderr


@pytest.mark.timeout(120)
def test_a_taken_port_is_named(endpoint: str) -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        result = run_cli("foxglove", "--connect", endpoint, "--port", str(port))
    assert result.code == 1
    assert "the Foxglove server did not start" in result.stderr
    assert "Address already in use" in result.stderr
