"""Joint streams: position or velocity targets a client sends every cycle, followed within the limits.

Owns the newest stream target, the braking near the position limits and the deadman. A position
stream brakes a joint whose freshly planned path would leave its limits, or that passed its target and
coasts on toward a limit it could no longer stop before; a velocity stream latches a joint's target to
zero once it must brake, until the client stops asking to go that way. Far from the limits (beyond
the safe distance, the longest stop from any admissible state) none of this is checked. The deadman:
a stream whose last command is older than the timeout has ended; the controller then stops it.
Streams run in real time: the speed scaling does not slow them (the client owns their timing).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from ruckig import Synchronization

from urdaemon.control.limits import (
    BRAKE_DOWN,
    BRAKE_UP,
    apply_permutation,
    braking_needed,
    check_finite,
    check_positions_within,
    check_velocities_within,
    stopping_distance,
)
from urdaemon.control.online import FINISHED, WORKING, OnlineGenerator
from urdaemon.control.ruckig_calls import RUCKIG_ERRORS, position_extrema, run_robustly
from urdaemon.control.setpoint import Setpoint, write_setpoint
from urdaemon.model import JointCommand, JointLimits

__all__ = ["STREAM_EXPIRED", "STREAM_FAILED", "STREAM_FOLLOWED", "StreamFollower"]

STREAM_FOLLOWED = 0
"""A stream tick wrote this cycle's setpoint."""
STREAM_FAILED = 1
"""A stream tick found no next setpoint (ruckig failed): nothing written, the stream is over."""
STREAM_EXPIRED = 2
"""A stream tick found the last command older than the timeout (the deadman): nothing written."""
_EXTREMA_EPS = 1e-9


class StreamFollower:
    """Follows one joint stream at a time online, braking joints that would leave their limits."""

    __slots__ = (
        "_acc",
        "_amax",
        "_applied_sync",
        "_braking",
        "_effective",
        "_hi",
        "_inp",
        "_jmax",
        "_latch",
        "_limits",
        "_lo",
        "_names",
        "_online",
        "_out",
        "_period",
        "_pos",
        "_safe_distance",
        "_synchronized",
        "_target",
        "_target_velocity",
        "_update",
        "_vel",
        "_velocity",
        "_vmax",
        "_zeros",
        "last_command",
        "timeout",
    )

    def __init__(
        self, limits: JointLimits, period: float, timeout: float, online: OnlineGenerator, setpoint: Setpoint
    ) -> None:
        n = limits.dof
        self._limits = limits
        self.timeout = timeout
        """s: a stream without a command for longer has ended (the deadman)."""
        self._names = limits.names
        self._period = period
        self._lo = list(limits.min_position)
        self._hi = list(limits.max_position)
        self._vmax = list(limits.max_velocity)
        self._amax = list(limits.max_acceleration)
        self._jmax = list(limits.max_jerk)
        self._safe_distance = [
            stopping_distance(v + a * period, a, a, j) + 2.0 * v * period + 1e-6
            for v, a, j in zip(self._vmax, self._amax, self._jmax, strict=True)
        ]
        """Per joint, the distance from both limits beyond which no stop from any admissible state
        can reach a limit: the per-cycle braking check is skipped there (the common case)."""
        self._online = online
        self._inp = online.inp
        self._out = online.out
        self._update = online.update
        self._braking = online.braking
        self._pos = setpoint.pos
        self._vel = setpoint.vel
        self._acc = setpoint.acc
        self._zeros = setpoint.zeros
        self._target = [0.0] * n
        """The position stream's target."""
        self._target_velocity = [0.0] * n
        """The position stream's velocity at the target (zero where coasting on could not stop)."""
        self._velocity = [0.0] * n
        self._effective = [0.0] * n
        self._latch = [0] * n
        self._synchronized = False
        self._applied_sync = False
        """Whether ruckig synchronizes now (off while a synchronized stream brakes for a limit)."""
        """Joints reach their velocity targets together (a twist's), not each as fast as it can."""
        self.last_command = -math.inf
        """When the last command of the running stream came (host seconds); -inf when none runs."""

    def release(self) -> None:
        """Let go of the online generator's ruckig objects, held here for the cycle's sake, and then the
        generator's own (the daemon stopped); unusable afterwards."""
        del self._inp, self._out, self._update
        self._online.release()

    def active(self, now: float) -> bool:
        """Whether the last command is recent enough for the stream to run on."""
        return now - self.last_command <= self.timeout

    def forget(self) -> None:
        """No stream runs: commands of a stopped stream must not keep it "active" for busy checks."""
        self.last_command = -math.inf
        self._synchronize(False)

    def _synchronize(self, on: bool) -> None:
        """Make the joints reach their targets at the same time (``on``) or each on its own."""
        if on != self._synchronized:
            self._synchronized = on
            self._applied_sync = on
            self._inp.synchronization = Synchronization.Time if on else Synchronization.No

    # ------------------------------------------------------------------ commands

    def follow_positions(
        self,
        perm: Sequence[int],
        positions: Sequence[float],
        velocities: Sequence[float] | None,
        start: Sequence[float] | None,
        now: float,
    ) -> None:
        """Make ``positions`` (reach them at ``velocities``, if given) the target; raises GoalRejected.

        ``start``: the measured pose to start from at rest; None continues from the setpoint.
        """
        target = apply_permutation(perm, positions, "positions")
        check_finite("positions", target, self._names)
        check_positions_within(self._limits, target, "stream target")
        tvel = self._zeros
        if velocities is not None:
            given = apply_permutation(perm, velocities, "velocities")
            check_finite("velocities", given, self._names)
            check_velocities_within(self._limits, given, "stream target")
            tvel = self._stoppable(target, list(given))
        self._start(start)
        self._synchronize(False)
        self._target[:] = target
        self._target_velocity[:] = tvel
        self._online.toward_position(self._target, tvel)
        self.last_command = now

    def _stoppable(self, target: Sequence[float], tvel: list[float]) -> list[float]:
        """``tvel`` with zero where coasting on from the target could not stop inside the limits."""
        safe = self._safe_distance
        for i, v in enumerate(tvel):
            q = target[i]
            if v == 0.0 or (q + safe[i] < self._hi[i] and q - safe[i] > self._lo[i]):
                continue
            mask = braking_needed(
                q, v, 0.0, self._lo[i], self._hi[i], self._amax[i], self._jmax[i], self._period
            )
            if (v > 0.0 and mask & BRAKE_UP) or (v < 0.0 and mask & BRAKE_DOWN):
                tvel[i] = 0.0
        return tvel

    def follow_velocities(
        self,
        perm: Sequence[int],
        velocities: Sequence[float],
        start: Sequence[float] | None,
        first: bool,
        now: float,
    ) -> None:
        """Make ``velocities`` the target velocity (limits are guarded every cycle); raises GoalRejected.

        ``start`` as for ``follow_positions``; ``first``: no velocity stream ran the cycle before.
        """
        target = apply_permutation(perm, velocities, "velocities")
        check_finite("velocities", target, self._names)
        check_velocities_within(self._limits, target, "stream target")
        self.follow_computed(start, first, now)
        self._velocity[:] = target

    def follow_computed(
        self, start: Sequence[float] | None, first: bool, now: float, *, synchronized: bool = False
    ) -> None:
        """A velocity stream whose target is set every cycle by ``want_velocities`` (a twist's joint
        velocities); ``now``: when the client's command that keeps it running came (the deadman's
        clock); ``synchronized``: the joints reach the target together, so their velocities keep the
        target's proportions (a twist's direction) while they change. ``start`` and ``first`` as for
        ``follow_velocities``."""
        self._start(start)
        self._synchronize(synchronized)
        if first:
            self._online.toward_velocity(None)
            # Forces the first tick to push the effective target into ruckig.
            n = len(self._velocity)
            self._effective[:] = [math.nan] * n
            self._latch[:] = [0] * n
            self._velocity[:] = self._zeros
        self._inp.target_acceleration = self._zeros
        self.last_command = now

    def want_velocities(self, velocities: Sequence[float]) -> None:
        """The velocity stream's target from now on (checked by the caller: finite, within the limits)."""
        self._velocity[:] = velocities

    def _start(self, start: Sequence[float] | None) -> None:
        if start is not None:
            self._pos[:] = start
            self._vel[:] = self._zeros
            self._acc[:] = self._zeros
            self._online.seed()

    # ------------------------------------------------------------------ the cycle

    def tick_positions(self, command: JointCommand, now: float) -> int:
        """One cycle of a position stream: STREAM_FOLLOWED, STREAM_FAILED or STREAM_EXPIRED."""
        if now - self.last_command > self.timeout:
            return STREAM_EXPIRED
        inp = self._inp
        out = self._out
        self._brake_coasting_joints()
        try:
            result = run_robustly(self._update, inp)
            if out.new_calculation and self._near_a_limit() and self._brake_overshooting_joints(out):
                # Same start state, now with those joints braking instead of following the target.
                result = run_robustly(self._update, inp)
        except RUCKIG_ERRORS:
            result = None
        if result != WORKING and result != FINISHED:
            return STREAM_FAILED
        self._online.accept()
        write_setpoint(command, self._pos, self._vel)
        return STREAM_FOLLOWED

    def _brake_overshooting_joints(self, out: Any) -> bool:
        """Brake the joints whose freshly planned stream path leaves the limits; True if any."""
        pos = self._pos
        bad: list[int] = []
        for i, (ext_min, ext_max) in enumerate(position_extrema(out.trajectory)):
            if self._braking[i]:
                continue
            # A joint already outside a limit may only move back in.
            hi = max(self._hi[i], pos[i]) + _EXTREMA_EPS
            lo = min(self._lo[i], pos[i]) - _EXTREMA_EPS
            if ext_max > hi or ext_min < lo:
                bad.append(i)
        if bad:
            self._online.brake(bad)
            return True
        return False

    def _near_a_limit(self) -> bool:
        """Whether a joint's path from the setpoint to the target might come close to a limit."""
        pos = self._pos
        vel = self._vel
        acc = self._acc
        target = self._target
        target_vel = self._target_velocity
        safe = self._safe_distance
        for i in range(len(pos)):
            p = pos[i]
            q = target[i]
            top = p if p > q else q
            bottom = p if p < q else q
            hi = self._hi[i]
            lo = self._lo[i]
            # Coarse filter first: one worst-case stop from each end of the span.
            if top + 2.0 * safe[i] < hi and bottom - 2.0 * safe[i] > lo:
                continue
            # An excursion beyond the start-to-target span is at most the stop from the current state
            # plus the run-up to the target velocity; the margin absorbs the bound's looseness.
            amax = self._amax[i]
            jmax = self._jmax[i]
            reach = (
                1.5
                * (
                    stopping_distance(abs(vel[i]), abs(acc[i]), amax, jmax)
                    + stopping_distance(abs(target_vel[i]), 0.0, amax, jmax)
                )
                + 1e-3
            )
            if top + reach >= hi or bottom - reach <= lo:
                return True
        return False

    def _brake_coasting_joints(self) -> None:
        """Brake joints that passed their stream target and coast on toward a limit they must not pass."""
        pos = self._pos
        vel = self._vel
        target = self._target
        safe = self._safe_distance
        braking = self._braking
        bad: list[int] | None = None
        for i in range(len(pos)):
            v = vel[i]
            if v == 0.0 or braking[i]:
                continue
            p = pos[i]
            if v > 0.0:
                if p < target[i] or self._hi[i] - p > safe[i]:
                    continue
                direction = BRAKE_UP
            else:
                if p > target[i] or p - self._lo[i] > safe[i]:
                    continue
                direction = BRAKE_DOWN
            mask = braking_needed(
                p, v, self._acc[i], self._lo[i], self._hi[i], self._amax[i], self._jmax[i], self._period
            )
            if mask & direction:
                if bad is None:
                    bad = []
                bad.append(i)
        if bad is not None:
            self._online.brake(bad)

    def tick_velocities(self, command: JointCommand, now: float) -> int:
        """One cycle of a velocity stream: STREAM_FOLLOWED, STREAM_FAILED or STREAM_EXPIRED."""
        if now - self.last_command > self.timeout:
            return STREAM_EXPIRED
        want = self._velocity
        eff = self._effective
        latch = self._latch
        pos = self._pos
        vel = self._vel
        safe = self._safe_distance
        lo = self._lo
        hi = self._hi
        vmax = self._vmax
        changed = False
        for i in range(len(want)):
            w = want[i]
            if w > 0.0:
                if latch[i] != 1:
                    latch[i] = 0
                    if (hi[i] - pos[i] <= safe[i] or abs(vel[i]) > vmax[i]) and self._must_brake(i, BRAKE_UP):
                        # Latched until the client stops asking to go up, so it does not creep on.
                        latch[i] = 1
                if latch[i] == 1:
                    w = 0.0
            elif w < 0.0:
                if latch[i] != -1:
                    latch[i] = 0
                    if (pos[i] - lo[i] <= safe[i] or abs(vel[i]) > vmax[i]) and self._must_brake(
                        i, BRAKE_DOWN
                    ):
                        latch[i] = -1
                if latch[i] == -1:
                    w = 0.0
            else:
                latch[i] = 0
            if w != eff[i]:
                eff[i] = w
                changed = True
        if self._synchronized:
            changed = self._brake_together(changed)
        if changed:
            self._inp.target_velocity = eff
        if self._online.step() is None:
            return STREAM_FAILED
        write_setpoint(command, pos, vel)
        return STREAM_FOLLOWED

    def _brake_together(self, changed: bool) -> bool:
        """A synchronized stream (a twist) brakes every joint while one brakes for a limit, so the TCP
        stops on its way instead of wandering off it; each joint then stops as fast as it can (not
        synchronized: stretched to the others' time, the braking joint's stop would end later than the
        braking check assumes). Whether the effective target changed."""
        braking = any(self._latch)
        if braking:
            eff = self._effective
            for i in range(len(eff)):
                if eff[i] != 0.0:
                    eff[i] = 0.0
                    changed = True
        if braking == self._applied_sync:
            self._applied_sync = not braking
            self._inp.synchronization = Synchronization.No if braking else Synchronization.Time
        return changed

    def _must_brake(self, i: int, direction: int) -> bool:
        """Whether joint ``i``, near a limit or too fast, must brake now to stop before the limit in
        ``direction`` (BRAKE_UP or BRAKE_DOWN)."""
        mask = braking_needed(
            self._pos[i],
            self._vel[i],
            self._acc[i],
            self._lo[i],
            self._hi[i],
            self._amax[i],
            self._jmax[i],
            self._period,
        )
        return bool(mask & direction)
