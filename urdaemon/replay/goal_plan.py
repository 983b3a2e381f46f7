"""Recorded joint states → the goals that drive a cell through the same motion again. Pure: no I/O.

Each robot's samples are put on its sample grid (``sample_ticks``: the host times rounded to the
period, and while a joint moves fast enough the ticks its positions and velocities say passed, so a
cycle the recording daemon missed does not shift the rest), their accelerations estimated
(``estimate_accelerations``: each interval is taken as one cubic, the jerk switches found), and the
motion cut where every robot rests. Each piece becomes one cell goal: a trajectory part per robot
that moves in it (docs/replay.md).

Two shapes of part, chosen by the rate:

- ``samples`` (``rate < 1``): every recorded sample is a point (positions, velocities × rate,
  accelerations × rate²), so the daemon's planner passes through each recorded state at its
  recorded time ÷ rate. A run of rest samples is kept as its first and last.
- ``moves`` (``rate >= 1``): one rest-to-rest point per move, at the move's recorded start and end
  (found to within float noise from the first and last moving samples), so the daemon re-plans
  each move itself. A recorded motion is jerk-limited at the joints' limits, so its states sit on
  the boundary of what the limits reach in one sample interval: the daemon's planner refuses them
  as points at the recorded timing (measured: docs/replay.md). A move that was planned
  time-optimally (or to a duration) from rest to rest is planned the same way again, so it is
  reproduced exactly; any other path between two rests is re-planned, not reproduced. A recorded
  result of the goal that made the move, when it fits, gives the move's planned length (a measured
  arm's move lasts longer than its plan).

A goal holds at most ``MAX_POINTS`` points and a cell goal ``MAX_BYTES`` of JSON (docs/keys.md
"Goals"): a piece that would not fit is cut at an earlier common rest, and a stretch between two
common rests that alone does not fit is thinned (every k-th point), which ``Plan.notes`` says.
"""

from __future__ import annotations

import itertools
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from urdaemon.publish.envelope import MAX_MESSAGE_BYTES
from urdaemon.publish.trajectory_goal import MAX_TRAJECTORY_POINTS

__all__ = [
    "KINEMATIC_MOVE",
    "MAX_BYTES",
    "MAX_POINTS",
    "MODES",
    "REST_VELOCITY",
    "Knot",
    "Plan",
    "Sample",
    "Step",
    "Track",
    "estimate_accelerations",
    "knots_of",
    "make_plan",
    "sample_ticks",
]

MAX_POINTS = MAX_TRAJECTORY_POINTS
"""Points a trajectory goal may hold (docs/keys.md "Goals")."""
MAX_BYTES = MAX_MESSAGE_BYTES - 64 * 1024
"""JSON bytes of a cell goal's request: the daemon's 2 MiB, less room for the envelope."""
REST_VELOCITY = 1e-6
"""A sample whose every joint velocity is at most this (rad/s) is at rest."""
KINEMATIC_MOVE = 1e-9
"""When a joint moved more than this (rad) between two samples, the ticks between them are read from
its positions and velocities rather than from the host times."""
_SAME_ACCELERATION = 1e-6
_NS = 1e-9


@dataclass(frozen=True, slots=True)
class Sample:
    """One recorded ``joint_states``: host time, positions and velocities in the recorded order."""

    time_ns: int
    positions: tuple[float, ...]
    velocities: tuple[float, ...]


@dataclass(frozen=True, slots=True)
class Track:
    """One robot's recorded motion, on its sample period (robot period × joint_states decimation)."""

    robot: str
    period_s: float
    samples: tuple[Sample, ...]
    goals: tuple[tuple[int, float], ...] = ()
    """The robot's goals that succeeded: when the result was recorded (ns) and the trajectory time
    they ran (s), which a move between two rests is timed by when one ended with it (``moves``)."""


@dataclass(frozen=True, slots=True)
class Knot:
    """A state the replay passes through: time (s, recorded timeline), positions, velocities and
    accelerations (zero at rest)."""

    time_s: float
    positions: tuple[float, ...]
    velocities: tuple[float, ...]
    accelerations: tuple[float, ...]

    @property
    def at_rest(self) -> bool:
        return not any(self.velocities) and not any(self.accelerations)


@dataclass(frozen=True)
class Step:
    """One cell goal: each moving robot's trajectory points, and where on the recorded timeline it
    starts (s from the plan's start) and how long it lasts (s, replayed)."""

    start_s: float
    duration_s: float
    parts: dict[str, list[dict[str, Any]]]


@dataclass
class Plan:
    """The whole replay: where each robot goes first (a move goal), then the cell goals in order."""

    first: dict[str, tuple[float, ...]]
    steps: list[Step]
    mode: str
    notes: list[str] = field(default_factory=list)


def unplanned_motion(tracks: Sequence[Track], plan: Plan) -> list[str]:
    """The robots whose recording moves (a sample faster than ``REST_VELOCITY``) but that no cell goal
    of ``plan`` drives: a replay of them would only move them to the start and succeed silently."""
    driven = {robot for step in plan.steps for robot in step.parts}
    return [
        track.robot
        for track in tracks
        if track.robot not in driven and any(not _at_rest(sample) for sample in track.samples)
    ]


def sample_ticks(samples: Sequence[Sample], period_s: float) -> list[int]:
    """Each sample's tick on its robot's grid, counted from the first (strictly increasing).

    While the robot moves, the ticks between two samples are what their positions and velocities
    say: the interval is taken as one cubic starting with the acceleration the interval before ended
    with (0 from rest), whose length solves ``a0·T²/6 + (v0 + Δv/3)·T = Δp`` on the joint that moved
    most. Host times jitter by up to cycles on a busy machine, and a cycle the daemon missed moves
    the host time on but not the motion. At rest the host time is all there is.
    """
    ticks = [0]
    acceleration: list[float] | None = None  # at the sample before, from the interval ending there
    for prev, cur in itertools.pairwise(samples):
        count = max(1, round((cur.time_ns - prev.time_ns) * _NS / period_s))
        if _at_rest(prev) and _at_rest(cur):
            acceleration = None
        else:
            a0 = acceleration or [0.0] * len(prev.positions)
            j = max(range(len(prev.positions)), key=lambda k: abs(cur.positions[k] - prev.positions[k]))
            moved = cur.positions[j] - prev.positions[j]
            length = _interval(a0[j], prev.velocities[j], cur.velocities[j], moved, count * period_s)
            if length is not None and abs(moved) > KINEMATIC_MOVE:
                count = max(1, round(length / period_s))
            dt = count * period_s
            acceleration = [
                2.0 * (v1 - v0) / dt - (6.0 * (p1 - p0) - 4.0 * v0 * dt - 2.0 * v1 * dt) / (dt * dt)
                for p0, p1, v0, v1 in zip(
                    prev.positions, cur.positions, prev.velocities, cur.velocities, strict=True
                )
            ]
        ticks.append(ticks[-1] + count)
    return ticks


def _interval(a0: float, v0: float, v1: float, moved: float, guess: float) -> float | None:
    """The length T > 0 of a constant-jerk interval from (v0, a0) to v1 that moves ``moved``: the
    smallest positive root of ``a0·T²/6 + (v0 + (v1 − v0)/3)·T − moved`` (None when there is none;
    ``guess``, the host's, only decides whether the quadratic term matters)."""
    b = v0 + (v1 - v0) / 3.0
    a = a0 / 6.0
    if abs(a) * guess * guess < 1e-9 * abs(b) * guess or a == 0.0:
        return moved / b if b and moved / b > 0.0 else None
    disc = b * b + 4.0 * a * moved
    if disc < 0.0:
        return None
    root = math.sqrt(disc)
    roots = [t for t in ((-b + root) / (2.0 * a), (-b - root) / (2.0 * a)) if t > 0.0]
    return min(roots) if roots else None


def estimate_accelerations(
    times: Sequence[float], positions: Sequence[Sequence[float]], velocities: Sequence[Sequence[float]]
) -> list[tuple[float, ...]]:
    """The acceleration at each sample, each interval taken as one cubic (constant jerk) through its
    two ends' positions and velocities. Where the two intervals around a sample disagree, one holds a
    jerk switch: the sample takes the value of the other (the one whose far end agrees)."""
    count = len(times)
    if count == 0:
        return []
    dof = len(positions[0])
    fwd: list[list[float] | None] = [None] * count
    bwd: list[list[float] | None] = [None] * count
    for i in range(count - 1):
        dt = times[i + 1] - times[i]
        f, b = [], []
        for j in range(dof):
            dp = positions[i + 1][j] - positions[i][j]
            a0 = (6.0 * dp - 4.0 * velocities[i][j] * dt - 2.0 * velocities[i + 1][j] * dt) / (dt * dt)
            f.append(a0)
            b.append(2.0 * (velocities[i + 1][j] - velocities[i][j]) / dt - a0)
        fwd[i], bwd[i + 1] = f, b
    out: list[tuple[float, ...]] = []
    for i in range(count):
        out.append(tuple(_pick(fwd, bwd, i, j) for j in range(dof)))
    return out


def _agree(x: float, y: float) -> bool:
    return abs(x - y) <= _SAME_ACCELERATION * (1.0 + abs(x) + abs(y))


def _pick(fwd: list[list[float] | None], bwd: list[list[float] | None], i: int, j: int) -> float:
    f, b = fwd[i], bwd[i]
    if f is None or b is None:
        known = f if f is not None else b
        return 0.0 if known is None else known[j]
    if _agree(f[j], b[j]):
        return 0.5 * (f[j] + b[j])
    before_f, before_b = fwd[i - 1], bwd[i - 1]
    left_clean = before_f is not None and (before_b is None or _agree(before_f[j], before_b[j]))
    return b[j] if left_clean else f[j]


def _at_rest(sample: Sample) -> bool:
    return all(abs(v) <= REST_VELOCITY for v in sample.velocities)


def knots_of(track: Track, t0_ns: int, mode: str, notes: list[str]) -> list[Knot]:
    """The states the replay of ``track`` passes through, on the recorded timeline (s from
    ``t0_ns``): from its first rest sample to its last (what moves before or after is left out and
    said in ``notes``)."""
    samples = track.samples
    rest = [_at_rest(s) for s in samples]
    if not any(rest):
        notes.append(f"robot {track.robot!r}: never at rest in the recording; nothing to replay")
        return []
    first, last = rest.index(True), len(rest) - 1 - rest[::-1].index(True)
    if first > 0:
        notes.append(f"robot {track.robot!r}: moving when the recording starts; replayed from its first rest")
    if last < len(rest) - 1:
        notes.append(f"robot {track.robot!r}: moving when the recording ends; replayed to its last rest")
    ticks = sample_ticks(samples, track.period_s)
    base = (samples[0].time_ns - t0_ns) * _NS
    times = [base + tick * track.period_s for tick in ticks]
    kept = range(first, last + 1)
    positions = [samples[k].positions for k in kept]
    velocities = [samples[k].velocities for k in kept]
    ktimes = [times[k] for k in kept]
    krest = [rest[k] for k in kept]
    if mode == "samples":
        return _sample_knots(ktimes, positions, velocities, krest, notes, track.robot)
    goals = [((end - t0_ns) * _NS, duration) for end, duration in track.goals]
    return _move_knots(ktimes, positions, velocities, krest, goals)


def _sample_knots(
    times: list[float],
    positions: list[tuple[float, ...]],
    velocities: list[tuple[float, ...]],
    rest: list[bool],
    notes: list[str],
    robot: str,
) -> list[Knot]:
    if _velocities_fit(times, positions, velocities, rest):
        accelerations = estimate_accelerations(times, positions, velocities)
    else:
        notes.append(
            f"robot {robot!r}: its recorded velocities do not fit its positions (a measured arm's): "
            "replayed through its positions, with velocities and accelerations taken from them"
        )
        velocities, accelerations = _differences(times, positions)
    zeros = (0.0,) * len(positions[0])
    knots: list[Knot] = []
    for k, t in enumerate(times):
        if rest[k]:
            inner = 0 < k < len(times) - 1 and rest[k - 1] and rest[k + 1]
            if not inner:
                knots.append(Knot(t, positions[k], zeros, zeros))
        else:
            knots.append(Knot(t, positions[k], velocities[k], accelerations[k]))
    return knots


def _velocities_fit(
    times: Sequence[float],
    positions: Sequence[Sequence[float]],
    velocities: Sequence[Sequence[float]],
    rest: Sequence[bool],
) -> bool:
    """Whether the velocities are the positions' own: at most moving samples the intervals on either
    side, each taken as one cubic, agree on the acceleration (as a plan sampled every cycle does,
    but where the jerk switches; a measured arm's velocity, filtered or lagging, does not)."""
    moving = [k for k in range(1, len(times) - 1) if not rest[k]]
    if not moving:
        return True
    agree = 0
    for k in moving:
        left = estimate_accelerations(
            times[k - 1 : k + 1], positions[k - 1 : k + 1], velocities[k - 1 : k + 1]
        )
        right = estimate_accelerations(times[k : k + 2], positions[k : k + 2], velocities[k : k + 2])
        scale = 1.0 + max(abs(a) for a in (*left[1], *right[0]))
        if all(abs(x - y) <= 1e-3 * scale for x, y in zip(left[1], right[0], strict=True)):
            agree += 1
    return agree >= len(moving) // 2


def _differences(
    times: Sequence[float], positions: Sequence[Sequence[float]]
) -> tuple[list[tuple[float, ...]], list[tuple[float, ...]]]:
    """Velocities and accelerations from the positions alone (central differences; 0 at the ends)."""
    dof = len(positions[0])
    velocities = [(0.0,) * dof]
    accelerations = [(0.0,) * dof]
    for k in range(1, len(times) - 1):
        h1, h2 = times[k] - times[k - 1], times[k + 1] - times[k]
        back = [(positions[k][j] - positions[k - 1][j]) / h1 for j in range(dof)]
        ahead = [(positions[k + 1][j] - positions[k][j]) / h2 for j in range(dof)]
        velocities.append(tuple((h2 * b + h1 * a) / (h1 + h2) for b, a in zip(back, ahead, strict=True)))
        accelerations.append(tuple(2.0 * (a - b) / (h1 + h2) for b, a in zip(back, ahead, strict=True)))
    if len(times) > 1:
        velocities.append((0.0,) * dof)
        accelerations.append((0.0,) * dof)
    return velocities, accelerations


def _move_knots(
    times: list[float],
    positions: list[tuple[float, ...]],
    velocities: list[tuple[float, ...]],
    rest: list[bool],
    goals: Sequence[tuple[float, float]] = (),
) -> list[Knot]:
    """Rest knots only: each rest run's start (a move's end, found from its last moving sample) and
    end (the next move's start, found from its first moving sample). A goal that succeeded while the
    move ran or soon after, and lasted about as long (within 20 %), times the move instead: a measured
    arm lags and smooths what it was commanded, so its moves last longer than they were planned."""
    zeros = (0.0,) * len(positions[0])
    knots = [Knot(times[0], positions[0], zeros, zeros)]
    k = 1
    while k < len(times):
        if rest[k]:
            k += 1
            continue
        stop = k
        while not rest[stop]:
            stop += 1
        start_at = times[k] - _since_rest(positions[k - 1], positions[k], velocities[k])
        end_at = times[stop - 1] + _until_rest(positions[stop - 1], positions[stop], velocities[stop - 1])
        start_at = min(max(start_at, times[k - 1]), times[k])
        end_at = min(max(end_at, times[stop - 1]), times[stop])
        planned = _planned(goals, times[k], times[stop], end_at - start_at)
        if planned is not None:
            end_at = start_at + planned
        if start_at > knots[-1].time_s:
            knots.append(Knot(start_at, positions[k - 1], zeros, zeros))
        knots.append(Knot(max(end_at, knots[-1].time_s + 1e-6), positions[stop], zeros, zeros))
        k = stop + 1
    if times[-1] > knots[-1].time_s:
        knots.append(Knot(times[-1], positions[-1], zeros, zeros))
    return knots


GOAL_RESULT_WAIT_S = 1.0
"""A goal's result may be recorded this long after its robot came to rest (the hold until it settles)."""


def _planned(
    goals: Sequence[tuple[float, float]], first_moving: float, rest: float, measured: float
) -> float | None:
    """The trajectory time of the goal that ended the move from ``first_moving`` to ``rest`` (its
    result recorded in between, or up to ``GOAL_RESULT_WAIT_S`` after) when it is within 20 % of the
    ``measured`` duration; else None."""
    for end, duration in goals:
        if first_moving <= end <= rest + GOAL_RESULT_WAIT_S and 0.8 * measured <= duration <= 1.25 * measured:
            return duration
    return None


def _fastest(velocities: Sequence[float]) -> int:
    return max(range(len(velocities)), key=lambda j: abs(velocities[j]))


def _since_rest(rest: Sequence[float], moving: Sequence[float], velocities: Sequence[float]) -> float:
    """Time from rest to the first moving sample: a jerk-limited start is cubic, p − p0 = v·τ/3."""
    j = _fastest(velocities)
    v = velocities[j]
    return 3.0 * (moving[j] - rest[j]) / v if v else 0.0


def _until_rest(moving: Sequence[float], rest: Sequence[float], velocities: Sequence[float]) -> float:
    """Time from the last moving sample to rest: a jerk-limited stop is cubic, p1 − p = v·τ/3."""
    j = _fastest(velocities)
    v = velocities[j]
    return 3.0 * (rest[j] - moving[j]) / v if v else 0.0


def _common_rests(knots: Mapping[str, list[Knot]]) -> list[float]:
    """Times at which every robot rests and a cell goal may end: the start of each interval in which
    all of them rest (a robot rests before its first knot and after its last)."""
    intervals: list[list[tuple[float, float]]] = []
    for track in knots.values():
        spans = [(-math.inf, track[0].time_s)]
        spans += [(a.time_s, b.time_s) for a, b in itertools.pairwise(track) if a.at_rest and b.at_rest]
        spans.append((track[-1].time_s, math.inf))
        intervals.append(spans)
    starts = sorted({lo for spans in intervals for lo, _ in spans if math.isfinite(lo)})
    return [t for t in starts if all(any(lo <= t <= hi for lo, hi in spans) for spans in intervals)]


def _point(knot: Knot, start: float, rate: float) -> dict[str, Any]:
    return {
        "positions": list(knot.positions),
        "velocities": [v * rate for v in knot.velocities],
        "accelerations": [a * rate * rate for a in knot.accelerations],
        "time_from_start": (knot.time_s - start) / rate,
    }


def _size(points: Sequence[dict[str, Any]]) -> int:
    return sum(len(json.dumps(p, separators=(",", ":"))) + 1 for p in points)


def _part(
    track: list[Knot], grid: tuple[float, float], a: float, b: float, rate: float
) -> list[dict[str, Any]]:
    """A robot's points for the piece (a, b] of the timeline, timed from ``a`` put on its sample grid
    (``grid``: its first sample's time and its period), so each point falls on a tick as recorded."""
    origin, period = grid
    start = origin + math.floor((a - origin) / period + 1e-9) * period
    return [_point(k, start, rate) for k in track if a < k.time_s <= b and k.time_s - start > 1e-9]


def _without_holds(part: list[dict[str, Any]], start: Sequence[float]) -> list[dict[str, Any]]:
    """The part without the rest points at its start position before the last of them: they only
    hold the robot where it is, and one a cycle after the start would ask a robot that rests a hair
    off that position (a real arm, or the fake, settles so) to get there within that cycle."""
    first = 0
    while first + 1 < len(part) and _holds(part[first], start) and _holds(part[first + 1], start):
        first += 1
    return part[first:]


def _holds(point: dict[str, Any], start: Sequence[float]) -> bool:
    return (
        point["positions"] == list(start) and not any(point["velocities"]) and not any(point["accelerations"])
    )


def _moves(part: Sequence[dict[str, Any]], first: Sequence[float]) -> bool:
    return any(p["positions"] != list(first) or any(p["velocities"]) for p in part)


def _fits(parts: Mapping[str, list[dict[str, Any]]]) -> bool:
    if any(len(p) > MAX_POINTS for p in parts.values()):
        return False
    return sum(_size(p) for p in parts.values()) <= MAX_BYTES


def _thin(points: list[dict[str, Any]], keep_every: int) -> list[dict[str, Any]]:
    """Every ``keep_every``-th moving point, every rest point (the last is one)."""
    return [
        p
        for i, p in enumerate(points)
        if i % keep_every == 0 or not any(p["velocities"]) or i == len(points) - 1
    ]


MODES = ("samples", "moves")
"""The shapes of part (module docstring); by default ``samples`` below rate 1, else ``moves``."""


def make_plan(tracks: Sequence[Track], rate: float, mode: str | None = None) -> Plan:
    """The replay of ``tracks`` at ``rate`` (1: recorded speed; 0.5: half), in ``mode`` (one of
    ``MODES``; None: chosen by the rate)."""
    if not (math.isfinite(rate) and rate > 0.0):
        raise ValueError(f"rate must be a finite number > 0, got {rate}")
    if mode is None:
        mode = "samples" if rate < 1.0 else "moves"
    if mode not in MODES:
        raise ValueError(f"mode must be one of {', '.join(MODES)}, got {mode!r}")
    notes: list[str] = []
    t0 = min((t.samples[0].time_ns for t in tracks if t.samples), default=0)
    knots = {t.robot: knots_of(t, t0, mode, notes) for t in tracks if t.samples}
    knots = {r: k for r, k in knots.items() if k}
    grids = {t.robot: ((t.samples[0].time_ns - t0) * _NS, t.period_s) for t in tracks if t.samples}
    plan = Plan({r: k[0].positions for r, k in knots.items()}, [], mode, notes)
    if not knots:
        return plan
    cuts = _common_rests(knots)
    begin = min(k[0].time_s for k in knots.values())
    end = max(k[-1].time_s for k in knots.values())
    cuts = [c for c in cuts if begin < c <= end] or [end]
    if cuts[-1] < end:
        cuts.append(end)
    position = {r: k[0].positions for r, k in knots.items()}
    a, i = begin, 0
    while i < len(cuts):
        parts, j = _longest_piece(knots, grids, position, a, cuts, i, rate, notes)
        if parts:
            longest = max(p[-1]["time_from_start"] for p in parts.values())
            plan.steps.append(Step(a, longest, parts))
            for robot, part in parts.items():
                position[robot] = tuple(part[-1]["positions"])
        a, i = cuts[j], j + 1
    return plan


def _longest_piece(
    knots: Mapping[str, list[Knot]],
    grids: Mapping[str, tuple[float, float]],
    position: Mapping[str, tuple[float, ...]],
    a: float,
    cuts: Sequence[float],
    i: int,
    rate: float,
    notes: list[str],
) -> tuple[dict[str, list[dict[str, Any]]], int]:
    """The parts from ``a`` to the furthest cut from ``cuts[i]`` on that fits in one cell goal (the
    first cut's piece thinned when even it does not fit), and that cut's index."""

    def parts_to(b: float) -> dict[str, list[dict[str, Any]]]:
        out = {}
        for robot, track in knots.items():
            part = _without_holds(_part(track, grids[robot], a, b, rate), position[robot])
            if part and _moves(part, position[robot]):
                out[robot] = part
        return out

    best, best_j = parts_to(cuts[i]), i
    if not _fits(best):
        best = _thinned(best, a, cuts[i], notes)
        return best, i
    lo, hi = i + 1, len(cuts) - 1
    while lo <= hi:  # the points only grow with the cut: the furthest that fits, by bisection
        mid = (lo + hi) // 2
        candidate = parts_to(cuts[mid])
        if _fits(candidate):
            best, best_j, lo = candidate, mid, mid + 1
        else:
            hi = mid - 1
    return best, best_j


def _thinned(
    parts: dict[str, list[dict[str, Any]]], a: float, b: float, notes: list[str]
) -> dict[str, list[dict[str, Any]]]:
    keep = 2
    while keep < 10_000:
        thinned = {r: _thin(p, keep) for r, p in parts.items()}
        if _fits(thinned):
            notes.append(
                f"{a:.3f}..{b:.3f} s of the recording does not fit in one goal "
                f"({', '.join(f'{r}: {len(p)} points' for r, p in parts.items())}): "
                f"replayed through every {keep}th sample, so the path between them is re-planned"
            )
            return thinned
        keep += 1
    raise ValueError(f"{a:.3f}..{b:.3f} s of the recording cannot be thinned into one goal")
