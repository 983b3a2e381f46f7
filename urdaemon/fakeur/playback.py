"""The motion a program plays, on the program's time (``Playback``), and the time scaling that pausing
and resuming ramp (``ScalingRamp``).

Pure: no asyncio, no clock, no arm. ``FakeArm`` (fakeur/fake_arm.py) holds one ``Playback`` and, while it
plays a motion, asks it once per cycle where the joints head (``advance``): a played motion advances
``dt × speed slider × speed scaling`` of program time per cycle (the controller's time scaling). When
it is over and no new motion replaced it, it goes on as a stop with the motion's deceleration, along
the path it was on (a speedj or servoj that is not renewed decelerates to rest); a stop that takes no
time, and a motion played out at rest on its target, end the playing (the arm then holds). The arm
moves its joints toward what ``advance`` answers within their velocity limits and says when they
could not follow (``held_back``), so what is commanded is what the arm does.

Pausing a program ramps the speed scaling to 0 (``pause``): the motion being played goes on along its
path with time slowed to a stop, decelerating within the joint limits; resuming ramps it back to 1
(``resume``) the same way.
"""

from __future__ import annotations

from collections.abc import Sequence

from urdaemon.fakeur.joint_motion import TIME_EPSILON_S, LinearStop, Motion, leading_stop_time

__all__ = ["ACCELERATION_STEP_S", "PAUSE_ACCELERATION_SHARE", "Playback", "ScalingRamp"]

ACCELERATION_STEP_S = 1e-5
"""s of program time: the backward difference over which a motion's acceleration at its end is taken."""
PAUSE_ACCELERATION_SHARE = 0.5
"""The share of each joint's acceleration limit that the speed scaling's ramp may use when the
controller pauses or resumes a program (the motion's own acceleration comes on top, scaled down)."""


class Playback:
    """The motion being played on the program's time, the targets it commands, and its time scaling."""

    __slots__ = (
        "carry",
        "motion",
        "played",
        "position",
        "program_qd",
        "scaling",
        "stop_deceleration",
        "target_q",
        "target_qd",
        "time",
    )

    def __init__(self, q: Sequence[float], stop_deceleration: float) -> None:
        self.motion: Motion | None = None
        """The motion being played: the one given to ``start``, then the stop it goes on as."""
        self.played: Motion | None = None
        """The last motion given to ``start``, until it is dropped (it stays once played out)."""
        self.time = 0.0
        """s: program time played of ``motion``."""
        self.stop_deceleration = stop_deceleration
        """rad/s² of the leading joint: how the motion stops once it is over."""
        self.position = list(q)
        """rad: the motion's position at ``time``."""
        self.target_q = list(q)
        """rad: the joint positions the motion commands."""
        self.target_qd = [0.0] * 6
        """rad/s: the joint velocities the motion commands (scaled by the slider and the scaling)."""
        self.program_qd = [0.0] * 6
        """rad/s of program time: the played motion's velocity before the speed slider's scaling."""
        self.carry = 0.0
        """s of program time: how far the last cycle went on past the end of the motion it ended."""
        self.scaling = ScalingRamp()
        """The time scaling of played motions that pausing and resuming ramp."""

    def start(self, motion: Motion, stop_deceleration: float) -> None:
        """Play ``motion`` from its start, as far into it as the last cycle went on past the motion it
        ended; once over it stops at ``stop_deceleration`` (leading joint, rad/s²)."""
        self.motion = self.played = motion
        self.time = self.carry
        self.carry = 0.0
        self.stop_deceleration = max(float(stop_deceleration), 1e-6)

    def forget(self) -> None:
        """Nothing is played any more (the arm halts: power is cut)."""
        self.motion = self.played = None

    def drop(self) -> None:
        """Nothing is played any more, and nothing goes on past it (the arm stops)."""
        self.motion = self.played = None
        self.carry = 0.0

    def next_cycle(self) -> None:
        """A new controller cycle: no motion has gone on past its end in it yet."""
        self.carry = 0.0

    def advance(self, dt: float, slider: float, q: Sequence[float]) -> list[float] | None:
        """One cycle of ``dt`` s at ``slider`` (speed slider × speed scaling) from joints ``q``: where the
        joints head this cycle, or None when the motion is over and its stop takes no time (nothing
        is played any more: the arm holds). Call only while ``motion`` is set."""
        motion = self.motion
        assert motion is not None
        elapsed = self.time
        if elapsed >= motion.duration - TIME_EPSILON_S:
            # over, and nothing replaced it: stop along the path from the commanded velocity
            velocity = self.program_qd
            motion = self.motion = LinearStop(
                q, velocity, leading_stop_time(velocity, self.stop_deceleration)
            )
            self.time = elapsed = 0.0
            if motion.duration <= 0:
                self.motion = None
                self.target_qd = [0.0] * 6
                self.program_qd = [0.0] * 6
                return None
        budget = dt * slider
        wanted = elapsed + budget
        elapsed = min(wanted, motion.duration)
        self.time = elapsed
        target = self.position = motion.position(elapsed)
        self.target_q = target
        velocity = self.program_qd = motion.velocity(elapsed)
        self.target_qd = [v * slider for v in velocity]
        carry = wanted - elapsed
        if carry > TIME_EPSILON_S and any(velocity):
            # the motion ended within this cycle (its time is not a whole number of cycles at this
            # scaling): the arm goes on at its end velocity for the rest of the cycle, and a motion
            # played next starts that far into its own time (``start``), so a stream of short motions
            # (one speedj per cycle) moves smoothly at any scaling. The target stays the motion's end.
            self.carry = carry
            return _went_on(motion, target, velocity, carry)
        return target

    def held_back(self, q: Sequence[float], qd: Sequence[float], slider: float) -> None:
        """The joints could not follow (the motion asks more than their velocity limits): what is
        commanded is what the arm does (the controller's target speeds never exceed the joint limits),
        and a following motion or stop starts from that."""
        self.target_q = list(q)
        self.target_qd = list(qd)
        if slider > 0:
            self.program_qd = [v / slider for v in qd]

    def played_out(self, q: Sequence[float]) -> list[float] | None:
        """The motion's position when it is over and the joints ``q`` rest on it (nothing is played any
        more: the arm stands there from now on), else None."""
        motion = self.motion
        assert motion is not None
        if self.time < motion.duration - TIME_EPSILON_S or any(self.program_qd):
            return None
        target = self.position
        if not all(abs(q[i] - target[i]) < 1e-9 for i in range(6)):
            return None
        self.motion = None
        return target

    def pause(self, velocity: Sequence[float], max_acceleration: Sequence[float], dt: float) -> bool:
        """Ramp the time scaling to 0 from joints at ``velocity``; True while the motion still slows."""
        self.scaling.ramp_to(0.0, velocity, max_acceleration, PAUSE_ACCELERATION_SHARE, dt)
        return self.scaling.scale != 0.0

    def resume(self, slider: float, max_acceleration: Sequence[float], dt: float, *, playing: bool) -> None:
        """Ramp the time scaling back to 1 the way it came down (from rest unless ``playing``)."""
        velocity = [v * slider for v in self.program_qd] if playing else [0.0] * 6
        self.scaling.ramp_to(1.0, velocity, max_acceleration, PAUSE_ACCELERATION_SHARE, dt)


class ScalingRamp:
    """A speed scaling ramped linearly between 1 and 0 (pause and resume) in controller time.

    The ramp's time is chosen from the joint velocities the arm has (pausing) or will have (resuming)
    at full scale: the scaling's own change then (de)celerates each joint by at most ``share`` of its
    acceleration limit, so the arm slows down and speeds up along its path within the joint limits."""

    __slots__ = ("_rate", "_target", "scale")

    def __init__(self) -> None:
        self.scale = 1.0
        self._target = 1.0
        self._rate = 0.0
        """Scale per second of controller time, toward ``_target``."""

    @property
    def settled(self) -> bool:
        """True when the scale is where the last ramp goes."""
        return self.scale == self._target

    def set(self, scale: float) -> None:
        """Jump to ``scale`` at once (no ramp)."""
        self.scale = self._target = scale
        self._rate = 0.0

    def ramp_to(
        self,
        target: float,
        velocity: Sequence[float],
        max_acceleration: Sequence[float],
        share: float,
        dt: float,
    ) -> None:
        """Ramp to ``target`` (0 or 1): from full scale to none in the time the joints at ``velocity``
        need to stop at ``share`` of ``max_acceleration``; at once if that is within one cycle ``dt``."""
        duration = max(abs(v) / (share * a) for v, a in zip(velocity, max_acceleration, strict=True))
        if duration <= dt:
            self.set(target)
            return
        self._target = target
        self._rate = 1.0 / duration

    def step(self, dt: float) -> float:
        """Advance one cycle of ``dt`` seconds; the scale for this cycle."""
        scale, target = self.scale, self._target
        if scale < target:
            scale = min(target, scale + self._rate * dt)
        elif scale > target:
            scale = max(target, scale - self._rate * dt)
        self.scale = scale
        return scale


def _went_on(motion: Motion, end: list[float], velocity: list[float], carry: float) -> list[float]:
    """Where a motion that ended at ``end`` with ``velocity`` goes on to in ``carry`` s of program time:
    at its end velocity, and a joint that was slowing down keeps slowing down (to rest at the most), so
    the arm does not run past where a path that ends in a slow-down is heading."""
    duration = motion.duration
    h = min(duration, ACCELERATION_STEP_S)
    before = motion.velocity(duration - h) if h > 0 else velocity
    goal = []
    for q, v, w in zip(end, velocity, before, strict=True):
        a = (v - w) / h if h > 0 else 0.0
        if a * v >= 0.0:  # cruising or speeding up: on at the end velocity
            goal.append(q + v * carry)
        elif v * (v + a * carry) <= 0.0:  # at rest before the carry is over
            goal.append(q - v * v / (2.0 * a))
        else:
            goal.append(q + v * carry + 0.5 * a * carry * carry)
    return goal
