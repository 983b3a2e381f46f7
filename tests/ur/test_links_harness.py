"""A ``UrBackend`` run against a fake controller without Zenoh, for the callback-link tests.

``UrRun`` starts the fake (on a run-specific address, ``fake_address``) and the backend's ``run`` as a
task, counts the cycles, and lets a test wait for a condition on the backend, cycle by cycle (events,
never sleeps). Its one test is of ``UrRun`` itself: a failed ``run`` is reported at once.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Callable
from typing import Any

import pytest

from tests.helpers import fake_address, free_tcp_port
from urdaemon.backends.ur.backend import UrBackend
from urdaemon.cell.load import parse_cell
from urdaemon.errors import ConnectionLostError
from urdaemon.fakeur.controller import FakeController
from urdaemon.fakeur.faults import FaultInjector
from urdaemon.protocols import primary as prim

HOME = (0.0, -1.57, 1.57, -1.57, -1.57, 0.0)
JOINTS = tuple(f"alice_joint_{i}" for i in range(6))


def robot_config(address: str, *, headless: bool = True, startup: bool = True, ur: str | None = None) -> Any:
    """One ``ur`` robot of a cell file, callback ports from the OS, listening on 127.0.0.1 (or with
    ``ur`` as its whole ``ur:`` options, a YAML flow mapping)."""
    ports = [free_tcp_port() for _ in range(4)]
    if ur is None:
        ur = f"{{startup: {str(startup).lower()}, listen_address: 127.0.0.1}}"
    text = f"""
cell: links
robots:
  - name: alice
    model: ur10e
    backend: ur
    address: {address}
    headless: {str(headless).lower()}
    ports:
      {{reverse: {ports[0]}, script_sender: {ports[1]}, trajectory: {ports[2]}, script_command: {ports[3]}}}
    ur: {ur}
"""
    return parse_cell(text).robots[0]


class UrRun:
    """The backend's ``run`` as a task against ``fake``; waits on its cycles and status changes."""

    def __init__(self, backend: UrBackend, fake: FakeController) -> None:
        self.backend = backend
        self.fake = fake
        self.cycles = 0
        self.notices: list[tuple[str, str]] = []
        self.changes = 0
        self.programs_sent = 0
        self._tick = asyncio.Event()
        self.task: asyncio.Task[None] | None = None
        backend.on_notice = self._on_notice
        backend.on_change = self._on_change

    def on_cycle(self) -> None:
        """Count a cycle the backend ran (its ``run``'s ``on_cycle``, or called after the owner's)."""
        self.cycles += 1
        primary = self.backend.links.primary
        if primary is not None and not getattr(primary, "_counted", False):
            self._count_scripts(primary)
        self._tick.set()

    def _count_scripts(self, primary: Any) -> None:
        """Count the programs the backend sends on this primary link."""
        send = primary.send_script

        def counted(text: str) -> None:
            if "\ndef " in f"\n{text}":
                self.programs_sent += 1
            send(text)

        primary.send_script = counted
        primary._counted = True

    def _on_notice(self, kind: str, text: str) -> None:
        self.notices.append((kind, text))
        self._tick.set()

    def _on_change(self) -> None:
        self.changes += 1
        self._tick.set()

    def start(self) -> None:
        """Start ``backend.run``."""
        self.task = asyncio.get_running_loop().create_task(self.backend.run(self.on_cycle))
        self.task.add_done_callback(lambda _: self._tick.set())  # a failed run ticks no more

    async def until(self, predicate: Callable[[], bool], *, timeout: float = 30.0, what: str = "") -> None:
        """Wait, cycle by cycle, until ``predicate()`` holds (AssertionError after ``timeout``); if
        ``run`` ends first, at once with its error."""
        try:
            async with asyncio.timeout(timeout):
                while not predicate():
                    if self.task is not None and self.task.done():
                        self.task.result()  # the backend failed: say how
                        raise AssertionError(f"the backend stopped before: {what}")
                    self._tick.clear()
                    await self._tick.wait()
        except TimeoutError:
            state = self.backend.state
            raise AssertionError(
                f"not within {timeout} s: {what} (lifecycle {state.lifecycle}, reason "
                f"{state.lifecycle_reason!r}, program_running {state.program_running})"
            ) from None

    async def cycles_pass(self, count: int) -> None:
        """Wait until ``count`` more cycles ran."""
        target = self.cycles + count
        await self.until(lambda: self.cycles >= target, timeout=30.0, what=f"{count} cycles")

    @property
    def ready(self) -> bool:
        """Whether the robot would accept motion now."""
        return self.backend.state.ready_for_motion

    async def stop(self) -> None:
        """Cancel ``run`` and close the backend."""
        if self.task is not None:
            self.task.cancel()
            with contextlib.suppress(BaseException):
                await self.task
        await self.backend.close()


@contextlib.asynccontextmanager
async def ur_run(
    *,
    powered: bool = True,
    headless: bool = True,
    startup: bool = True,
    faults: FaultInjector | None = None,
    rtde_versions: tuple[int, ...] = (1, 2),
    start: bool = True,
) -> AsyncIterator[UrRun]:
    """A fake on a fresh address and a ``UrBackend`` for it, running (unless ``start`` is False)."""
    address = fake_address()
    robot = robot_config(address, headless=headless, startup=startup)
    urcap = None if headless else ("127.0.0.1", robot.ports.script_sender)
    options: dict[str, Any] = {} if rtde_versions == (1, 2) else {"rtde_versions": rtde_versions}
    fake = FakeController(
        "ur10e",
        address=address,
        initial_positions=HOME,
        powered=powered,
        urcap=urcap,
        faults=faults,
        **options,
    )
    await fake.start()
    backend = UrBackend(robot, JOINTS, expected_hash=None)
    run = UrRun(backend, fake)
    try:
        if start:
            run.start()
        yield run
    finally:
        await run.stop()
        await fake.close()


def program_is_running(run: UrRun) -> bool:
    """The fake runs a program and the backend holds all of its links."""
    servers = run.backend.servers
    return run.ready and all(
        s.link is not None for s in (servers.reverse, servers.trajectory, servers.script_command)
    )


def controller_command(run: UrRun, command: prim.ControllerCommand) -> None:
    """Have the fake execute a controller command, as if sent on its primary interface."""
    run.fake._controller_command(str(command))


async def test_until_reports_a_failed_backend_at_once() -> None:
    """Reproduction: the fake drops the backend's RTDE link, so ``run`` fails with ConnectionLostError
    while a test waits for a condition that never holds. ``until`` woke only on ticks, and a failed run
    ticks no more: it sat out its whole timeout, then blamed the condition (AssertionError, "not
    within") instead of the failure. Now the run's end wakes it and it raises the run's own error."""
    async with ur_run() as run:
        await run.until(lambda: run.cycles >= 5, what="RTDE streams")
        assert run.fake.drop("rtde") == 1
        with pytest.raises(ConnectionLostError) as raised:
            await run.until(lambda: False, timeout=10.0, what="a condition that never holds")
        assert run.task is not None
        assert run.task.done()
        assert raised.value is run.task.exception(), "the run's own failure, not a new error"
