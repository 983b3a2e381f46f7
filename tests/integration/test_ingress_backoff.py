"""Issue 13, finding 6 (part): the restart backoff starts over once the backend has been healthy.

One RobotRuntime on a mock backend that fails on a script: at once, at once, after a healthy run,
at once, then runs. The delays are read from the runtime's log lines; waits are on an event.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from tests.integration.conftest import TWO_MOCKS
from urdaemon import robot as robot_module
from urdaemon.backends.mock import MockBackend
from urdaemon.cell import parse_cell
from urdaemon.control import MotionController
from urdaemon.daemon import describe_cell
from urdaemon.errors import BackendError
from urdaemon.robot import RobotRuntime

pytestmark = pytest.mark.timeout(60)

ROOT = Path(__file__).resolve().parents[2]
HEALTHY_CYCLES = 50
"""Cycles of the healthy run (the test makes 25 cycles count as healthy)."""


class FlakyBackend(MockBackend):
    """Each ``run`` fails after the next number of cycles from ``script`` (0: at once); once the
    script is used up it runs and sets ``done``."""

    def __init__(self, *args: Any, script: list[int], **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.script = script
        self.done = asyncio.Event()

    async def run(self, on_cycle: Callable[[], None]) -> None:
        if not self.script:
            self.done.set()
            await super().run(on_cycle)
            return
        fail_after = self.script.pop(0)
        if fail_after == 0:
            raise BackendError("connection refused")
        count = 0

        def cycle() -> None:
            nonlocal count
            on_cycle()
            count += 1
            if count >= fail_after:
                raise BackendError("connection lost")

        await super().run(cycle)


class _Node:
    def put(self, key: str, payload: bytes, *, attachment: bytes | None = None) -> None:
        pass


async def test_a_fault_after_a_healthy_run_restarts_with_the_first_delay(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    """Reproduction: the backoff only reset after a 30 s healthy run, so a second fault soon after a
    recovery waited the next, longer delay (0.1 s, then 0.5 s, 1 s, ... in the daemon)."""
    caplog.set_level(logging.INFO, logger="urdaemon.robot")
    monkeypatch.setattr(robot_module, "RESTART_BACKOFF_S", (0.1, 0.2, 0.3, 0.4))
    monkeypatch.setattr(robot_module, "HEALTHY_CYCLES_S", 0.05, raising=False)  # 25 cycles at 500 Hz
    cell = parse_cell(TWO_MOCKS, base_dir=ROOT / "configs")
    robot = cell.robot("alice")
    limits = describe_cell(cell).limits["alice"]
    backend = FlakyBackend("alice", limits.names, 500.0, script=[0, 0, HEALTHY_CYCLES, 0])
    controller = MotionController(limits, period=backend.period)
    runtime = RobotRuntime(cell.cell, robot, backend, controller, _Node(), cell.publish)  # type: ignore[arg-type]
    task = asyncio.create_task(runtime.run())
    try:
        await asyncio.wait_for(backend.done.wait(), 20.0)
    finally:
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
    delays = [r.getMessage() for r in caplog.records if "restarting backend in" in r.getMessage()]
    assert delays == [
        "[alice] restarting backend in 0.1 s",  # refused
        "[alice] restarting backend in 0.2 s",  # refused again: the backoff grows
        "[alice] restarting backend in 0.1 s",  # lost after a healthy run: a new fault, the first delay
        "[alice] restarting backend in 0.2 s",
    ], delays
    assert runtime.status_message()["restarts"] == 4
