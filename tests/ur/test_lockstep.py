"""The lockstep clock the Cartesian tests on the fake tick on (tests/ur/lockstep.py), driven by hand:
its real-time timer never started, each ``_fire`` stands for one real period."""

from __future__ import annotations

import asyncio

from tests.ur.lockstep import LockstepClock


def _clock(hold: int = 3) -> tuple[LockstepClock, list[bool]]:
    clock = LockstepClock(0.002, hold=hold)
    clock._loop = asyncio.get_running_loop()
    ran: list[bool] = []
    clock.slots[0].append(lambda: ran.append(clock.last_answered))
    return clock, ran


async def _soon() -> None:
    await asyncio.sleep(0)  # one turn of the loop: what call_soon scheduled has run


async def test_it_ticks_on_every_period_while_not_following() -> None:
    clock, ran = _clock()
    for _ in range(4):
        clock._fire()
    assert ran == [False] * 4


async def test_a_cycle_waits_for_the_answer_to_the_one_before_and_runs_on_it() -> None:
    clock, ran = _clock()
    clock.follow = lambda: True
    clock._fire()
    assert len(ran) == 1
    clock._fire()
    clock._fire()
    assert len(ran) == 1, "held: no answer yet"
    clock.answered()
    assert len(ran) == 1, "runs on the loop, not inside the daemon's send"
    await _soon()
    assert ran == [False, True]
    clock.answered()  # a second answer to the same cycle adds nothing
    await _soon()
    assert ran == [False, True]


async def test_an_answer_before_the_period_runs_the_cycle_on_the_period() -> None:
    clock, ran = _clock()
    clock.follow = lambda: True
    clock._fire()
    clock.answered()
    await _soon()
    assert len(ran) == 1, "never sooner than the period"
    clock._fire()
    assert ran == [False, True]


async def test_a_daemon_that_stops_answering_costs_the_lockstep_not_the_clock() -> None:
    clock, ran = _clock(hold=3)
    clock.follow = lambda: True
    clock._fire()
    for _ in range(3):
        clock._fire()
    assert ran == [False, False]
    assert clock.unanswered == 1
    clock._fire()
    clock._fire()
    assert len(ran) == 4, "not waiting again until the next answer"
    assert clock.unanswered == 1
    clock.answered()
    clock._fire()
    clock._fire()
    assert len(ran) == 5, "an answer brings the lockstep back"
