"""The linear goal's message (``<cell>/<robot>/goal/linear``): straight TCP lines through a list of
poses; the goal as a client sends it (``LinearGoalRequest``, ``linear_goal_body``), its decoded type
and its decoder, which checks the poses a few at a time."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Generator
from dataclasses import dataclass
from typing import Any

from urdaemon.errors import MessageError
from urdaemon.publish import fields
from urdaemon.publish.envelope import SMALL_MESSAGE_BYTES, decode_message, message_body
from urdaemon.publish.fields import MAX_POSE_M, POSE_FRAMES, Pose6, ToleranceMessage

__all__ = [
    "LINEAR_FIELDS",
    "LINEAR_LIMITS",
    "LINEAR_MESSAGE_BYTES",
    "LINEAR_POSES_PER_LOOK",
    "MAX_LINEAR_POSES",
    "LinearGoalDecoder",
    "LinearGoalMessage",
    "LinearGoalRequest",
    "decode_linear_goal",
    "linear_goal_body",
]

LINEAR_LIMITS = ("speed", "acceleration", "jerk", "angular_speed", "angular_acceleration", "angular_jerk")
"""A linear goal's own Cartesian limits, each optional (m/s, m/s², m/s³, rad/s, rad/s², rad/s³)."""
MAX_LINEAR_POSES = 100
"""Most poses of one linear goal: as many as fit, with every blend radius and field, in the node's
ordinary message size (``LINEAR_MESSAGE_BYTES``); a longer path is sent as several goals."""
LINEAR_MESSAGE_BYTES = SMALL_MESSAGE_BYTES
"""Largest linear goal: the node's ordinary 16 KiB, so its JSON is parsed in one call like every other
non-trajectory message (~0.3 ms at most; 256 KiB held the loop 5-9 ms). 100 poses and 99 blend radii
of full-precision numbers with every field are ~15.6 KB as compact JSON; its poses are checked in
slices (``LinearGoalDecoder``)."""
LINEAR_POSES_PER_LOOK = 16
"""Poses of a linear goal checked between two looks at the clock (~3 µs each)."""


@dataclass(frozen=True, slots=True)
class LinearGoalRequest:
    """A linear goal as a client sends it. Each field is the message's field of that name, in this
    order; None is left out (the daemon's default: no blend, the cell's limits). Values go as given:
    the daemon checks them and refuses naming the field."""

    poses: tuple[Any, ...]
    """Each pose [x, y, z, rx, ry, rz] (m, rad)."""
    frame: str | None = None
    blend_radii: tuple[float, ...] | None = None
    """One per corner (``len(poses) - 1``), m."""
    speed: float | None = None
    acceleration: float | None = None
    jerk: float | None = None
    angular_speed: float | None = None
    angular_acceleration: float | None = None
    angular_jerk: float | None = None
    tolerances: dict[str, Any] | None = None
    """``path``, ``goal`` (a number, or one per joint), ``goal_time`` (s)."""


LINEAR_FIELDS = frozenset(item.name for item in dataclasses.fields(LinearGoalRequest))
"""The fields of a linear goal (``LINEAR_LIMITS`` among them)."""


def linear_goal_body(request: LinearGoalRequest) -> dict[str, Any]:
    """The message's fields of ``request`` (the linear decoder's inverse): tuples as lists, None left
    out."""
    return message_body(request)


@dataclass(frozen=True, slots=True)
class LinearGoalMessage:
    """A decoded linear goal: straight TCP lines from the current pose through each of ``poses``."""

    poses: tuple[Pose6, ...]
    frame: str
    blend_radii: tuple[float, ...]
    """One per corner (``len(poses) - 1``), m; zeros when left out."""
    limits: tuple[tuple[str, float], ...]
    """The Cartesian limits the goal names (field, value), each > 0; the rest are the cell's defaults."""
    tolerances: ToleranceMessage


def decode_linear_goal(payload: bytes | None) -> LinearGoalMessage:
    """Decode a linear goal at once (the daemon uses ``LinearGoalDecoder``, in slices)."""
    steps = LinearGoalDecoder(payload).steps()
    while True:
        try:
            next(steps)
        except StopIteration as stop:
            return stop.value  # type: ignore[no-any-return]


class LinearGoalDecoder:
    """Decodes a linear goal: poses (1..100), frame?, blend_radii?, speed?, acceleration?, jerk?,
    angular_speed?, angular_acceleration?, angular_jerk?, tolerances?.

    The JSON is parsed at once (at most ``LINEAR_MESSAGE_BYTES``, refused by size before parsing:
    ~0.3 ms); its poses are checked
    ``LINEAR_POSES_PER_LOOK`` at a time by ``steps()`` (a generator that returns the goal), so
    the checks of a hundred poses (~0.3 ms) run in slices between robot cycles (runtime/slicing.py).
    """

    def __init__(self, payload: bytes | None) -> None:
        what = self._what = "linear goal"
        data = decode_message(payload, what, max_bytes=LINEAR_MESSAGE_BYTES)
        fields.allowed(data, what, set(LINEAR_FIELDS))
        raw = data.get("poses")
        if not isinstance(raw, list) or not raw:
            raise MessageError(f"{what}.poses: expected a list of one or more poses [x, y, z, rx, ry, rz]")
        if len(raw) > MAX_LINEAR_POSES:
            raise MessageError(f"{what}.poses: {len(raw)} poses; at most {MAX_LINEAR_POSES} are accepted")
        self._data = data
        self._raw: list[Any] = raw
        self._poses: list[Pose6] = []
        self._raw_radii: Any = None
        self._radii: list[float] | None = None

    def steps(self) -> Generator[None, None, LinearGoalMessage]:
        """The checks, a few poses (then blend radii) per ``next``; returns the goal. Raises
        ``MessageError``."""
        while self._next():
            yield
        return self._finish()

    def _next(self) -> bool:
        """Check the next few poses or radii; False once all are checked."""
        raw, poses, what = self._raw, self._poses, self._what
        if len(poses) < len(raw):
            for i in range(len(poses), min(len(raw), len(poses) + LINEAR_POSES_PER_LOOK)):
                poses.append(fields.pose(raw[i], f"{what}.poses[{i}]"))
            return True
        field = f"{what}.blend_radii"
        if self._radii is None:
            given = self._data.get("blend_radii")
            self._raw_radii = [0.0] * (len(raw) - 1) if given is None else given
            self._radii = []
            if not isinstance(self._raw_radii, list):
                raise MessageError(f"{field}: expected a list of numbers, got {type(given).__name__}")
            if len(self._raw_radii) != len(raw) - 1:
                raise MessageError(
                    f"{field}: {len(self._raw_radii)} radii for {len(raw)} poses; expected {len(raw) - 1} "
                    "(one per corner)"
                )
        radii, given = self._radii, self._raw_radii
        if len(radii) < len(given):
            for i in range(len(radii), min(len(given), len(radii) + 6 * LINEAR_POSES_PER_LOOK)):
                radius = fields.number(given[i], f"{field}[{i}]")
                radii.append(fields.within(radius, f"{field}[{i}] (m)", 0.0, MAX_POSE_M))
            return True
        return False

    def _finish(self) -> LinearGoalMessage:
        data, what, poses = self._data, self._what, tuple(self._poses)
        limits = []
        for key in LINEAR_LIMITS:
            value = fields.optional_number(data, key, what)
            if value is not None:
                if not (value > 0.0 and math.isfinite(value)):
                    raise MessageError(f"{what}.{key}: must be a finite number > 0, got {value:g}")
                limits.append((key, value))
        return LinearGoalMessage(
            poses=poses,
            frame=fields.choice(data, "frame", what, POSE_FRAMES),
            blend_radii=tuple(self._radii or ()),
            limits=tuple(limits),
            tolerances=fields.tolerances(data.get("tolerances"), what),
        )
