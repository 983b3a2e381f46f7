"""A goal planned as joint samples, one per robot cycle: what a linear goal runs.

Owns ``SampledTrajectory`` (the plan a goal run samples on the 500 Hz path, shaped like
control/planned_trajectory.py's ``PlannedTrajectory``) and ``SampleWriter``, which fills one.

Every sample ``n`` (at trajectory time ``n * period``) holds the joint positions and their velocities:
the central difference of the neighbouring samples (zero at the first and the last, which are at
rest). Between two samples ``sample`` interpolates each joint with the cubic Hermite polynomial
through both positions and velocities, and reports that polynomial's derivatives as velocity and
acceleration, so the three are consistent; at a sample's time it returns the sample exactly.

Samples are stored in chunks of ``CHUNK_SAMPLES`` (flat ``array('d')``: positions then velocities),
so ``sample`` is O(1) and allocates nothing, and ``release`` frees a long plan a few chunks at a time.
"""

from __future__ import annotations

from array import array
from collections.abc import Sequence

__all__ = ["CHUNK_SAMPLES", "SampleWriter", "SampledTrajectory"]

_SHIFT = 9
CHUNK_SAMPLES = 1 << _SHIFT
"""Samples per chunk (512: ~1 s of motion at 500 Hz, 48 KB for six joints)."""
_MASK = CHUNK_SAMPLES - 1


class SampledTrajectory:
    """Joint samples every ``period`` seconds, interpolated by cubic Hermite polynomials in between.

    ``slowed_by`` is the factor >= 1 the plan was retimed by to keep every limit (1.0: as asked).
    """

    __slots__ = (
        "_chunks",
        "_dof",
        "_last",
        "_rate",
        "duration",
        "final_positions",
        "final_velocities",
        "period",
        "sample_count",
        "slowed_by",
    )

    def __init__(
        self, chunks: list[array[float]], count: int, dof: int, period: float, slowed_by: float = 1.0
    ) -> None:
        if count < 1 or len(chunks) != (count + _MASK) >> _SHIFT:
            raise ValueError("SampledTrajectory needs at least one sample and its chunks")
        if not period > 0.0:
            raise ValueError(f"period must be > 0, got {period}")
        self._chunks = chunks
        self._dof = dof
        self._last = count - 1
        self._rate = 1.0 / period
        self.period = period
        """Time between two samples (s): the robot's cycle."""
        self.sample_count = count
        """Samples, the first at time 0 and the last at ``duration``."""
        self.duration: float = (count - 1) * period
        """Total trajectory time in seconds."""
        self.slowed_by = slowed_by
        end = self._at(self._last)
        self.final_positions: tuple[float, ...] = tuple(end[0][end[1] : end[1] + dof])
        self.final_velocities: tuple[float, ...] = tuple(end[0][end[1] + dof : end[1] + 2 * dof])

    @property
    def segment_count(self) -> int:
        """Chunks of samples still held (what ``release`` frees, a few at a time)."""
        return len(self._chunks)

    def _at(self, n: int) -> tuple[array[float], int]:
        return self._chunks[n >> _SHIFT], (n & _MASK) * 2 * self._dof

    def positions(self, n: int) -> tuple[float, ...]:
        """The joint positions of sample ``n``."""
        chunk, at = self._at(n)
        return tuple(chunk[at : at + self._dof])

    def sample(self, t: float, pos_out: list[float], vel_out: list[float], acc_out: list[float]) -> None:
        """Write the state at trajectory time ``t`` (clamped to [0, duration]) into the given lists."""
        u = t * self._rate
        last = self._last
        if u <= 0.0:
            n, f = 0, 0.0
        elif u >= last:
            n, f = last, 0.0
        else:
            n = int(u)
            f = u - n
        if n >= last:
            chunk, at = self._at(last)
            dof = self._dof
            for i in range(dof):
                pos_out[i] = chunk[at + i]
                vel_out[i] = chunk[at + dof + i]
                acc_out[i] = 0.0
            return
        self._sample_between(n, f, pos_out, vel_out, acc_out)

    def _sample_between(
        self, n: int, f: float, pos_out: list[float], vel_out: list[float], acc_out: list[float]
    ) -> None:
        """The Hermite polynomial from sample ``n`` to ``n + 1`` at fraction ``f`` of the interval."""
        dof = self._dof
        chunks = self._chunks
        c0 = chunks[n >> _SHIFT]
        o0 = (n & _MASK) * 2 * dof
        n1 = n + 1
        c1 = chunks[n1 >> _SHIFT]
        o1 = (n1 & _MASK) * 2 * dof
        rate = self._rate
        h = self.period
        for i in range(dof):
            p0 = c0[o0 + i]
            m0 = c0[o0 + dof + i] * h
            m1 = c1[o1 + dof + i] * h
            d = c1[o1 + i] - p0
            a2 = 3.0 * d - 2.0 * m0 - m1
            a3 = m0 + m1 - 2.0 * d
            pos_out[i] = p0 + f * (m0 + f * (a2 + f * a3))
            vel_out[i] = (m0 + f * (2.0 * a2 + 3.0 * f * a3)) * rate
            acc_out[i] = (2.0 * a2 + 6.0 * f * a3) * rate * rate

    def release(self, count: int) -> bool:
        """Drop up to ``count`` chunks (the last first), so a long plan is freed a little at a time;
        True while some remain. A plan being released must not be sampled again."""
        chunks = self._chunks
        for _ in range(min(count, len(chunks))):
            chunks.pop()
        return bool(chunks)


class SampleWriter:
    """Builds a ``SampledTrajectory`` from joint positions appended one sample at a time.

    A sample's velocity is the central difference of its neighbours, written when the next sample
    arrives; the first and the last sample are at rest (velocity 0).
    """

    __slots__ = ("_chunks", "_count", "_dof", "_half_rate", "_last", "_period", "_prev")

    def __init__(self, dof: int, period: float) -> None:
        self._dof = dof
        self._period = period
        self._half_rate = 0.5 / period
        self._chunks: list[array[float]] = []
        self._count = 0
        self._prev: tuple[float, ...] = ()
        self._last: tuple[float, ...] = ()

    @property
    def count(self) -> int:
        """Samples appended so far."""
        return self._count

    def append(self, q: Sequence[float]) -> None:
        """Append the joint positions of the next sample."""
        dof = self._dof
        n = self._count
        if n & _MASK == 0:
            self._chunks.append(array("d"))
        chunk = self._chunks[-1]
        chunk.extend(q)
        chunk.extend([0.0] * dof)
        if n >= 2:
            # Sample n - 1's velocity: (q[n] - q[n - 2]) / 2h.
            c, at = self._chunks[(n - 1) >> _SHIFT], ((n - 1) & _MASK) * 2 * dof
            before = self._prev  # sample n - 2
            for i in range(dof):
                c[at + dof + i] = (q[i] - before[i]) * self._half_rate
        self._prev = self._last
        self._last = tuple(q)
        self._count = n + 1

    def finish(self, slowed_by: float = 1.0) -> SampledTrajectory:
        """The trajectory of the samples appended (the last one at rest); the writer is spent."""
        chunks, self._chunks = self._chunks, []
        return SampledTrajectory(chunks, self._count, self._dof, self._period, slowed_by)
