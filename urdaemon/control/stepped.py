"""Long pure work run in steps: a generator of steps whose return value is the result.

The caller decides how many steps fit between two turns of its loop (runtime/slicing.py); nothing
here reads a clock. A trajectory's check (``TrajectoryCheck``) and a linear goal's plan
(``LinearCheck``) are both one of these.
"""

from __future__ import annotations

from collections.abc import Generator
from typing import Generic, TypeVar

__all__ = ["StepCheck"]

T = TypeVar("T")


class StepCheck(Generic[T]):
    """Work run in steps: ``step(count)`` until it returns False, then ``result()``."""

    __slots__ = ("_result", "_steps")

    def __init__(self, steps: Generator[None, None, T]) -> None:
        self._steps: Generator[None, None, T] | None = steps
        self._result: T | None = None

    def step(self, count: int = 1) -> bool:
        """Run up to ``count`` steps; True while more remain. Raises GoalRejected (then it is done)."""
        steps = self._steps
        if steps is None:
            return False
        try:
            for _ in range(count):
                next(steps)
        except StopIteration as stop:
            self._result = stop.value
            self._steps = None
            return False
        except BaseException:
            self._steps = None
            raise
        return True

    def run(self) -> T:
        """Run every step left at once; the result."""
        while self.step(1024):
            pass
        return self.result()

    def result(self) -> T:
        """What the finished work gave."""
        if self._result is None:
            raise RuntimeError("the check has not finished")
        return self._result

    def close(self) -> None:
        """Abandon unfinished work."""
        if self._steps is not None:
            self._steps.close()
            self._steps = None
