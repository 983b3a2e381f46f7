"""Real-time scheduling of the daemon's event loop thread (issue 5: tail latency on a busy machine)."""

from __future__ import annotations

import argparse
import asyncio
import gc
import logging
import os
import signal
import threading
import weakref
from typing import Any

import pytest

from tests.integration.conftest import running_daemon
from urdaemon import daemon as daemon_module
from urdaemon.cell import parse_cell
from urdaemon.errors import ConfigError
from urdaemon.fakeur import command as fake_command
from urdaemon.scheduling import RealtimeUnavailable, startup_objects_frozen, use_realtime_priority

pytestmark = pytest.mark.timeout(60)

CELL = """
cell: rt
realtime_priority: {priority}
robots:
  - name: alice
    model: ur10e
    backend: mock
"""


def _in_a_thread(work: Any) -> Any:
    """``work()`` in a thread of its own (never raise the test process's own threads)."""
    result: list[Any] = []

    def run() -> None:
        try:
            result.append(work())
        except BaseException as err:  # handed back to the test
            result.append(err)

    thread = threading.Thread(target=run)
    thread.start()
    thread.join(10.0)
    assert not thread.is_alive()
    (outcome,) = result
    if isinstance(outcome, BaseException):
        raise outcome
    return outcome


def test_the_calling_thread_runs_fifo_and_the_threads_it_starts_do_not() -> None:
    def work() -> tuple[int, int, tuple[int, int], int]:
        restore = use_realtime_priority(7)
        children: list[tuple[int, int]] = []
        child = threading.Thread(
            target=lambda: children.append((os.sched_getscheduler(0), os.sched_getparam(0).sched_priority))
        )
        child.start()
        child.join(10.0)
        raised = os.sched_getscheduler(0), os.sched_getparam(0).sched_priority
        restore()
        return *raised, children[0], os.sched_getscheduler(0)

    try:
        policy, priority, child, restored = _in_a_thread(work)
    except RealtimeUnavailable as err:
        pytest.skip(f"this machine does not allow SCHED_FIFO: {err}")
    assert policy & ~os.SCHED_RESET_ON_FORK == os.SCHED_FIFO
    assert policy & os.SCHED_RESET_ON_FORK
    assert priority == 7
    assert child == (os.SCHED_OTHER, 0), "threads started later keep normal scheduling"
    assert restored == os.SCHED_OTHER, "restore() puts the previous policy back"
    assert os.sched_getscheduler(0) == os.SCHED_OTHER, "only the calling thread was raised"


def test_without_permission_the_error_says_what_to_grant(monkeypatch: pytest.MonkeyPatch) -> None:
    def refuse(pid: int, policy: int, param: Any) -> None:
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(os, "sched_setscheduler", refuse)
    with pytest.raises(RealtimeUnavailable, match=r"priority 30 .*rtprio limit of at least 30.*CAP_SYS_NICE"):
        use_realtime_priority(30)


@pytest.mark.parametrize("priority", [0, 100, -1])
def test_priorities_outside_1_to_99_are_refused(priority: int) -> None:
    with pytest.raises(ValueError, match="between 1 and 99"):
        use_realtime_priority(priority)


def test_the_cell_file_takes_0_to_99_and_names_the_field_otherwise() -> None:
    assert parse_cell(CELL.format(priority=0)).realtime_priority == 0
    assert parse_cell(CELL.format(priority=80)).realtime_priority == 80
    for bad in ("100", "-3", "high", "1.5"):
        with pytest.raises(ConfigError, match="realtime_priority"):
            parse_cell(CELL.format(priority=bad))


async def test_the_daemon_raises_its_loop_thread_after_zenoh_started(monkeypatch: pytest.MonkeyPatch) -> None:
    calls: list[tuple[int, int]] = []
    restored: list[int] = []

    def raise_priority(priority: int) -> Any:
        calls.append((priority, threading.get_ident()))
        return lambda: restored.append(threading.get_ident())

    monkeypatch.setattr(daemon_module, "use_realtime_priority", raise_priority)
    async with running_daemon(CELL.format(priority=42)) as (daemon, client):
        assert daemon.node is not None
        alice = await client.robot("alice")
        assert (await alice.status())["ready"] is True
        assert restored == []
    assert calls == [(42, threading.get_ident())], "once, on the loop's thread"
    assert restored == [threading.get_ident()], "put back when the daemon stops"


async def test_a_daemon_not_allowed_fifo_warns_and_serves(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    def refuse(priority: int) -> None:
        raise RealtimeUnavailable(f"not permitted to use SCHED_FIFO priority {priority}")

    monkeypatch.setattr(daemon_module, "use_realtime_priority", refuse)
    with caplog.at_level(logging.WARNING, logger="urdaemon.daemon"):
        async with running_daemon(CELL.format(priority=50)) as (_, client):
            alice = await client.robot("alice")
            states = alice.joint_states(10)
            try:
                state = await asyncio.wait_for(states.get_json(timeout=5.0), 10.0)
            finally:
                states.close()
            assert state["robot"] == "alice"
    assert "serving at normal priority: not permitted to use SCHED_FIFO priority 50" in caplog.text


async def test_no_priority_no_change(monkeypatch: pytest.MonkeyPatch) -> None:
    calls: list[int] = []
    monkeypatch.setattr(daemon_module, "use_realtime_priority", calls.append)  # must not be called
    async with running_daemon(CELL.format(priority=0)) as (_, client):
        assert (await (await client.robot("alice")).status())["ready"] is True
    assert calls == []


class _Node:
    """A container the collector tracks, able to take part in a reference cycle."""

    def __init__(self) -> None:
        self.other: _Node | None = None


def _cycle() -> weakref.ref[_Node]:
    """A reference cycle nothing else refers to: only the collector can free it."""
    a, b = _Node(), _Node()
    a.other, b.other = b, a
    return weakref.ref(a)


def test_startup_objects_are_kept_out_of_collections_and_later_garbage_is_collected() -> None:
    assert gc.get_freeze_count() == 0
    alive = _Node()
    with startup_objects_frozen() as frozen:
        assert frozen > 0
        assert gc.get_freeze_count() > 0  # less than frozen once frozen objects are freed by refcount
        assert not any(o is alive for o in gc.get_objects()), "frozen: no collection walks it"
        later = _Node()
        assert any(o is later for o in gc.get_objects())
        garbage = _cycle()
        gc.collect()
        assert garbage() is None, "cyclic garbage made after the freeze is still freed"
    assert gc.get_freeze_count() == 0, "unfrozen when the block ends"
    assert any(o is alive for o in gc.get_objects())


def test_garbage_alive_at_the_freeze_is_collected_first() -> None:
    garbage = _cycle()
    assert garbage() is not None
    with startup_objects_frozen():
        assert garbage() is None


def test_leaving_by_an_exception_unfreezes_too() -> None:
    with pytest.raises(RuntimeError, match="boom"), startup_objects_frozen():
        raise RuntimeError("boom")
    assert gc.get_freeze_count() == 0


async def test_the_daemon_serves_with_its_startup_objects_frozen() -> None:
    async with running_daemon(CELL.format(priority=0)) as (daemon, client):
        assert (await (await client.robot("alice")).status())["ready"] is True
        assert gc.get_freeze_count() > 0
        assert not any(o is daemon for o in gc.get_objects())
    assert gc.get_freeze_count() == 0, "unfrozen when the daemon stops"


def test_the_fake_robot_command_serves_with_its_startup_objects_frozen(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    seen: list[int] = []

    class Fake:
        """Stands in for FakeController: its start() is where the fakes' startup ends."""

        async def start(self) -> None:
            def serving() -> None:
                seen.append(gc.get_freeze_count())
                os.kill(os.getpid(), signal.SIGTERM)  # what ends `urdaemon fake-robot`

            asyncio.get_running_loop().call_later(0.05, serving)

        async def close(self) -> None:
            seen.append(gc.get_freeze_count())

    monkeypatch.setattr(fake_command, "build_fakes", lambda args: [Fake()])
    monkeypatch.setattr(fake_command, "share_clock", lambda fakes, phases: None)
    before = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}
    assert fake_command.run_fakes(argparse.Namespace(late_start=0.0, phases="aligned")) == 0
    assert seen[0] > 0, "frozen while serving"
    assert seen[1] == 0, "unfrozen before the fakes close"
    # called, not run as `urdaemon fake-robot`: the caller keeps its handlers (an ignored SIGINT left
    # here was inherited by every `urdaemon move` this worker started later: Ctrl-C did nothing)
    assert {sig: signal.getsignal(sig) for sig in before} == before
