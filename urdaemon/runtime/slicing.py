"""Stepped work in slices between robot cycles: decoding, checking, planning, encoding and freeing a goal.

Every stepped work has one shape (``motion.Steps``: a generator whose every ``next`` is one bounded
step and whose return value is the result). Every robot's sliced work shares one budget per event
loop (``sliced``): N robots receiving big goals at once still cost one slice per turn of the loop,
and every robot's cycle runs between.
"""

from __future__ import annotations

import asyncio
import time
import weakref
from collections.abc import Callable, Generator
from typing import TypeVar

from urdaemon.control.trajectory import TrajectoryPlanner

__all__ = ["PLANNING_SLICE_S", "RELEASE_ITEMS", "release", "release_steps", "sliced"]

T = TypeVar("T")

PLANNING_SLICE_S = 0.00025
"""Longest stretch of trajectory decoding, checking, planning, encoding or freeing in one turn of the
event loop, for the whole process: every robot's sliced work shares one budget (``sliced``), so N
robots receiving big goals at once still cost one slice per turn (a cycle is 2 ms; a young-generation
garbage collection inside a slice adds ~0.2 ms)."""
RELEASE_ITEMS = 16
"""Objects freed in one step when a goal's big objects are freed in slices."""

_BATONS: weakref.WeakKeyDictionary[asyncio.AbstractEventLoop, asyncio.Lock] = weakref.WeakKeyDictionary()
"""One slicing baton per event loop, shared by every robot's sliced work."""


async def sliced(steps: Generator[None, None, T], check: Callable[[], None] | None = None) -> T:
    """Run ``steps`` to their end, one slice of ``PLANNING_SLICE_S`` per turn of the event loop for
    the whole process (at least one step a slice); their result. ``check`` runs before every slice
    (it raises to end the work: runtime/motion.py's generation). Each slice holds the loop's baton
    until the next turn, so however many robots slice at once, one turn runs one slice and every
    robot's cycle runs between."""
    budget = PLANNING_SLICE_S  # read at each call (tests set it)
    loop = asyncio.get_running_loop()
    baton = _BATONS.get(loop)
    if baton is None:
        baton = _BATONS[loop] = asyncio.Lock()
    while True:
        async with baton:
            if check is not None:
                check()
            deadline = time.perf_counter() + budget
            try:
                next(steps)
                while time.perf_counter() <= deadline:
                    next(steps)
            except StopIteration as stop:
                await asyncio.sleep(0)  # the next stage's slice, in a later turn
                return stop.value  # type: ignore[no-any-return]
            await asyncio.sleep(0)  # the next slice, anyone's, in a later turn


def release_steps(owned: list[object]) -> Generator[None, None, None]:
    """Free what the caller hands over, ``RELEASE_ITEMS`` objects a step: it keeps no reference to the
    list's items, so a planner among them is ours to take apart attribute by attribute. What they
    reach is only dropped (a big list or tuple item by item, never changed): whoever else holds it
    keeps it intact."""
    dropped: list[object] = []
    count = 0
    while owned or dropped:
        if owned:
            obj = owned.pop()
            if isinstance(obj, TrajectoryPlanner):
                attributes = vars(obj)
                dropped.extend(attributes.values())
                attributes.clear()
            elif isinstance(obj, list | tuple):
                dropped.extend(obj)
        else:
            obj = dropped.pop()
            if isinstance(obj, list | tuple) and len(obj) > RELEASE_ITEMS:
                dropped.extend(obj)
        del obj
        count += 1
        if count % RELEASE_ITEMS == 0:
            yield


async def release(owned: list[object]) -> None:
    """Free what the caller hands over in slices (``release_steps``)."""
    await sliced(release_steps(owned))
