"""What the fake arm touches: walls and a hand's push, the wrench they put on the TCP, and how force
mode, freedrive and ``tool_contact`` answer it.

Pure (time passed in, no I/O). A :class:`Surroundings` is stepped once per controller cycle by
``FakeArm.step`` after the arm's own motion, when the arm has one (``arm.surroundings``):

- a **wall** is a plane in the base frame (a point and an outward normal) with a stiffness: a TCP on
  the wrong side by ``d`` metres feels ``stiffness * d`` newtons along the normal. The fake does not
  stop the tool at the surface: like a real arm pressing into a stiff object, the force rises as the
  tool sinks in, and beyond the controller's force limit (:data:`FORCE_LIMIT_N`) the arm
  protective-stops;
- a **push** is a constant wrench at the TCP in the base frame (N, N·m), like a hand on the tool.

Their sum is the external wrench on the TCP; ``arm.tcp_force`` is it minus the offset that
``zero_ftsensor`` took (:meth:`Surroundings.zero`). The sign is the controller's: the force the
surroundings put on the tool (a wall below the tool pushes it up: +z).

**Force mode** (a model, after the URScript manual's description): along each compliant axis of the
task frame (type 2: the frame as given) the TCP is driven at an admittance speed
``(wrench + measured) * admittance * gain_scaling`` (``wrench`` is what the robot applies to its
surroundings, so it balances where the measured force equals the commanded one and opposes it),
capped by ``limits`` and reached through a first-order lag whose time constant shrinks as the damping
grows (damping 1: the speed follows the force error almost at once; 0: the speed lingers). The
non-compliant axes get no motion from the model: they follow the program's motion. The twist goes
to joint velocities through the arm's Jacobian. The compliant motion is added to the joints after the
program's motion: a program that drives the joints to a target at the same time (servoj, a move)
pulls the compliant axes back to it; force mode in our control script runs with the arm holding.

**Freedrive** (a model): along the free axes (base frame, or the feature frame if given) the TCP moves
at ``external wrench * FREEDRIVE_ADMITTANCE``, its joint velocities scaled down together to the joint
limits; with nothing pushing it stays still.

**Tool contact** (``tool_contact``): the model counts the cycles since the external force last rose
from zero; a contact is detected when the measured force opposes the given direction by more than a
threshold, and the answer is the cycles back to just before the force rose.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Final

from urdaemon.description.frames import IDENTITY, Frame, frame_of_pose, rotate

if TYPE_CHECKING:
    from urdaemon.fakeur.arm import FakeArm

__all__ = [
    "DEFAULT_WALL_STIFFNESS",
    "FORCE_LIMIT_N",
    "FORCE_MODE_ADMITTANCE",
    "FORCE_MODE_TORQUE_ADMITTANCE",
    "FREEDRIVE_ADMITTANCE",
    "FREEDRIVE_TORQUE_ADMITTANCE",
    "TOOL_CONTACT_THRESHOLD_N",
    "ForceModeSettings",
    "Surroundings",
    "Wall",
    "surroundings_of",
]

DEFAULT_WALL_STIFFNESS: Final = 20_000.0
"""N/m: a wall's stiffness unless given (a stiff fixture felt through the arm's own compliance). The
admittances below stay stable against walls up to about 1e5 N/m at 2 ms and 5e4 N/m at 8 ms cycles."""
FORCE_LIMIT_N: Final = 150.0
"""N: the e-Series safety configuration's default force limit (normal mode); a wall pressing harder
than this protective-stops the arm."""
TOOL_CONTACT_THRESHOLD_N: Final = 5.0
"""N: the force against the direction of motion above which ``tool_contact`` reports a contact when
the program gives no threshold (a model: the controller's own detection is not documented)."""
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
        p, n = self.point, self.normal
        d = (p[0] - position[0]) * n[0] + (p[1] - position[1]) * n[1] + (p[2] - position[2]) * n[2]
        return d if d > 0.0 else 0.0


@dataclass(slots=True)
class ForceModeSettings:
    """``force_mode``'s parameters and the damping and gain scaling in force when it started."""

    frame: Sequence[float]
    selection: Sequence[int]
    wrench: Sequence[float]
    limits: Sequence[float]
    damping: float
    gain_scaling: float


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
    """The cycle at which the external force last rose from zero (None while there is none)."""
    _twist: list[float] = field(default_factory=lambda: [0.0] * 6)
    """Force mode's TCP twist in the task frame (the lag's state)."""

    def step(self, arm: FakeArm, dt: float) -> None:
        """One controller cycle, after the arm's own motion: the wrench, the safety limit, force mode or
        freedrive motion, and ``arm.tcp_force``."""
        self.cycle += 1
        walls, push = self.walls, self.push
        fx, fy, fz = push[0], push[1], push[2]
        pressing = 0.0
        if walls:
            pose = arm.actual_tcp_pose()
            for wall in walls:
                depth = wall.depth(pose)
                if depth > 0.0:
                    f = wall.stiffness * depth
                    pressing = max(pressing, f)
                    fx, fy, fz = fx + f * wall.normal[0], fy + f * wall.normal[1], fz + f * wall.normal[2]
        wrench = (fx, fy, fz, push[3], push[4], push[5])
        if fx or fy or fz:
            if self.touched_at is None:
                self.touched_at = self.cycle
        else:
            self.touched_at = None
        self.wrench = wrench
        offset = self.offset
        arm.tcp_force = [wrench[i] - offset[i] for i in range(6)]
        if pressing > FORCE_LIMIT_N and arm.can_move:
            arm.protective_stop()
        if not arm.can_move:
            self._twist = [0.0] * 6
            return
        measured = arm.tcp_force
        if arm.force_mode and self.force is not None:
            self._move(arm, self._force_twist(measured, dt), dt)
        elif arm.freedrive:
            self._move(arm, self._free_twist(measured), dt)
        else:
            self._twist = [0.0] * 6

    def zero(self) -> None:
        """``zero_ftsensor``: the wrench now reads as zero from here on."""
        self.offset = list(self.wrench)

    def contact_steps(
        self, force: Sequence[float], direction: Sequence[float], threshold: float, history: int
    ) -> int:
        """``tool_contact``: cycles back to just before the force rose (at most ``history``), or 0.

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

    def _force_twist(self, measured: Sequence[float], dt: float) -> list[float]:
        settings = self.force
        assert settings is not None
        frame = frame_of_pose(settings.frame)
        f = _unrotate(frame, measured[0], measured[1], measured[2])
        t = _unrotate(frame, measured[3], measured[4], measured[5])
        felt = (*f, *t)
        lag = FORCE_MODE_MIN_LAG_S + (1.0 - settings.damping) * (FORCE_MODE_LAG_S - FORCE_MODE_MIN_LAG_S)
        keep = math.exp(-dt / lag)
        twist = self._twist
        for i in range(6):
            if not settings.selection[i]:
                twist[i] = 0.0
                continue
            admittance = FORCE_MODE_ADMITTANCE if i < 3 else FORCE_MODE_TORQUE_ADMITTANCE
            limit = abs(settings.limits[i])
            wanted = (settings.wrench[i] + felt[i]) * admittance * settings.gain_scaling
            wanted = max(-limit, min(limit, wanted))
            twist[i] = wanted + (twist[i] - wanted) * keep
        return [*rotate(frame, twist[:3]), *rotate(frame, twist[3:])]

    def _free_twist(self, measured: Sequence[float]) -> list[float]:
        frame, axes = self.free_frame, self.free_axes
        f = _unrotate(frame, measured[0], measured[1], measured[2])
        t = _unrotate(frame, measured[3], measured[4], measured[5])
        local = [f[i] * FREEDRIVE_ADMITTANCE if axes[i] else 0.0 for i in range(3)] + [
            t[i] * FREEDRIVE_TORQUE_ADMITTANCE if axes[i + 3] else 0.0 for i in range(3)
        ]
        return [*rotate(frame, local[:3]), *rotate(frame, local[3:])]

    @staticmethod
    def _move(arm: FakeArm, twist: Sequence[float], dt: float) -> None:
        """Drive the joints at the velocities that give the TCP ``twist``, scaled into the joint limits."""
        if not any(twist):
            return
        qd = arm.ik.joint_velocity(arm.q, twist, arm.tcp_offset)
        vmax = arm.max_velocity
        scale = 1.0
        for i in range(6):
            if abs(qd[i]) * scale > vmax[i]:
                scale = vmax[i] / abs(qd[i])
        q, actual = arm.q, arm.qd
        for i in range(6):
            v = qd[i] * scale
            q[i] += v * dt
            actual[i] += v


def _unrotate(frame: Frame, x: float, y: float, z: float) -> tuple[float, float, float]:
    """A base-frame vector in ``frame``'s axes."""
    return (
        frame[0] * x + frame[3] * y + frame[6] * z,
        frame[1] * x + frame[4] * y + frame[7] * z,
        frame[2] * x + frame[5] * y + frame[8] * z,
    )


def surroundings_of(arm: FakeArm) -> Surroundings:
    """The arm's surroundings, made (empty) on first use."""
    model = arm.surroundings
    if model is None:
        model = arm.surroundings = Surroundings()
    return model
