"""Long work in slices between robot cycles: decoding, checking, planning, encoding and freeing a goal.

Every robot's sliced work shares one budget per event loop (``sliced``): N robots receiving big
goals at once still cost one slice per turn of the loop, and every robot's cycle runs between.
"""

from __future__ import annotations

import asyncio
import itertools
import time
import weakref
from collections.abc import Callable

from urdaemon.control.trajectory import TrajectoryCheck, TrajectoryPlanner
from urdaemon.publish.trajectory_goal import TrajectoryGoalMessage
from urdaemon.publish.trajectory_json import TrajectoryGoalDecoder

__all__ = [
    "CHECK_STEPS",
    "PLANNING_SLICE_S",
    "RELEASE_ITEMS",
    "check_sliced",
    "decode_sliced",
    "plan_tail",
    "release",
    "sliced",
    "until_deadline",
]

PLANNING_SLICE_S = 0.00025
"""Longest stretch of trajectory decoding, checking, planning, encoding or freeing in one turn of the
event loop, for the whole process: every robot's sliced work shares one budget (``sliced``), so N
robots receiving big goals at once still cost one slice per turn (a cycle is 2 ms; a young-generation
garbage collection inside a slice adds ~0.2 ms)."""
CHECK_STEPS = 4
"""Steps of a trajectory's check (a point each, a few µs) between two looks at the clock."""
RELEASE_ITEMS = 16
"""Objects freed between two looks at the clock when a goal's big objects are freed in slices."""

_BATONS: weakref.WeakKeyDictionary[asyncio.AbstractEventLoop, asyncio.Lock] = weakref.WeakKeyDictionary()
"""One slicing baton per event loop, shared by every robot's sliced work."""


async def sliced(step: Callable[[float], bool]) -> None:
    """Run ``step(deadline)`` until it returns False (done), one slice of ``PLANNING_SLICE_S`` per turn
    of the event loop for the whole process: each slice holds the loop's baton until the next turn,
    so however many robots slice at once, one turn runs one slice and every robot's cycle runs
    between."""
    budget = PLANNING_SLICE_S  # read at each call (tests set it)
    loop = asyncio.get_running_loop()
    baton = _BATONS.get(loop)
    if baton is None:
        baton = _BATONS[loop] = asyncio.Lock()
    more = True
    while more:
        async with baton:
            more = step(time.perf_counter() + budget)
            await asyncio.sleep(0)  # the next slice, anyone's (the next stage's too), in a later turn


async def release(owned: list[object]) -> None:
    """Free what the caller hands over in slices: it keeps no reference to the list's items, so a
    planner among them is ours to take apart attribute by attribute. What they reach is only dropped
    (a big list or tuple item by item, never changed): whoever else holds it keeps it intact."""
    dropped: list[object] = []

    def step(deadline: float) -> bool:
        for count in itertools.count(1):
            if owned:
                obj = owned.pop()
                if isinstance(obj, TrajectoryPlanner):
                    attributes = vars(obj)
                    dropped.extend(attributes.values())
                    attributes.clear()
                elif isinstance(obj, list | tuple):
                    dropped.extend(obj)
            elif dropped:
                obj = dropped.pop()
                if isinstance(obj, list | tuple) and len(obj) > RELEASE_ITEMS:
                    dropped.extend(obj)
            else:
                return False
            del obj
            if count % RELEASE_ITEMS == 0 and time.perf_counter() > deadline:
                return True
        return False  # unreachable: itertools.count never ends

    await sliced(step)


async def check_sliced(check: TrajectoryCheck) -> TrajectoryPlanner:
    """Check a trajectory's points in slices (``sliced``), letting every robot's cycle run between."""
    try:
        await sliced(until_deadline(lambda: check.step(CHECK_STEPS)))
        return check.result()
    finally:
        check.close()


async def decode_sliced(decoder: TrajectoryGoalDecoder) -> TrajectoryGoalMessage:
    """Decode a goal in slices (``sliced``), letting every robot's cycle run between."""
    await sliced(decoder.step)
    return decoder.result()


async def plan_tail(planner: TrajectoryPlanner) -> None:
    """Plan a trajectory's tail in slices (``sliced``), letting every robot's cycle run between."""
    await sliced(until_deadline(planner.plan_next))


def until_deadline(advance: Callable[[], bool]) -> Callable[[float], bool]:
    """A ``sliced`` step: call ``advance`` (True while there is more) until it is done or the slice's
    deadline passed; True while there is more."""

    def step(deadline: float) -> bool:
        while advance():
            if time.perf_counter() > deadline:
                return True
        return False

    return step
