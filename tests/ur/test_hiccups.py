"""Issue 32, points 1 to 4, the daemon's side: a stall of the daemon within the window loses no goal, a
program killed mid-goal ends it with one result, bounded auto-recovery after a protective stop (never
after an emergency stop), the not-ready reason names the action that works, and a daemon started
before its controller waits at INFO, not ERROR.

The fake controller runs the same control script; a stall of the daemon is N cycles in which the
backend writes no reverse frame (the robot sees exactly what a late daemon does to it)."""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import AsyncIterator, Callable
from typing import Any

import pytest

from tests.helpers import fake_address, free_tcp_port, swing_trajectory
from tests.integration.test_review_planning import Node, Query
from tests.ur.test_links_harness import HOME, JOINTS, UrRun, program_is_running, robot_config
from tests.ur.test_review_passthrough import CountedUrBackend
from urdaemon.backends.ur.backend import UrBackend
from urdaemon.backends.ur.readiness import ProgramFacts, not_ready_reason
from urdaemon.backends.ur.recovery import UNLOCK_WAIT_S, Decision, RecoveryPolicy
from urdaemon.cell.load import parse_cell
from urdaemon.cell.robot_options import UrAutoRecover
from urdaemon.control import MotionController
from urdaemon.daemon import describe_cell
from urdaemon.fakeur.controller import FakeController
from urdaemon.model import Lifecycle, RobotMode, RobotState, SafetyMode
from urdaemon.robot import RobotRuntime

pytestmark = pytest.mark.timeout(120)


# ---- the not-ready reason -------------------------------------------------------------------------


def _facts(headless: bool) -> ProgramFacts:
    return ProgramFacts(False, headless, False, "", (), 3, "", "")


def test_a_paused_headless_program_says_resend_program_not_play() -> None:
    """Reproduction: after a protective stop was unlocked, a headless robot's status said "resume it
    (play)", but play plays the loaded .urp; only resend_program brought the program back."""
    state = _paused_state()
    headless = not_ready_reason(state, _facts(headless=True))
    assert "resend_program" in headless, headless
    assert "(play)" not in headless, headless
    urcap = not_ready_reason(state, _facts(headless=False))
    assert "play" in urcap, urcap
    state.lifecycle = Lifecycle.PROTECTIVE_STOP
    state.safety_mode = SafetyMode.PROTECTIVE_STOP
    assert "resend_program" in not_ready_reason(state, _facts(headless=True))


def _paused_state() -> RobotState:
    state = RobotState(JOINTS, list(HOME), [0.0] * 6, [0.0] * 6)
    state.lifecycle = Lifecycle.PAUSED
    state.robot_mode = RobotMode.RUNNING
    state.safety_mode = SafetyMode.NORMAL
    return state


# ---- the recovery policy, on a clock of its own ---------------------------------------------------


def test_the_policy_waits_the_controllers_5_s_then_recovers_within_its_budget() -> None:
    policy = RecoveryPolicy(UrAutoRecover(protective_stop=True, max_attempts=2, within_s=60.0))
    stop, normal = SafetyMode.PROTECTIVE_STOP, SafetyMode.NORMAL
    assert policy.decide(stop, 100.0) is Decision.WAIT
    assert policy.decide(stop, 100.0 + UNLOCK_WAIT_S - 0.01) is Decision.NOTHING, "said once"
    assert policy.decide(stop, 100.0 + UNLOCK_WAIT_S) is Decision.RECOVER
    assert policy.decide(normal, 106.0) is Decision.NOTHING
    assert policy.decide(stop, 110.0) is Decision.WAIT
    assert policy.decide(stop, 115.0) is Decision.RECOVER
    assert policy.decide(normal, 116.0) is Decision.NOTHING
    assert policy.decide(stop, 120.0) is Decision.GIVE_UP, "two attempts within 60 s already"
    assert policy.decide(stop, 130.0) is Decision.NOTHING, "given up once"
    assert policy.decide(normal, 131.0) is Decision.NOTHING
    assert policy.decide(stop, 170.0) is Decision.WAIT, "the first attempt left the window"
    assert policy.decide(stop, 175.0) is Decision.RECOVER


def test_the_policy_never_recovers_an_emergency_stop_and_is_off_unless_asked() -> None:
    policy = RecoveryPolicy(UrAutoRecover(protective_stop=True))
    for mode in (SafetyMode.ROBOT_EMERGENCY_STOP, SafetyMode.SYSTEM_EMERGENCY_STOP):
        decisions = {policy.decide(mode, float(t)) for t in range(0, 100, 5)}
        assert Decision.RECOVER not in decisions
    off = RecoveryPolicy(UrAutoRecover(protective_stop=False))
    assert {off.decide(SafetyMode.PROTECTIVE_STOP, float(t)) for t in range(20)} == {Decision.NOTHING}


# ---- auto-recovery on the fake --------------------------------------------------------------------


@contextlib.asynccontextmanager
async def ur_robot(ur: str, *, start_fake: bool = True) -> AsyncIterator[UrRun]:
    """A UrBackend with ``ur`` as its options (a YAML flow mapping) against a fake, running."""
    address = fake_address()
    robot = robot_config(address, ur=ur)
    fake = FakeController("ur10e", address=address, initial_positions=HOME, powered=True)
    if start_fake:
        await fake.start()
    run = UrRun(UrBackend(robot, JOINTS, expected_hash=None), fake)
    run.start()
    try:
        yield run
    finally:
        await run.stop()
        await fake.close()


RECOVERING = (
    "{startup: true, listen_address: 127.0.0.1, auto_recover: {protective_stop: true, max_attempts: 1}}"
)


def _said(run: UrRun, text: str) -> int:
    return sum(text in said for kind, said in run.notices if kind == "auto_recover")


async def test_a_protective_stop_is_recovered_by_the_policy_once_within_its_budget() -> None:
    async with ur_robot(RECOVERING) as run:
        await run.until(lambda: program_is_running(run), what="ready")
        run.fake.protective_stop()
        await run.until(lambda: _said(run, "recovered from the protective stop") == 1, what="recovered")
        await run.until(lambda: program_is_running(run), what="ready again")
        assert _said(run, "unlocking the protective stop (attempt 1 of 1)") == 1
        run.fake.protective_stop()  # the budget (1 within 60 s) is spent
        await run.until(lambda: _said(run, "not recovered, 1 attempts within 60 s") == 1, what="gave up")
        assert run.backend.state.safety_mode is SafetyMode.PROTECTIVE_STOP
        assert _said(run, "unlocking the protective stop (") == 1


async def test_an_emergency_stop_is_never_recovered() -> None:
    async with ur_robot(RECOVERING) as run:
        await run.until(lambda: program_is_running(run), what="ready")
        run.fake.emergency_stop()
        await run.until(lambda: _said(run, "emergency stop: not recovered") == 1, what="said")
        await run.cycles_pass(round(1.2 * UNLOCK_WAIT_S * 500))
        assert _said(run, "unlocking the protective stop (") == 0
        assert run.backend.state.safety_mode is SafetyMode.ROBOT_EMERGENCY_STOP


# ---- the start-up race -----------------------------------------------------------------------------


class Records(logging.Handler):
    def __init__(self) -> None:
        super().__init__(logging.DEBUG)
        self.records: list[logging.LogRecord] = []
        self.waiting = asyncio.Event()
        """Set by the first "waiting for the controller" record."""

    def emit(self, record: logging.LogRecord) -> None:
        self.records.append(record)
        if "waiting for the controller at" in record.getMessage():
            self.waiting.set()

    def count(self, level: int, text: str = "") -> int:
        return sum(r.levelno == level and text in r.getMessage() for r in self.records)


async def test_a_daemon_started_before_its_controller_waits_at_info_not_error() -> None:
    """Reproduction: the README's fake-controller one-liner starts the fakes and serve together; the
    daemon connected before the fakes listened and logged an ERROR ("backend failed: … cannot
    connect") at every start."""
    records = Records()
    logger = logging.getLogger("urdaemon")
    level = logger.level
    logger.setLevel(logging.INFO)
    logger.addHandler(records)
    try:
        async with served(start_fake=False) as (_, run):
            await asyncio.wait_for(records.waiting.wait(), 30.0)
            await run.fake.start()
            await run.until(lambda: program_is_running(run), what="ready")
    finally:
        logger.removeHandler(records)
        logger.setLevel(level)
    assert records.count(logging.ERROR) == 0, [r.getMessage() for r in records.records]
    assert records.count(logging.INFO, "waiting for the controller at") == 1


# ---- no goal lost ------------------------------------------------------------------------------------


@contextlib.asynccontextmanager
async def served(*, start_fake: bool = True) -> AsyncIterator[tuple[RobotRuntime, UrRun]]:
    """alice served by a RobotRuntime (no Zenoh) against a fake controller."""
    address = fake_address()
    ports = [free_tcp_port() for _ in range(4)]
    cell = parse_cell(
        f"""
cell: hiccup
robots:
  - name: alice
    model: ur10e
    backend: ur
    address: {address}
    headless: true
    ports:
      {{reverse: {ports[0]}, script_sender: {ports[1]}, trajectory: {ports[2]}, script_command: {ports[3]}}}
    ur: {{startup: true, listen_address: 127.0.0.1}}
"""
    )
    robot = cell.robot("alice")
    limits = describe_cell(cell).limits["alice"]
    fake = FakeController("ur10e", address=address, initial_positions=HOME)
    if start_fake:
        await fake.start()
    backend = CountedUrBackend(robot, limits.names, expected_hash=None)
    run = UrRun(backend, fake)
    backend.after_cycle = run.on_cycle
    controller = MotionController(limits, period=backend.period)
    node = Node()
    runtime = RobotRuntime(cell.cell, robot, backend, controller, node, cell.publish)  # type: ignore[arg-type]
    runtime.declare()
    task = asyncio.create_task(runtime.run())
    run.task = task
    try:
        yield runtime, run
    finally:
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
        await backend.close()
        await fake.close()


def _results(runtime: RobotRuntime, goal_id: str) -> list[dict[str, Any]]:
    node: Any = runtime.node
    return [r for r in node.results() if r.get("goal_id") == goal_id]


async def _goal(runtime: RobotRuntime, last_segment: float) -> str:
    query = Query("hiccup/alice/goal/trajectory", swing_trajectory(30, HOME, last_segment=last_segment))
    runtime.goals.on_trajectory_goal(query)
    answer = await query.answer()
    assert answer["accepted"] is True, answer
    return str(answer["goal_id"])


def _drop_frames(run: UrRun, count: int) -> Callable[[], int]:
    """The backend writes no reverse frame for its next ``count`` cycles; how many it dropped."""
    server = run.backend.servers.reverse
    write = server.write
    dropped = 0

    def late(data: bytes) -> bool:
        nonlocal dropped
        if dropped < count:
            dropped += 1
            return True
        return write(data)

    server.write = late  # type: ignore[method-assign]
    return lambda: dropped


@pytest.mark.parametrize("stall", [60, 150])
async def test_a_stall_of_the_daemon_within_the_window_loses_no_goal(stall: int) -> None:
    """Reproduction: a 0.1 s receive timeout ended the program at the first hiccup, and the goal with
    it ("Socket timed out waiting for command on reverse_socket"). A stall shorter than the keepalive
    (60 cycles) or longer, within the window (150 cycles past the 100), now leaves the program up."""
    async with served() as (runtime, run):
        await run.until(lambda: program_is_running(run), what="ready")
        goal = await _goal(runtime, last_segment=1.0)
        await run.cycles_pass(100)
        sent = run.programs_sent
        dropped = _drop_frames(run, stall)
        await run.until(lambda: dropped() == stall, what="the stall")
        await run.until(lambda: bool(_results(runtime, goal)), timeout=30.0, what="the goal's result")
        await run.cycles_pass(50)
        results = _results(runtime, goal)
        assert len(results) == 1, results
        assert program_is_running(run)
        assert run.programs_sent == sent, "the program survived the stall: none was sent again"
        assert run.fake.programs.name is not None
        if stall < 100:
            assert results[0]["status"] == "succeeded", results


async def test_a_program_killed_and_restarted_mid_goal_ends_the_goal_with_one_result() -> None:
    async with served() as (runtime, run):
        await run.until(lambda: program_is_running(run), what="ready")
        goal = await _goal(runtime, last_segment=2.0)
        await run.cycles_pass(100)
        ok, _ = await run.backend.dashboard("stop")  # the program is killed on the controller
        assert ok
        await run.until(lambda: bool(_results(runtime, goal)), what="the goal's result")
        await run.until(lambda: program_is_running(run), what="the program is back (headless: resent)")
        await run.cycles_pass(200)
        results = _results(runtime, goal)
        assert len(results) == 1, results
        assert results[0]["status"] == "aborted"
        assert "program" in results[0]["reason"], results
