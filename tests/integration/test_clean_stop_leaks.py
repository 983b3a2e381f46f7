"""A clean stop of ``serve`` leaves no ruckig object for nanobind to report as leaked (issue 32: about
40 ``nanobind: leaked …`` lines on stderr).

nanobind reports every instance of its types still alive when the interpreter ends. The daemon's
controllers hold ruckig objects for as long as they live (the online generator, the twist smoothing,
goal plans), so anything that still holds a controller at exit keeps them alive: a Zenoh callback
whose last reference is dropped on one of Zenoh's threads, which never runs Python again. Once its
loop ended, ``serve`` now has the daemon release them (``Daemon.release``). The holder is simulated
by a thread that keeps the daemon to the end of the process.
"""

from __future__ import annotations

import gc
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from tests.helpers import free_tcp_port, wait_for_line
from urdaemon.cell import load_cell
from urdaemon.control import MotionController
from urdaemon.daemon import describe_cell

pytestmark = pytest.mark.timeout(180)

REPO = Path(__file__).resolve().parents[2]
DEMO = REPO / "configs" / "dual_robot_mock.yaml"
LEAK = "nanobind: leaked"
HOLDER = """
import sys, threading
from urdaemon import daemon
from urdaemon.cli import main

held = threading.Event()
run = daemon.Daemon.run

async def run_and_be_held(self, stop):
    # what a Zenoh thread's late callback reference does: keep the daemon to the end of the process
    threading.Thread(target=lambda d=self: held.wait(), daemon=True).start()
    await run(self, stop)

daemon.Daemon.run = run_and_be_held
sys.exit(main(sys.argv[1:]))
"""
"""``urdaemon ARGS`` whose daemon something holds until the interpreter exits."""


def ruckig_objects(root: object, limit: int = 200_000) -> list[str]:
    """The types of ruckig objects reachable from ``root`` (a walk of at most ``limit`` objects)."""
    seen: set[int] = set()
    todo: list[Any] = [root]
    found: list[str] = []
    while todo and len(seen) < limit:
        item = todo.pop()
        if id(item) in seen or isinstance(item, type):
            continue
        seen.add(id(item))
        kind = type(item)
        if kind.__module__.startswith("ruckig") and not hasattr(kind, "__members__"):  # enums are constants
            found.append(kind.__name__)
        todo.extend(gc.get_referents(item))
    assert len(seen) < limit, "the walk did not finish"
    return found


def test_a_released_controller_holds_no_ruckig_object() -> None:
    limits = describe_cell(load_cell(DEMO)).limits["alice"]
    controller = MotionController(limits, period=0.002)
    assert {"Ruckig", "InputParameter", "OutputParameter"} <= set(ruckig_objects(controller))
    controller.release()
    assert ruckig_objects(controller) == []


async def _serve_and_stop(*argv: str) -> tuple[int, str]:
    """Run ``argv`` (a ``serve``), wait for it to serve, SIGINT it; its exit code and stderr."""
    proc = subprocess.Popen(argv, cwd=REPO, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True)
    try:
        lines = await wait_for_line(proc, "serving 2 robot(s)", timeout=90.0)
        proc.send_signal(signal.SIGINT)
        _, rest = proc.communicate(timeout=90.0)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
    return proc.returncode, "".join(lines) + rest


async def test_a_clean_serve_stop_reports_no_leak() -> None:
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    code, err = await _serve_and_stop(
        sys.executable, "-m", "urdaemon", "serve", "--config", str(DEMO), "--listen", endpoint
    )
    assert code == 0, err
    assert "stopped" in err, err
    assert LEAK not in err, err


async def test_a_daemon_held_at_exit_keeps_no_ruckig_object_alive() -> None:
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    code, err = await _serve_and_stop(
        sys.executable, "-c", HOLDER, "serve", "--config", str(DEMO), "--listen", endpoint
    )
    assert code == 0, err
    assert "stopped" in err, err
    assert LEAK not in err, err
