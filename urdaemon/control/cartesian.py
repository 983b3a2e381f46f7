"""Cartesian motion of a robot's TCP: its limits, and the straight-line path a linear goal follows.

``CartesianLimits`` is the one value type linear goals and twists share: a linear goal
(control/linear.py) time-parameterises its straight lines with it; a twist stream (control/twist.py)
smooths and caps its commands with it. The TCP point's linear limits and the TCP frame's angular limits
are separate, as in URScript's ``movel`` (``v``, ``a``) and ``speedl``.

``LinePath`` is the geometry and timing of a linear goal (docs/cartesian.md): from the start pose
through each pose by straight lines. Segment ``k`` ends at pose ``k``; on it the TCP point moves on the
line and the orientation turns about one fixed axis (the shortest rotation, in base), both by the same
fraction ``s_k(t)``: a rest-to-rest jerk-limited ruckig profile from 0 to 1 whose limits are the
Cartesian ones divided by the segment's length and by its angle, so neither the TCP point's speed,
acceleration, jerk nor the frame's angular ones exceed the limits. A blend radius ``r`` at pose ``k``
(clamped to half of each adjacent segment's length) starts segment ``k + 1`` while segment ``k`` ends,
the two motions superposed: it starts when segment ``k`` has ``r`` left to go, or later if segment
``k + 1`` would cover more than ``r`` before segment ``k`` ends. Each profile is time-symmetric with its
speed rising from each end to its middle, so inside the blend the distance left on ``k`` plus the
distance covered on ``k + 1`` never exceeds ``r``: the TCP stays within ``r`` of pose ``k``.
"""

from __future__ import annotations

import math
from collections.abc import Generator, Sequence
from dataclasses import dataclass, replace
from typing import Any

from ruckig import InputParameter, Ruckig

from urdaemon.control.ruckig_calls import calculate
from urdaemon.description.frames import Frame, Pose, compose, frame_of_pose, inverse, rotation_vector

__all__ = ["SAME_POSE", "CartesianLimits", "LinePath", "LineSegment", "build_path"]

SAME_POSE = 1e-12
"""A pose within this (m and rad) of the one before it adds no segment: the TCP does not move there."""
_BISECTIONS = 64
"""Halvings of a profile's time that find when it reaches a fraction (to float resolution)."""


@dataclass(frozen=True, slots=True)
class CartesianLimits:
    """Limits of the TCP's motion: its point's linear and its frame's angular speed, acceleration, jerk.

    Units: m/s, m/s^2, m/s^3 for the TCP point; rad/s, rad/s^2, rad/s^3 for the TCP frame's rotation.
    Every value must be finite and > 0.
    """

    speed: float
    acceleration: float
    jerk: float
    angular_speed: float
    angular_acceleration: float
    angular_jerk: float

    def __post_init__(self) -> None:
        for name in (
            "speed",
            "acceleration",
            "jerk",
            "angular_speed",
            "angular_acceleration",
            "angular_jerk",
        ):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"CartesianLimits.{name} must be a finite number > 0, got {value!r}")


@dataclass(frozen=True, slots=True)
class LineSegment:
    """One straight line of a path: from the frame ``start`` to pose ``pose`` of the goal.

    ``delta`` is the TCP point's displacement and ``turn`` the rotation (a rotation vector in base,
    the shortest one) from ``start``'s orientation to the pose's; ``profile`` the 1-DOF ruckig
    trajectory of the fraction ``s`` from 0 to 1; ``begin`` when it starts on the path's time.
    """

    pose: int
    start: Frame
    delta: tuple[float, float, float]
    turn: tuple[float, float, float]
    length: float
    angle: float
    profile: Any
    duration: float
    begin: float

    def fraction(self, t: float) -> float:
        """The fraction ``s`` of the line covered at path time ``t`` (0 before it, 1 after it)."""
        t -= self.begin
        if t <= 0.0:
            return 0.0
        if t >= self.duration:
            return 1.0
        return float(self.profile.at_time(t)[0][0])

    def time_at(self, fraction: float) -> float:
        """The profile time (from the segment's start) when ``s`` first reaches ``fraction``."""
        lo, hi = 0.0, self.duration
        for _ in range(_BISECTIONS):
            mid = 0.5 * (lo + hi)
            if self.profile.at_time(mid)[0][0] < fraction:
                lo = mid
            else:
                hi = mid
        return hi


class LinePath:
    """A linear goal's path: its segments on one time line, the pose at any time (see the module)."""

    __slots__ = ("_cursor", "duration", "end", "segments", "start")

    def __init__(self, start: Pose, end: Pose, segments: list[LineSegment]) -> None:
        self.start = start
        """The TCP pose the path starts at."""
        self.end = end
        """The last pose (exactly as given)."""
        self.segments = segments
        self.duration = max((seg.begin + seg.duration for seg in segments), default=0.0)
        """The path's time at the Cartesian limits (s)."""
        self._cursor = 0

    def where(self, t: float) -> tuple[int, float]:
        """The pose index of the segment under way at path time ``t`` and the fraction of it covered."""
        k = self._seek(t)
        if k >= len(self.segments):
            return (self.segments[-1].pose, 1.0) if self.segments else (0, 1.0)
        seg = self.segments[k]
        return seg.pose, seg.fraction(t)

    def _seek(self, t: float) -> int:
        """The first segment not finished at ``t`` (segments end in order)."""
        segments = self.segments
        k = self._cursor
        if k > 0 and t < segments[k - 1].begin + segments[k - 1].duration:
            k = 0  # time went back: start over
        while k < len(segments) and t >= segments[k].begin + segments[k].duration:
            k += 1
        self._cursor = k
        return k

    def frame_at(self, t: float) -> Frame:
        """The TCP frame at path time ``t``: the segment under way and, in a blend, the next one."""
        segments = self.segments
        k = self._seek(t)
        if k >= len(segments):
            return frame_of_pose(self.end)
        seg = segments[k]
        s = seg.fraction(t)
        x = seg.start[9] + s * seg.delta[0]
        y = seg.start[10] + s * seg.delta[1]
        z = seg.start[11] + s * seg.delta[2]
        w = seg.turn
        rot = compose(frame_of_pose((0.0, 0.0, 0.0, s * w[0], s * w[1], s * w[2])), seg.start)
        if k + 1 < len(segments) and t > segments[k + 1].begin:
            nxt = segments[k + 1]
            s = nxt.fraction(t)
            x += s * nxt.delta[0]
            y += s * nxt.delta[1]
            z += s * nxt.delta[2]
            w = nxt.turn
            rot = compose(frame_of_pose((0.0, 0.0, 0.0, s * w[0], s * w[1], s * w[2])), rot)
        return (*rot[:9], x, y, z)


def _profile(length: float, angle: float, limits: CartesianLimits, what: str) -> Any:
    """The rest-to-rest profile of ``s`` from 0 to 1 within the limits over ``length`` and ``angle``."""
    bounds = []
    if length > 0.0:
        bounds.append((limits.speed / length, limits.acceleration / length, limits.jerk / length))
    if angle > 0.0:
        bounds.append(
            (limits.angular_speed / angle, limits.angular_acceleration / angle, limits.angular_jerk / angle)
        )
    inp = InputParameter(1)
    inp.current_position = [0.0]
    inp.target_position = [1.0]
    inp.max_velocity = [min(b[0] for b in bounds)]
    inp.max_acceleration = [min(b[1] for b in bounds)]
    inp.max_jerk = [min(b[2] for b in bounds)]
    return calculate(Ruckig(1), inp, what)


def _line(index: int, start: Frame, pose: Pose, limits: CartesianLimits, begin: float) -> LineSegment | None:
    """The segment from ``start`` to ``pose`` (goal pose ``index``) starting at ``begin``; None if
    the pose is the start's (within ``SAME_POSE``)."""
    end = frame_of_pose(pose)
    delta = (end[9] - start[9], end[10] - start[10], end[11] - start[11])
    turn = rotation_vector(*compose(end, inverse(start))[:9])
    length = math.sqrt(delta[0] ** 2 + delta[1] ** 2 + delta[2] ** 2)
    angle = math.sqrt(turn[0] ** 2 + turn[1] ** 2 + turn[2] ** 2)
    if length < SAME_POSE and angle < SAME_POSE:
        return None
    what = f"linear goal: segment {index}"
    profile = _profile(length, angle, limits, what)
    return LineSegment(index, start, delta, turn, length, angle, profile, float(profile.duration), begin)


def _overlap(before: LineSegment, after: LineSegment, radius: float) -> float:
    """How long ``after`` runs while ``before`` ends, for a blend of ``radius`` (0: none)."""
    r = min(radius, 0.5 * before.length, 0.5 * after.length)
    if not r > 0.0:
        return 0.0
    out = before.duration - before.time_at(1.0 - r / before.length)
    into = after.time_at(r / after.length)
    return max(0.0, min(out, into))


def build_path(
    start: Pose, poses: Sequence[Pose], blends: Sequence[float], limits: CartesianLimits
) -> Generator[None, None, LinePath]:
    """The path from ``start`` through ``poses`` (blend radius ``blends[k]`` at pose ``k``), a
    segment a step. Raises GoalRejected if ruckig cannot time a segment."""
    segments: list[LineSegment] = []
    frame = frame_of_pose(start)
    begin = 0.0
    for k, pose in enumerate(poses):
        seg = _line(k, frame, pose, limits, begin)
        frame = frame_of_pose(pose)
        if seg is None:
            yield
            continue
        if segments:
            prev = segments[-1]
            radius = blends[k - 1] if prev.pose == k - 1 else 0.0
            overlap = _overlap(prev, seg, radius)
            if overlap > 0.0:
                seg = replace(seg, begin=begin - overlap)
        segments.append(seg)
        begin = seg.begin + seg.duration
        yield
    end = poses[-1] if poses else start
    return LinePath(start, (end[0], end[1], end[2], end[3], end[4], end[5]), segments)
