"""The ``urdaemon view`` command, in this process: ``--config`` starts a mock copy of the demo cell in a
child process, serves the page, and ends cleanly on Ctrl-C; without viser it says which extra to
install.

Reproduction on the code before issue 18: ``urdaemon view`` was a usage error (exit 2, "invalid
choice: 'view'"), without the page or the message.
"""

from __future__ import annotations

import io
import os
import re
import signal
import sys
import threading
import urllib.request
from pathlib import Path

import pytest
import yaml

from tests.helpers import run_cli
from tests.integration.conftest import ROOT
from urdaemon.view.command import NEEDS_EXTRA
from urdaemon.view.mockcell import mock_cell_text

DEMO = ROOT / "configs" / "dual_robot_mock.yaml"


class _Recorder(io.StringIO):
    """Stands in for stdout: tells when the view's URL is printed."""

    def __init__(self) -> None:
        super().__init__()
        self.url: str | None = None
        self.printed = threading.Event()

    def write(self, text: str) -> int:
        written = super().write(text)
        found = re.search(r"http://127\.0\.0\.1:\d+", self.getvalue())
        if found is not None and not self.printed.is_set():
            self.url = found.group(0)
            self.printed.set()
        return written


@pytest.mark.timeout(180)
def test_view_config_serves_a_mock_cell_and_ends_on_ctrl_c(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from urdaemon.cli import main

    out = _Recorder()
    monkeypatch.setattr(sys, "stdout", out)
    fetched: list[bytes] = []

    def visit_then_interrupt() -> None:
        if not out.printed.wait(150):  # the command ends by itself then (an error): nothing to interrupt
            return
        assert out.url is not None
        try:
            fetched.append(urllib.request.urlopen(out.url, timeout=30).read())
        finally:
            os.kill(os.getpid(), signal.SIGINT)  # Ctrl-C

    visitor = threading.Thread(target=visit_then_interrupt, daemon=True)
    visitor.start()
    code = main(["view", "--config", str(DEMO), "--port", "0"])
    visitor.join(30)
    assert code == 0, (out.getvalue(), capsys.readouterr().err)
    assert out.url is not None
    assert not out.url.endswith(":0")
    assert fetched
    assert b"viser" in fetched[0].lower()
    assert "urdaemon view of cell 'demo_cell'" in out.getvalue()


def test_view_without_viser_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "viser", None)  # `import viser` raises ImportError
    result = run_cli("view", "--port", "0")
    assert result.code == 2
    assert NEEDS_EXTRA in result.stderr
    assert NEEDS_EXTRA == "urdaemon view needs the view extra: pip install 'urdaemon[view]'"


def test_view_refuses_config_and_connect_together() -> None:
    result = run_cli("view", "--config", str(DEMO), "--connect", "tcp/127.0.0.1:7447")
    assert result.code == 2
    assert "not allowed with" in result.stderr


def test_the_mock_copy_puts_every_robot_on_the_mock_backend(tmp_path: Path) -> None:
    cell = tmp_path / "cell.yaml"
    cell.write_text(
        """
cell: real_cell
zenoh: {listen: ["tcp/127.0.0.1:7447"]}
robots:
  - name: alice
    model: ur10e
    backend: ur
    address: 192.168.1.10
    ur: {read_only: false}
  - name: bob
    model: ur5e
    backend: mock
""",
        encoding="utf-8",
    )
    data = yaml.safe_load(mock_cell_text(cell))
    assert "zenoh" not in data
    assert [r["backend"] for r in data["robots"]] == ["mock", "mock"]
    assert "address" not in data["robots"][0]
    assert "ur" not in data["robots"][0]
