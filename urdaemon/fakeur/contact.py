"""What the fake arm touches: walls and a hand's push, the wrench they put on the TCP, and how force
mode, freedrive and ``tool_contact`` answer it.

Pure (time passed in, no I/O), and a decider: it holds no arm and calls nothing back. A
:class:`Surroundings` is stepped once per controller cycle by ``FakeArm.step`` after the arm's own
motion, when the arm has one (``arm.surroundings``), with what it needs of the arm (the TCP pose,
whether the arm can move, force mode and freedrive on or off); it answers what it does to the arm
(:class:`Felt`: the measured wrench, a protective stop, the TCP twist to move at), which the arm does:

- a **wall** is a plane in the base frame (a point and an outward normal) with a stiffness: a TCP on
  the wrong side by ``d`` metres feels ``stiffness * d`` newtons along the normal. The fake does not
  stop the tool at the surface: like a real arm pressing into a stiff object, the force rises as the
  tool sinks in, and beyond the controller's force limit (:data:`FORCE_LIMIT_N`) the arm
  protective-stops;
- a **push** is a constant wrench at the TCP in the base frame (N, N·m), like a hand on the tool.

Their sum is the external wrench on the TCP; ``arm.tcp_force`` (``Felt.force``) is it minus the offset
that ``zero_ftsensor`` took (:meth:`Surroundings.zero`). The sign is the controller's: the force the
surroundings put on the tool (a wall below the tool pushes it up: +z).

**Force mode** (a model, after the URScript manual's description): along each compliant axis of the
task frame (type 2: the frame as given) the TCP is driven at an admittance speed
``(wrench + measured) * admittance * gain_scaling`` (``wrench`` is what the robot applies to its
surroundings, so it balances where the measured force equals the commanded one and opposes it),
capped by ``limits`` and reached through a first-order lag whose time constant shrinks as the damping
grows (damping 1: the speed follows the force error almost at once; 0: the speed lingers). The
non-compliant axes get no motion from the model: they follow the program's motion. The arm turns the
twist into joint velocities through its Jacobian. The compliant motion is added to the joints after the
program's motion: a program that drives the joints to a target at the same time (servoj, a move)
pulls the compliant axes back to it; force mode in our control script runs with the arm holding.

**Freedrive** (a model): along the free axes (base frame, or the feature frame if given) the TCP moves
at ``external wrench * FREEDRIVE_ADMITTANCE``, its joint velocities scaled down together to the joint
limits; with nothing pushing it stays still.

Against walls both admittances are integrated implicitly (:class:`_Admittance`): a cycle's speed is
solved with the walls' force where that cycle's motion leaves the tool, not where it starts, walls the
tool enters during the cycle included. Pushed or pressing into a wall of any stiffness, freedrive and
force mode come to rest where the forces balance (stepped explicitly, a loop gain
``dt * admittance * stiffness`` of 2, 5e4 N/m at CB3's 8 ms, chattered forever, and more diverged).
Walls exert no torque (the force acts at the TCP), so rotations stay explicit. What remains is the
model's own dynamics: force mode's lag carries the approach speed into a wall, so with little damping
(the default) a fast approach to a stiff wall overshoots the commanded force, at 1e6 N/m into a
protective stop; damping 1 or a lower speed limit keeps it near the commanded force.

**Tool contact** (``tool_contact``, a model: the controller's detection is not documented): a contact
starts when a wall starts pushing on the tool, or when, after a cycle with the tool feeling no more than
:data:`CONTACT_ONSET_N` beyond its zeroed level (``arm.tcp_force``) and no wall pressing harder, the
felt force rises past it or a wall presses harder. A steady force from before, zeroed or not (a payload
mismatch, a cable, a table the tool rests on), does not date a contact. A contact is detected when
the measured force opposes the given direction by more than a threshold, and the answer is the cycles
back to just before the contact started.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Final, Protocol

from urdaemon.description.frames import IDENTITY, Frame, Pose, frame_of_pose, rotate

__all__ = [
    "CONTACT_ONSET_N",
    "DEFAULT_WALL_STIFFNESS",
    "FORCE_LIMIT_N",
    "FORCE_MODE_ADMITTANCE",
    "FORCE_MODE_TORQUE_ADMITTANCE",
    "FREEDRIVE_ADMITTANCE",
    "FREEDRIVE_TORQUE_ADMITTANCE",
    "TOOL_CONTACT_THRESHOLD_N",
    "Felt",
    "ForceModeSettings",
    "Surrounded",
    "Surroundings",
    "Wall",
    "surroundings_of",
]

DEFAULT_WALL_STIFFNESS: Final = 20_000.0
"""N/m: a wall's stiffness unless given (a stiff fixture felt through the arm's own compliance). Any
stiffness is stable: force mode and freedrive are integrated implicitly against walls (see the module)."""
FORCE_LIMIT_N: Final = 150.0
"""N: the e-Series safety configuration's default force limit (normal mode); a wall pressing harder
than this protective-stops the arm."""
TOOL_CONTACT_THRESHOLD_N: Final = 5.0
"""N: the force against the direction of motion above which ``tool_contact`` reports a contact when
the program gives no threshold (a model: the controller's own detection is not documented)."""
CONTACT_ONSET_N: Final = 0.5
"""N: the force beyond the zeroed level at which a contact without a wall starts, for ``tool_contact``'s
count (a model)."""
FORCE_MODE_ADMITTANCE: Final = 0.005
"""m/s per N: force mode's TCP speed along a compliant axis per newton of force error (gain scaling 1)."""
FORCE_MODE_TORQUE_ADMITTANCE: Final = 0.05
"""rad/s per N·m: the same for a compliant rotation."""
FORCE_MODE_LAG_S: Final = 0.05
"""s: the time constant of force mode's speed response with no damping; damping 1 leaves
:data:`FORCE_MODE_MIN_LAG_S`."""
FORCE_MODE_MIN_LAG_S: Final = 0.002
FREEDRIVE_ADMITTANCE: Final = 0.005
"""m/s per N: freedrive's TCP speed per newton pushing along a free axis."""
FREEDRIVE_TORQUE_ADMITTANCE: Final = 0.05
"""rad/s per N·m: freedrive's TCP rotation speed per newton metre about a free axis."""

_ZERO6: Final = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
_ONSET_SQUARED: Final = CONTACT_ONSET_N * CONTACT_ONSET_N


@dataclass(frozen=True, slots=True)
class Wall:
    """A plane the TCP cannot pass freely: ``point`` on it, ``normal`` pointing to the free side."""

    point: tuple[float, float, float]
    normal: tuple[float, float, float]
    stiffness: float = DEFAULT_WALL_STIFFNESS

    @classmethod
    def of(
        cls, point: Sequence[float], normal: Sequence[float], stiffness: float = DEFAULT_WALL_STIFFNESS
    ) -> Wall:
        """A wall; ValueError for a zero normal or a stiffness that is not positive."""
        length = math.sqrt(sum(float(v) * float(v) for v in normal))
        if len(point) != 3 or len(normal) != 3 or not length > 1e-12:
            raise ValueError(f"a wall needs a point and a non-zero normal, 3 numbers each: {point} {normal}")
        if not stiffness > 0 or not math.isfinite(stiffness):
            raise ValueError(f"a wall's stiffness must be a positive number of N/m, got {stiffness}")
        n = (float(normal[0]) / length, float(normal[1]) / length, float(normal[2]) / length)
        return cls((float(point[0]), float(point[1]), float(point[2])), n, float(stiffness))

    def depth(self, position: Sequence[float]) -> float:
        """m: how far ``position`` is on the wrong side (0 on the free side)."""
        d = self.signed_depth(position)
        return d if d > 0.0 else 0.0

    def signed_depth(self, position: Sequence[float]) -> float:
        """m: how far ``position`` is on the wrong side, negative on the free side (minus the clearance)."""
        p, n = self.point, self.normal
        return (p[0] - position[0]) * n[0] + (p[1] - position[1]) * n[1] + (p[2] - position[2]) * n[2]


@dataclass(slots=True)
class ForceModeSettings:
    """``force_mode``'s parameters and the damping and gain scaling in force when it started."""

    frame: Sequence[float]
    selection: Sequence[int]
    wrench: Sequence[float]
    limits: Sequence[float]
    damping: float
    gain_scaling: float


@dataclass(frozen=True, slots=True)
class Felt:
    """What one cycle of the surroundings does to the arm (``Surroundings.step``)."""

    force: list[float]
    """N, N·m in the base frame: the wrench the arm measures at the TCP (``arm.tcp_force``)."""
    stop: bool
    """A wall pushes back harder than :data:`FORCE_LIMIT_N`: the arm protective-stops."""
    twist: list[float] | None
    """m/s, rad/s in the base frame: the TCP twist force mode or freedrive moves the arm at this cycle,
    on top of its own motion (None: no such motion)."""


@dataclass(slots=True)
class Surroundings:
    """The walls and the push around one arm, and what they do to it (see the module)."""

    walls: list[Wall] = field(default_factory=list)
    push: list[float] = field(default_factory=lambda: [0.0] * 6)
    """N, N·m in the base frame: a constant wrench on the TCP."""
    force: ForceModeSettings | None = None
    """Force mode's parameters (set by ``force_mode``; they matter while ``arm.force_mode``)."""
    free_axes: Sequence[int] = (1, 1, 1, 1, 1, 1)
    free_frame: Frame = IDENTITY
    """The frame freedrive's free axes are in (the base unless a feature was given)."""
    offset: list[float] = field(default_factory=lambda: [0.0] * 6)
    """The external wrench ``zero_ftsensor`` took as zero."""
    wrench: tuple[float, ...] = _ZERO6
    """N, N·m: the external wrench on the TCP at the last step (before the offset)."""
    cycle: int = 0
    touched_at: int | None = None
    """The cycle at which the current contact started (None while there is none; see the module)."""
    _walled: float = 0.0
    """N: the sum of the walls' forces at the last step."""
    _quiet: bool = False
    """The last step had nothing around the arm and no mode on: its outputs stand until that changes."""
    _twist: list[float] = field(default_factory=lambda: [0.0] * 6)
    """Force mode's TCP twist in the task frame (the lag's state)."""

    def step(
        self, dt: float, pose: Pose | None, *, can_move: bool, force_mode: bool, freedrive: bool
    ) -> Felt | None:
        """One controller cycle, after the arm's own motion: the wrench the arm measures, the safety
        limit, force mode or freedrive motion. ``pose``: the arm's TCP pose (needed only while there
        are walls); ``can_move``: the arm's life lets it move. With nothing around the arm, no mode on
        and nothing changed since the last step, it only counts the cycle (None: nothing changes)."""
        self.cycle += 1
        walls, push = self.walls, self.push
        if self._quiet and not walls and not force_mode and not freedrive and not any(push):
            return None
        fx, fy, fz = push[0], push[1], push[2]
        pressing = walled = 0.0
        depths: list[float] = []
        if walls:
            assert pose is not None, "walls need the TCP pose"
            for wall in walls:
                depth = wall.signed_depth(pose)
                depths.append(depth)
                if depth > 0.0:
                    f = wall.stiffness * depth
                    pressing = max(pressing, f)
                    walled += f
                    fx, fy, fz = fx + f * wall.normal[0], fy + f * wall.normal[1], fz + f * wall.normal[2]
        wrench = self.wrench = (fx, fy, fz, push[3], push[4], push[5])
        offset = self.offset
        felt = [wrench[i] - offset[i] for i in range(6)]
        self._track_contact(felt, walled)
        self._quiet = not walls and not force_mode and not freedrive and not any(push)
        stop = pressing > FORCE_LIMIT_N and can_move
        moving = can_move and not stop  # a protective stop ends what the arm may do this cycle
        twist = None
        if moving and force_mode and self.force is not None:
            twist = self._force_twist(felt, depths, dt)
        elif moving and freedrive:
            twist = self._free_twist(felt, depths, dt)
        elif any(self._twist):
            self._twist[:] = _ZERO6
        if twist is not None and max(abs(v) for v in twist) < _STILL:
            twist = None  # the round-off of balanced forces: no motion
        return Felt(felt, stop, twist)

    def _track_contact(self, felt: Sequence[float], walled: float) -> None:
        """Where ``tool_contact`` counts from (``walled``: the walls' force now): a wall starting to push,
        or, after a cycle where the tool felt no more than :data:`CONTACT_ONSET_N` beyond its zeroed
        level and no wall pressed harder, the felt force rising past it or a wall pressing harder. A
        steady force from before, zeroed or not, does not date a contact."""
        if walled > 0.0 and not self._walled > 0.0:
            self.touched_at = self.cycle
        elif walled > self._walled or felt[0] ** 2 + felt[1] ** 2 + felt[2] ** 2 > _ONSET_SQUARED:
            if self.touched_at is None:
                self.touched_at = self.cycle
        else:
            self.touched_at = None
        self._walled = walled

    def zero(self) -> None:
        """``zero_ftsensor``: the wrench now reads as zero from here on."""
        self.offset = list(self.wrench)
        self._quiet = False

    def contact_steps(
        self, force: Sequence[float], direction: Sequence[float], threshold: float, history: int
    ) -> int:
        """``tool_contact``: cycles back to just before the contact started (at most ``history``), or 0.

        ``force`` is the measured TCP force; a contact is a force opposing ``direction`` (its first three
        elements, base frame; any direction if they are zero) by more than ``threshold`` N
        (:data:`TOOL_CONTACT_THRESHOLD_N` if it is not positive)."""
        touched = self.touched_at
        if touched is None:
            return 0
        limit = threshold if threshold > 0.0 else TOOL_CONTACT_THRESHOLD_N
        dx, dy, dz = direction[0], direction[1], direction[2]
        length = math.sqrt(dx * dx + dy * dy + dz * dz)
        if length < 1e-9:
            against = math.sqrt(force[0] ** 2 + force[1] ** 2 + force[2] ** 2)
        else:
            against = -(force[0] * dx + force[1] * dy + force[2] * dz) / length
        if against <= limit:
            return 0
        return min(self.cycle - touched + 1, history)

    @property
    def idle(self) -> bool:
        """True when stepping would change nothing (no wall, no push, no offset, nothing felt)."""
        return not self.walls and not any(self.push) and not any(self.offset) and not any(self.wrench)

    # ---- motion ----------------------------------------------------------------------------------

    def _force_twist(self, measured: Sequence[float], depths: Sequence[float], dt: float) -> list[float]:
        settings = self.force
        assert settings is not None
        frame = frame_of_pose(settings.frame)
        t = _unrotate(frame, measured[3], measured[4], measured[5])
        lag = FORCE_MODE_MIN_LAG_S + (1.0 - settings.damping) * (FORCE_MODE_LAG_S - FORCE_MODE_MIN_LAG_S)
        keep = math.exp(-dt / lag)
        twist, selection, wrench, limits = self._twist, settings.selection, settings.wrench, settings.limits
        law = _Admittance(selection, FORCE_MODE_ADMITTANCE * settings.gain_scaling, keep, dt)
        law.bounds = [abs(limits[i]) for i in range(3)]
        law.previous = twist[:3]
        twist[:3] = self._wall_speed(law, frame, measured, depths, wrench)
        gain = FORCE_MODE_TORQUE_ADMITTANCE * settings.gain_scaling
        for i in range(3, 6):
            if not selection[i]:
                twist[i] = 0.0
                continue
            limit = abs(limits[i])
            wanted = max(-limit, min(limit, (wrench[i] + t[i - 3]) * gain))
            twist[i] = wanted + (twist[i] - wanted) * keep
        return [*rotate(frame, twist[:3]), *rotate(frame, twist[3:])]

    def _free_twist(self, measured: Sequence[float], depths: Sequence[float], dt: float) -> list[float]:
        frame, axes = self.free_frame, self.free_axes
        t = _unrotate(frame, measured[3], measured[4], measured[5])
        law = _Admittance(axes, FREEDRIVE_ADMITTANCE, 0.0, dt)
        local = self._wall_speed(law, frame, measured, depths, _ZERO6)
        turn = [t[i] * FREEDRIVE_TORQUE_ADMITTANCE if axes[i + 3] else 0.0 for i in range(3)]
        return [*rotate(frame, local), *rotate(frame, turn)]

    def _wall_speed(
        self,
        law: _Admittance,
        frame: Frame,
        measured: Sequence[float],
        depths: Sequence[float],
        commanded: Sequence[float],
    ) -> list[float]:
        """m/s in ``frame``: the admittance's TCP speed, solved against every wall where the cycle's motion
        leaves the tool (``depths``: each wall's signed depth now). A wall counts when the tool ends the
        cycle inside it, whether it is inside now or enters during the cycle; the set is found by trying
        the walls the tool is in now, then those the resulting motion ends in, until it holds."""
        felt = _unrotate(frame, measured[0], measured[1], measured[2])
        target = [commanded[i] + felt[i] for i in range(3)]
        if not depths:
            return law.solve(target, None)
        walls = []
        for wall, depth in zip(self.walls, depths, strict=True):
            n, k = _unrotate(frame, *wall.normal), wall.stiffness
            walls.append((n, k, depth))
            if depth > 0.0:  # out of the target: added back below while the tool ends the cycle inside
                target = [target[i] - k * depth * n[i] for i in range(3)]
        inside = [w for w in walls if w[2] > 0.0]
        speed = law.solve(target, None) if not inside else []
        for _ in range(len(walls) + 1):
            if inside:
                pushed, stiffness = list(target), [[0.0] * 3 for _ in range(3)]
                for n, k, depth in inside:
                    for r in range(3):
                        pushed[r] += k * depth * n[r]
                        row = stiffness[r]
                        for c in range(3):
                            row[c] += k * n[r] * n[c]
                speed = law.solve(pushed, stiffness)
            ends = [w for w in walls if w[2] - law.dt * _dot(w[0], speed) > 0.0]
            if ends == inside:
                break
            inside = ends
            if not inside:
                speed = law.solve(target, None)
        return speed


_UNBOUNDED: Final = (math.inf, math.inf, math.inf)
_STILL: Final = 1e-9
"""m/s, rad/s: a compliant twist this small is the round-off of balanced forces, not motion."""


class _Admittance:
    """One cycle of a translational admittance with a first-order lag, solved implicitly against walls.

    Along each ``active`` axis of a frame the speed ``u`` (m/s) solves ``u = keep·previous + (1 −
    keep)·clamp(gain·(target − dt·K·u))``, ``K`` the stiffness matrix of the walls the tool ends the cycle
    in: their force is taken where the cycle's motion leaves the tool, not where it starts, so the
    admittance cannot overshoot a wall however stiff (implicit Euler: stable for any ``gain·K·dt``,
    where the explicit step chatters from 2). ``clamp`` keeps ``gain·(…)`` within ``±bounds``; an axis
    whose bound binds is fixed there and the others are solved again. Inactive axes do not move."""

    __slots__ = ("active", "bounds", "dt", "gain", "keep", "previous")

    def __init__(self, active: Sequence[int], gain: float, keep: float, dt: float) -> None:
        self.active, self.gain, self.keep, self.dt = active, gain, keep, dt
        self.bounds: Sequence[float] = _UNBOUNDED
        self.previous: Sequence[float] = _ZERO6

    def solve(self, target: Sequence[float], stiffness: list[list[float]] | None) -> list[float]:
        """m/s: the speeds for ``target`` (N, in the frame) against ``stiffness`` (N/m; None: no wall)."""
        gain, keep, bounds, previous = self.gain, self.keep, self.bounds, self.previous
        speed = [0.0, 0.0, 0.0]
        free = [i for i in range(3) if self.active[i]]
        if stiffness is None:
            for i in free:
                wanted = max(-bounds[i], min(bounds[i], gain * target[i]))
                speed[i] = wanted + (previous[i] - wanted) * keep
            return speed
        k, blend = stiffness, 1.0 - keep
        step = blend * gain * self.dt
        start = [keep * previous[i] + blend * gain * target[i] for i in range(3)]
        while free:
            for i in free:
                speed[i] = 0.0
            matrix = [[step * k[r][c] + (1.0 if r == c else 0.0) for c in free] for r in free]
            rhs = [start[r] - step * _dot(k[r], speed) for r in free]
            for i, value in zip(free, _solve(matrix, rhs), strict=True):
                speed[i] = value
            bound = []
            for i in free:
                asked = gain * (target[i] - self.dt * _dot(k[i], speed))
                if abs(asked) > bounds[i]:
                    speed[i] = keep * previous[i] + blend * math.copysign(bounds[i], asked)
                    bound.append(i)
            if not bound:
                break
            free = [i for i in free if i not in bound]
        return speed


def _dot(a: Sequence[float], b: Sequence[float]) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _solve(m: list[list[float]], b: list[float]) -> list[float]:
    """``x`` with ``m·x = b`` for a 1×1 to 3×3 ``m`` (Cramer's rule; ``m`` is here always symmetric
    positive definite: the identity plus a positive multiple of a stiffness matrix)."""
    if len(b) == 1:
        return [b[0] / m[0][0]]
    if len(b) == 2:
        det = m[0][0] * m[1][1] - m[0][1] * m[1][0]
        return [(b[0] * m[1][1] - m[0][1] * b[1]) / det, (m[0][0] * b[1] - b[0] * m[1][0]) / det]
    (a, b_, c), (d, e, f), (g, h, i) = m
    co = (e * i - f * h, f * g - d * i, d * h - e * g)
    det = a * co[0] + b_ * co[1] + c * co[2]
    x, y, z = b
    return [
        (x * co[0] + b_ * (z * f - y * i) + c * (y * h - z * e)) / det,
        (a * (y * i - z * f) + x * co[1] + c * (z * d - y * g)) / det,
        (a * (e * z - h * y) + b_ * (g * y - d * z) + x * co[2]) / det,
    ]


def _unrotate(frame: Frame, x: float, y: float, z: float) -> tuple[float, float, float]:
    """A base-frame vector in ``frame``'s axes."""
    return (
        frame[0] * x + frame[3] * y + frame[6] * z,
        frame[1] * x + frame[4] * y + frame[7] * z,
        frame[2] * x + frame[5] * y + frame[8] * z,
    )


class Surrounded(Protocol):
    """An arm that may have surroundings (``FakeArm``)."""

    surroundings: Surroundings | None


def surroundings_of(arm: Surrounded) -> Surroundings:
    """The arm's surroundings, made (empty) on first use."""
    model = arm.surroundings
    if model is None:
        model = arm.surroundings = Surroundings()
    return model
