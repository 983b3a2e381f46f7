"""A plan made offline: a chain of ruckig segments sampled by trajectory time, freed a few at a time
(control/trajectory.py and control/move.py make it; a goal run samples it, the ledger frees it)."""

from __future__ import annotations

from bisect import bisect_right
from typing import Any

__all__ = ["PlannedTrajectory"]


class PlannedTrajectory:
    """A planned jerk-limited trajectory: a chain of ruckig segments sampled by trajectory time.

    Segment ``i`` starts at trajectory time ``starts[i] + shift``: a planner that knows the tail's
    start times before segment 0 (and so the shift) hands its lists over as they are, without a copy
    or a walk over them. The lists are owned by the plan from then on.
    """

    __slots__ = (
        "_count",
        "_index",
        "_shift",
        "_starts",
        "_trajs",
        "duration",
        "final_positions",
        "final_velocities",
    )

    def __init__(self, segments: list[Any], starts: list[float], shift: float = 0.0) -> None:
        if not segments or len(segments) != len(starts):
            raise ValueError("PlannedTrajectory needs one start time per segment, at least one segment")
        self._trajs = segments
        self._starts = starts
        self._shift = shift
        self._count = len(segments)
        self._index = 0
        last = segments[-1]
        self.duration: float = shift + starts[-1] + float(last.duration)
        """Total trajectory time in seconds."""
        end_p, end_v, _ = last.at_time(float(last.duration))
        self.final_positions: tuple[float, ...] = tuple(end_p)
        self.final_velocities: tuple[float, ...] = tuple(end_v)

    @property
    def segment_count(self) -> int:
        """Number of ruckig segments (one per trajectory point)."""
        return self._count

    def sample(self, t: float, pos_out: list[float], vel_out: list[float], acc_out: list[float]) -> None:
        """Write the state at trajectory time ``t`` (clamped to [0, duration]) into the given lists."""
        if t <= 0.0:
            t = 0.0
        elif t >= self.duration:
            t = self.duration
        t -= self._shift
        starts = self._starts
        i = self._index
        if t < starts[i]:
            # Time went backwards (rare): search instead of walking.
            i = bisect_right(starts, t) - 1
            if i < 0:
                i = 0
        last = self._count - 1
        while i < last and t >= starts[i + 1]:
            i += 1
        self._index = i
        p, v, a = self._trajs[i].at_time(t - starts[i])
        pos_out[:] = p
        vel_out[:] = v
        acc_out[:] = a

    def release(self, count: int) -> bool:
        """Drop up to ``count`` segments (the last first), so a long plan is freed a little at a time;
        True while some remain. A plan being released must not be sampled again."""
        trajs = self._trajs
        for _ in range(min(count, len(trajs))):
            trajs.pop()
        if trajs:
            return True
        self._starts.clear()
        self._count = 0
        return False
