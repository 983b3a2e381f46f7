"""The fake arm's joint-space motions: what a controller plays for movej, speedj, servoj, stopj, stopl.

Pure: no asyncio, no clock. A ``Motion`` is a joint-space path over program time ``[0, duration]``;
``FakeArm.play`` samples it once per cycle (fakeur/playback.py), advancing ``dt × speed slider`` of
program time (the controller's time scaling), so every motion here is written in program time. All
arrays are plain lists of 6 floats (hot path: no numpy). The motions whose path is the TCP's (movel,
movep, movec, speedl) are in fakeur/tcp_motion.py, on the profile and the ``Motion`` of this module.

* ``JointMove`` (movej): the leading joint follows a trapezoidal speed profile and every other joint
  is scaled to arrive with it; started while the arm still moves (a blend), the old velocity fades out
  under a cubic Hermite term decelerating at most at the move's acceleration, so the path is smooth.
* ``SpeedRamp`` (speedj): accelerate linearly (``a`` of the leading joint, all joints reaching their
  speeds together) to the target joint speeds, then keep them. A speedj faster than a joint's speed
  limit is played slower in time (``TimeScaled``, ``speed_command``): the joints keep the direction and
  the distance the command asks for, as a controller's speed limiter slows a program rather than
  clamping one joint.
* ``ServoFilter`` (servoj): the joints pulled toward the setpoint by the manual's gain and lookahead
  (a model: a damped oscillator, solved in closed form), so the arm lags a moving setpoint.
* ``LinearStop`` (stopj, stopl, a stop at the end of a motion): every joint decelerates linearly to rest
  in the same time, so the arm stops along the path it was on.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Final, Protocol

from urdaemon.model import UR_JOINT_COUNT

__all__ = [
    "JOINTS",
    "TIME_EPSILON_S",
    "JointMove",
    "LinearStop",
    "Motion",
    "Profile",
    "ServoFilter",
    "ServoModes",
    "SpeedRamp",
    "TimeScaled",
    "Vector",
    "joint_move",
    "leading_stop_time",
    "profile",
    "resumed_velocity",
    "servo_modes",
    "speed_command",
    "time_factor",
]

JOINTS: Final = UR_JOINT_COUNT
TIME_EPSILON_S: Final = 1e-9
"""s: a motion with less than this left is over (float noise of summing cycle times)."""

Vector = list[float]
"""One value per joint (rad, rad/s)."""


class Motion(Protocol):
    """A joint-space motion over ``[0, duration]`` s of program time."""

    duration: float

    def position(self, t: float) -> Vector:
        """Joint positions [rad] at ``t``."""
        ...

    def velocity(self, t: float) -> Vector:
        """Joint velocities [rad/s] at ``t`` (in program time)."""
        ...


# ---- a 1-D trapezoidal profile ---------------------------------------------------------------------


class Profile:
    """Distance ``s(t)`` over ``[0, duration]``: accelerate for ``ramp`` s to ``peak``, cruise, decelerate."""

    __slots__ = ("distance", "duration", "peak", "ramp")

    def __init__(self, distance: float, ramp: float, peak: float) -> None:
        self.distance = distance
        self.ramp = ramp
        self.peak = peak
        self.duration = distance / peak + ramp if distance > 0 and peak > 0 else 0.0

    def at(self, t: float) -> tuple[float, float]:
        """(distance covered, speed) at ``t``."""
        ramp, peak, total = self.ramp, self.peak, self.duration
        if t <= 0.0 or total <= 0.0:
            return 0.0, 0.0
        if t >= total:
            return self.distance, 0.0
        if t < ramp:
            return 0.5 * peak / ramp * t * t, peak / ramp * t
        if t <= total - ramp:
            return peak * (t - 0.5 * ramp), peak
        left = total - t
        return self.distance - 0.5 * peak / ramp * left * left, peak / ramp * left


def profile(distance: float, *, velocity: float, acceleration: float, duration: float = 0.0) -> Profile:
    """The profile covering ``distance`` at ``velocity``/``acceleration``, or in ``duration`` if > 0.

    ValueError for a speed or acceleration that cannot move. With a duration (URScript: ``t`` given,
    then ``v`` and ``a`` are ignored) the acceleration is kept if it can make the time, else the
    gentlest triangle that does.
    """
    if distance <= 0:
        return Profile(0.0, 0.0, 1.0)
    if duration > 0:
        a = acceleration
        discriminant = (a * duration) ** 2 - 4 * a * distance if a > 0 else -1.0
        if discriminant >= 0:
            peak = (a * duration - math.sqrt(discriminant)) / 2
            return Profile(distance, peak / a, peak)
        return Profile(distance, duration / 2, 2 * distance / duration)
    if not (velocity > 0 and acceleration > 0 and math.isfinite(velocity) and math.isfinite(acceleration)):
        raise ValueError(f"needs a > 0 and v > 0 (got a={acceleration}, v={velocity})")
    ramp = velocity / acceleration
    if distance < velocity * ramp:  # never reaches v: a triangle at acceleration a
        ramp = math.sqrt(distance / acceleration)
        return Profile(distance, ramp, acceleration * ramp)
    return Profile(distance, ramp, velocity)


# ---- joint motions ---------------------------------------------------------------------------------


class JointMove:
    """movej: start → target along a straight joint-space line; a start velocity fades out smoothly."""

    __slots__ = ("_delta", "_fade", "_profile", "_residual", "_start", "duration", "target")

    def __init__(
        self,
        start: Sequence[float],
        target: Sequence[float],
        shape: Profile,
        start_velocity: Sequence[float] | None = None,
        fade_time: float = 0.0,
    ) -> None:
        self._start = [float(v) for v in start]
        self.target = [float(v) for v in target]
        self._delta = [b - a for a, b in zip(self._start, self.target, strict=True)]
        self._profile = shape
        moving = start_velocity is not None and fade_time > 0 and any(start_velocity)
        self._residual = [float(v) for v in start_velocity] if moving and start_velocity else None
        self._fade = fade_time if moving else 0.0
        self.duration = max(shape.duration, self._fade)

    def _fraction(self, t: float) -> tuple[float, float]:
        shape = self._profile
        if shape.distance <= 0:
            return 1.0, 0.0
        s, ds = shape.at(t)
        return s / shape.distance, ds / shape.distance

    def position(self, t: float) -> Vector:
        """Joint positions [rad] at ``t``."""
        f, _ = self._fraction(t)
        q = [a + d * f for a, d in zip(self._start, self._delta, strict=True)]
        residual, fade = self._residual, self._fade
        if residual is not None and t < fade:
            # Hermite h10(u)·T: 0 at both ends, slope 1 at the start and 0 at the end
            u = max(t, 0.0) / fade
            h = fade * u * (1.0 - u) * (1.0 - u)
            q = [v + r * h for v, r in zip(q, residual, strict=True)]
        return q

    def velocity(self, t: float) -> Vector:
        """Joint velocities [rad/s] at ``t``."""
        _, rate = self._fraction(t)
        qd = [d * rate for d in self._delta]
        residual, fade = self._residual, self._fade
        if residual is not None and t < fade:
            u = max(t, 0.0) / fade
            dh = (1.0 - u) * (1.0 - 3.0 * u)
            qd = [v + r * dh for v, r in zip(qd, residual, strict=True)]
        return qd


def joint_move(
    start: Sequence[float],
    target: Sequence[float],
    *,
    velocity: float,
    acceleration: float,
    duration: float = 0.0,
    max_velocity: Sequence[float] | None = None,
    start_velocity: Sequence[float] | None = None,
) -> JointMove:
    """movej(target, a, v, t) from ``start``; v and a are the leading joint's, capped so that no joint
    exceeds ``max_velocity``. A ``start_velocity`` (blending out of a moving motion) fades out,
    decelerating at most at ``acceleration``. ValueError for a speed or acceleration that cannot move."""
    delta = [b - a for a, b in zip(start, target, strict=True)]
    distance = max((abs(d) for d in delta), default=0.0)
    if max_velocity is not None and distance > 0 and duration <= 0:
        for d, limit in zip(delta, max_velocity, strict=True):
            if abs(d) > 0:
                velocity = min(velocity, limit * distance / abs(d))
    shape = profile(distance, velocity=velocity, acceleration=acceleration, duration=duration)
    fade = 0.0
    if start_velocity is not None and acceleration > 0:
        # the Hermite fade's deceleration peaks at 4·v0/T at its start: T = 4·v0/a keeps it within a
        fade = 4.0 * max((abs(v) for v in start_velocity), default=0.0) / acceleration
    return JointMove(start, target, shape, start_velocity, fade)


class SpeedRamp:
    """speedj: from ``start_velocity`` to ``target_velocity`` at ``acceleration`` (leading joint); then on."""

    __slots__ = ("_accel", "_q0", "_ramp", "_v0", "_v1", "duration")

    def __init__(
        self,
        start: Sequence[float],
        start_velocity: Sequence[float],
        target_velocity: Sequence[float],
        acceleration: float,
        duration: float,
    ) -> None:
        """``duration`` <= 0: the motion lasts until the target speed is reached."""
        self._q0 = [float(v) for v in start]
        self._v0 = [float(v) for v in start_velocity]
        self._v1 = [float(v) for v in target_velocity]
        change = max(abs(b - a) for a, b in zip(self._v0, self._v1, strict=True))
        a = max(float(acceleration), 1e-9)
        self._ramp = change / a
        ramp = self._ramp
        self._accel = [(b - v) / ramp if ramp > 0 else 0.0 for v, b in zip(self._v0, self._v1, strict=True)]
        self.duration = duration if duration > 0 else ramp

    def position(self, t: float) -> Vector:
        """Joint positions [rad] at ``t``."""
        ramp = self._ramp
        if t <= ramp:
            return [
                q + v * t + 0.5 * a * t * t for q, v, a in zip(self._q0, self._v0, self._accel, strict=True)
            ]
        rest = t - ramp
        return [
            q + v * ramp + 0.5 * a * ramp * ramp + w * rest
            for q, v, a, w in zip(self._q0, self._v0, self._accel, self._v1, strict=True)
        ]

    def velocity(self, t: float) -> Vector:
        """Joint velocities [rad/s] at ``t``."""
        if t >= self._ramp:
            return list(self._v1)
        return [v + a * t for v, a in zip(self._v0, self._accel, strict=True)]


class TimeScaled:
    """``motion`` played ``factor`` (>= 1) times slower: the same path, every velocity divided by the
    factor. How a controller keeps a command within the joint speed limits: it slows the program's
    time (RTDE ``speed_scaling`` below 1) rather than clamping a joint, so the path is kept."""

    __slots__ = ("_factor", "_motion", "duration")

    def __init__(self, motion: Motion, factor: float) -> None:
        self._motion = motion
        self._factor = factor
        self.duration = motion.duration * factor

    def position(self, t: float) -> Vector:
        """Joint positions [rad] at ``t``."""
        return self._motion.position(t / self._factor)

    def velocity(self, t: float) -> Vector:
        """Joint velocities [rad/s] at ``t``."""
        factor = self._factor
        return [v / factor for v in self._motion.velocity(t / factor)]


def time_factor(velocities: Sequence[Sequence[float]], limits: Sequence[float], slider: float) -> float:
    """How many times slower (>= 1) joints at any of ``velocities`` (program time, played at ``slider``)
    must go to stay within their speed ``limits``."""
    factor = 1.0
    for velocity in velocities:
        for v, limit in zip(velocity, limits, strict=True):
            factor = max(factor, abs(v) * slider / limit)
    return factor


def resumed_velocity(moving: Vector, asked: Sequence[float], factor: float) -> Vector:
    """The velocity a speedj ramps on from: what the speedj before asked (``asked``), when it was played
    ``factor`` times slower and the joints still move at that (``moving``); else ``moving``."""
    if factor > 1.0 and all(
        abs(m * factor - v) <= 1e-9 * (1.0 + abs(v)) for m, v in zip(moving, asked, strict=True)
    ):
        return list(asked)
    return moving


def speed_command(
    start: Sequence[float],
    start_velocity: Sequence[float],
    target_velocity: Sequence[float],
    acceleration: float,
    times: tuple[float, float],
    limits: tuple[Sequence[float], float],
) -> tuple[Motion, float]:
    """speedj from joints ``start`` at ``start_velocity`` (as commanded, before any slowing) to
    ``target_velocity``: the motion to play and its time factor (1: as asked). ``times``: (t, at least);
    a motion shorter than the second (one cycle) lasts that long. ``limits``: (joint speed limits,
    speed slider). Too fast for a joint's limit, the whole ramp is played slower (``TimeScaled``):
    the joints cover what the command asks, in more time, along the same direction."""
    duration, shortest = times
    ramp = SpeedRamp(start, start_velocity, target_velocity, acceleration, duration)
    if ramp.duration < shortest:  # t = 0 and already (nearly) at speed: one cycle at that speed
        ramp = SpeedRamp(start, start_velocity, target_velocity, acceleration, shortest)
    factor = time_factor((start_velocity, target_velocity), *limits)
    return (ramp if factor <= 1.0 else TimeScaled(ramp, factor)), factor


class ServoModes:
    """The modal quantities of servoj's law for one (gain, lookahead_time), shared by every joint and
    every servoj call with them (``servo_modes``): ω = √gain, ζ = lookahead_time·√gain / 2, and the
    basis (f, h, f', h') of the free response, with the last sample kept (a stream samples the same
    time, one cycle, every call)."""

    __slots__ = ("_last", "kind", "r1", "r2", "sigma", "w", "wd", "zeta")

    def __init__(self, gain: float, lookahead_time: float) -> None:
        w = math.sqrt(gain)
        zeta = 0.5 * lookahead_time * w
        self.w = w
        self.zeta = zeta
        self.sigma = zeta * w
        self.wd = self.r1 = self.r2 = 0.0
        if zeta < 1.0 - 1e-9:
            self.kind = 0  # under-damped
            self.wd = w * math.sqrt(1.0 - zeta * zeta)
        elif zeta > 1.0 + 1e-9:
            self.kind = 2  # over-damped
            root = w * math.sqrt(zeta * zeta - 1.0)
            self.r1, self.r2 = -self.sigma + root, -self.sigma - root
        else:
            self.kind = 1  # critically damped
        self._last: tuple[float, float, float, float, float] = (0.0, 1.0, 0.0, 0.0, 1.0)

    def basis(self, t: float) -> tuple[float, float, float, float, float]:
        """(t, f, h, f', h') at ``t`` >= 0: e(t) = e₀·f + ė₀·h and ė(t) = e₀·f' + ė₀·h'."""
        last = self._last
        if last[0] == t:
            return last
        kind = self.kind
        if kind == 0:
            sigma, wd = self.sigma, self.wd
            decay = math.exp(-sigma * t)
            c, s = math.cos(wd * t) * decay, math.sin(wd * t) * decay
            w2 = self.w * self.w
            basis = (t, c + sigma / wd * s, s / wd, -w2 / wd * s, c - sigma / wd * s)
        elif kind == 1:
            w = self.w
            decay = math.exp(-w * t)
            basis = (t, (1.0 + w * t) * decay, t * decay, -w * w * t * decay, (1.0 - w * t) * decay)
        else:
            r1, r2 = self.r1, self.r2
            e1, e2 = math.exp(r1 * t), math.exp(r2 * t)
            k = 1.0 / (r1 - r2)
            basis = (
                t,
                (r1 * e2 - r2 * e1) * k,
                (e1 - e2) * k,
                r1 * r2 * (e2 - e1) * k,
                (r1 * e1 - r2 * e2) * k,
            )
        self._last = basis
        return basis


_SERVO_MODES: dict[tuple[float, float], ServoModes] = {}
_SERVO_MODES_KEPT: Final = 64
"""Distinct (gain, lookahead_time) pairs kept; a program that uses more starts the table afresh."""


def servo_modes(gain: float, lookahead_time: float) -> ServoModes:
    """The shared ``ServoModes`` of (gain, lookahead_time)."""
    key = (gain, lookahead_time)
    modes = _SERVO_MODES.get(key)
    if modes is None:
        if len(_SERVO_MODES) >= _SERVO_MODES_KEPT:
            _SERVO_MODES.clear()
        modes = _SERVO_MODES[key] = ServoModes(gain, lookahead_time)
    return modes


class ServoFilter:
    """servoj: the joints pulled toward the setpoint ``target`` by the manual's PD law, for ``duration`` s.

    A model of what the URScript manual says of servoj (the controller's own law is not published):
    ``gain`` acts like the P-term of a PID controller and ``lookahead_time`` projects the position
    forward with the current velocity. Per joint, toward a constant setpoint q*::

        q'' = gain · (q* − (q + lookahead_time · q'))

    a damped oscillator of natural frequency ω = √gain (1/s) and damping ratio
    ζ = lookahead_time·√gain / 2 (gain 300 / lookahead 0.1: ζ = 0.87; 2000 / 0.03: ζ = 0.67, a slight
    overshoot; 100 / 0.03: ζ = 0.15, it oscillates). On setpoints moving at speed v the joints lag
    ``lookahead_time × v`` behind. Solved in closed form from ``start`` and ``start_velocity``: with
    e = q − q*, e(t) = e₀·f(t) + ė₀·h(t), where the basis f, h (and their derivatives) depend only on
    gain and lookahead (``ServoModes``), so they are computed once per sample for all six joints.
    """

    __slots__ = ("_e0", "_modes", "_v0", "duration", "target")

    def __init__(
        self,
        start: list[float],
        start_velocity: list[float],
        target: list[float],
        duration: float,
        gain: float,
        lookahead_time: float,
    ) -> None:
        """Keeps ``target`` and ``start_velocity`` (the caller gives lists it does not change afterwards)."""
        self.target = target
        self.duration = duration
        s, g = start, target  # six joints, unrolled: this runs once per cycle of a servoj stream
        self._e0 = [s[0] - g[0], s[1] - g[1], s[2] - g[2], s[3] - g[3], s[4] - g[4], s[5] - g[5]]
        self._v0 = start_velocity
        self._modes = servo_modes(gain, lookahead_time)

    def position(self, t: float) -> Vector:
        """Joint positions [rad] at ``t``."""
        _, f, h, _, _ = self._modes.basis(min(max(t, 0.0), self.duration))
        q, e, v = self.target, self._e0, self._v0
        return [
            q[0] + e[0] * f + v[0] * h,
            q[1] + e[1] * f + v[1] * h,
            q[2] + e[2] * f + v[2] * h,
            q[3] + e[3] * f + v[3] * h,
            q[4] + e[4] * f + v[4] * h,
            q[5] + e[5] * f + v[5] * h,
        ]

    def velocity(self, t: float) -> Vector:
        """Joint velocities [rad/s] at ``t``."""
        _, _, _, df, dh = self._modes.basis(min(max(t, 0.0), self.duration))
        e, v = self._e0, self._v0
        return [
            e[0] * df + v[0] * dh,
            e[1] * df + v[1] * dh,
            e[2] * df + v[2] * dh,
            e[3] * df + v[3] * dh,
            e[4] * df + v[4] * dh,
            e[5] * df + v[5] * dh,
        ]


class LinearStop:
    """Every joint from ``start_velocity`` to rest in ``duration`` s, decelerating linearly."""

    __slots__ = ("_q0", "_v0", "duration")

    def __init__(self, start: Sequence[float], start_velocity: Sequence[float], duration: float) -> None:
        self._q0 = [float(v) for v in start]
        self._v0 = [float(v) for v in start_velocity]
        self.duration = duration if any(self._v0) else 0.0

    def position(self, t: float) -> Vector:
        """Joint positions [rad] at ``t``."""
        total = self.duration
        t = min(max(t, 0.0), total)
        factor = t - t * t / (2.0 * total) if total > 0 else 0.0
        return [q + v * factor for q, v in zip(self._q0, self._v0, strict=True)]

    def velocity(self, t: float) -> Vector:
        """Joint velocities [rad/s] at ``t``."""
        total = self.duration
        if total <= 0 or t >= total:
            return [0.0] * JOINTS
        scale = 1.0 - max(t, 0.0) / total
        return [v * scale for v in self._v0]


def leading_stop_time(velocity: Sequence[float], deceleration: float) -> float:
    """s: the time a stop at ``deceleration`` of the leading joint takes from ``velocity``."""
    return max((abs(v) for v in velocity), default=0.0) / max(deceleration, 1e-9)
