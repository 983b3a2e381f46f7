"""Twist streams: a TCP velocity a client sends, followed smoothly in Cartesian space and in the joints.

Owns the arm's kinematics and TCP offset as the controller knows them, the newest twist target and
its frame, and the Cartesian smoothing. A twist message sets the target (base frame; a ``tool`` twist
is re-expressed in base every cycle from the setpoint's forward kinematics, so it turns with the
tool); near a singularity the target shrinks with the Jacobian's smallest singular value
(``SLOW_BELOW``). Every cycle the commanded twist follows the target through ruckig's velocity
interface within the Cartesian acceleration and jerk (each axis of a triple at limit/√3, so the
vector's norm stays within the limit in any direction); the joint velocities for it come from damped
least squares on the Jacobian at the setpoint (description/dls.py), scaled down uniformly so no joint
exceeds its speed limit, and then go through the joint velocity stream (control/streams.py): its
joints reach their targets together (keeping the twist's direction), all brake when one must brake
for a position limit, and their acceleration and jerk stay within the limits. The deadman is the
joint stream's: its clock is the twist message's arrival.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from typing import Any

from ruckig import ControlInterface, InputParameter, OutputParameter, Ruckig

from urdaemon.control.cartesian import CartesianLimits
from urdaemon.control.online import FINISHED, WORKING
from urdaemon.control.ruckig_calls import RUCKIG_ERRORS, run_robustly
from urdaemon.control.setpoint import Setpoint
from urdaemon.control.streams import STREAM_EXPIRED, STREAM_FAILED, StreamFollower
from urdaemon.description.arm import ArmKinematics
from urdaemon.description.dls import damped_velocity, singularity
from urdaemon.description.frames import frame_of_pose, rotate
from urdaemon.errors import GoalRejected
from urdaemon.model import JointCommand, JointLimits

__all__ = [
    "FRAMES",
    "TwistFollower",
    "check_twist",
    "reach_of",
    "singular_share",
    "uniform_scale",
]

FRAMES = ("base", "tool")
"""The frames a twist may be given in."""
_AXIS_SHARE = 1.0 / math.sqrt(3.0)
"""Each Cartesian axis gets this share of a limit, so a vector of three within it stays within it."""
_CAP_SLACK = 1.0 + 1e-9
SLOW_BELOW = 0.12
"""Per metre of the arm's reach: below this smallest singular value of the Jacobian a twist slows down
in proportion to it. Near a singularity the joints that realise even a slow twist turn fast, faster
than a jerk-limited joint follows, and what the arm can still do there (sliding along its reach,
turning the tool instead) is not what the client asked for. The Jacobian's linear rows are in metres,
so its singular values grow with the arm: 0.12 per metre slows a UR10e (1.3 m) below 0.16, a UR3e
(0.5 m) below 0.06, both well under their values in ordinary poses (0.3 and 0.12 at home)."""
SLOWEST = 0.1
"""The share of the twist kept at the singularity itself, so the arm can still be jogged away from it."""


def check_twist(twist: Sequence[float], frame: str, caps: CartesianLimits) -> tuple[float, ...]:
    """The twist (vx, vy, vz, wx, wy, wz) as floats; GoalRejected naming what is wrong: its length, a
    value not finite, a speed above the cap, an unknown frame."""
    if frame not in FRAMES:
        raise GoalRejected(f"twist: frame {frame!r} is not one of {', '.join(FRAMES)}")
    if len(twist) != 6:
        raise GoalRejected(f"twist: {len(twist)} values; a twist is vx, vy, vz, wx, wy, wz")
    values = tuple(float(v) for v in twist)
    for label, v in zip(("vx", "vy", "vz", "wx", "wy", "wz"), values, strict=True):
        if not math.isfinite(v):
            raise GoalRejected(f"twist: {label} is {v}, not a finite number")
    speed = math.sqrt(values[0] ** 2 + values[1] ** 2 + values[2] ** 2)
    if speed > caps.speed * _CAP_SLACK:
        raise GoalRejected(f"twist: linear speed {speed:.6g} m/s exceeds the cap {caps.speed:.6g} m/s")
    turn = math.sqrt(values[3] ** 2 + values[4] ** 2 + values[5] ** 2)
    if turn > caps.angular_speed * _CAP_SLACK:
        raise GoalRejected(
            f"twist: angular speed {turn:.6g} rad/s exceeds the cap {caps.angular_speed:.6g} rad/s"
        )
    return values


def singular_share(sigma: float, slow_below: float) -> float:
    """The share of a twist kept where the Jacobian's smallest singular value is ``sigma``: 1 from
    ``slow_below`` up, ``sigma / slow_below`` below it, at least ``SLOWEST``. Continuous in the pose."""
    if sigma >= slow_below:
        return 1.0
    return max(sigma / slow_below, SLOWEST)


def reach_of(kin: ArmKinematics) -> float:
    """The arm's reach (m), estimated as the TCP's largest distance from a joint axis with all joints at
    zero (a UR is stretched out there); at least 0.1 m."""
    rows = kin.jacobian_rows([0.0] * kin.dof)
    return max(0.1, *(math.sqrt(rows[0][j] ** 2 + rows[1][j] ** 2 + rows[2][j] ** 2) for j in range(kin.dof)))


def uniform_scale(qd: list[float], vmax: Sequence[float]) -> float:
    """Scale ``qd`` in place so no joint exceeds its ``vmax``; the factor applied (<= 1)."""
    worst = 1.0
    for i in range(len(qd)):
        r = abs(qd[i]) / vmax[i]
        if r > worst:
            worst = r
    if worst > 1.0:
        k = 1.0 / worst
        for i in range(len(qd)):
            qd[i] *= k
        return k
    return 1.0


class TwistFollower:
    """Follows one twist stream: Cartesian smoothing, damped least squares, the joint velocity stream."""

    __slots__ = (
        "_caps",
        "_cart_inp",
        "_cart_out",
        "_cart_update",
        "_kin",
        "_pos",
        "_slow_below",
        "_streams",
        "_target",
        "_target_base",
        "_tool",
        "_vel",
        "_vmax",
        "scale",
        "sigma",
        "tcp",
    )

    def __init__(
        self, limits: JointLimits, period: float, streams: StreamFollower, setpoint: Setpoint
    ) -> None:
        self._streams = streams
        self._pos = setpoint.pos
        self._vel = setpoint.vel
        self._vmax = list(limits.max_velocity)
        self._kin: ArmKinematics | None = None
        self._caps: CartesianLimits | None = None
        self._slow_below = 0.0
        self.tcp: tuple[float, ...] = (0.0,) * 6
        """The TCP offset (flange -> TCP pose, metres and rotation vector) every Cartesian command uses."""
        otg: Any = Ruckig(6, period)
        self._cart_inp: Any = InputParameter(6)
        self._cart_out: Any = OutputParameter(6)
        self._cart_update = functools.partial(otg.update, self._cart_inp, self._cart_out)
        self._cart_inp.control_interface = ControlInterface.Velocity
        self._target = [0.0] * 6
        """The twist the client asked for, in its frame."""
        self._target_base = [0.0] * 6
        """The target in the base frame, as last given to the smoothing."""
        self._tool = False
        self.sigma = math.inf
        """The Jacobian's smallest singular value at the last cycle (how near a singularity)."""
        self.scale = 1.0
        """The last cycle's uniform slow-down for the joint speed limits (1: none)."""

    def release(self) -> None:
        """Let go of the Cartesian smoothing's ruckig objects (the daemon stopped); unusable afterwards."""
        del self._cart_update, self._cart_inp, self._cart_out

    def set_arm(self, kin: ArmKinematics | None, limits: CartesianLimits) -> None:
        """The arm's kinematics (None: no twists) and the twist limits: speed caps, smoothing limits."""
        self._kin = kin
        self._caps = limits
        self._slow_below = 0.0 if kin is None else SLOW_BELOW * reach_of(kin)
        inp = self._cart_inp
        inp.max_velocity = [limits.speed] * 3 + [limits.angular_speed] * 3
        inp.max_acceleration = [limits.acceleration * _AXIS_SHARE] * 3 + [
            limits.angular_acceleration * _AXIS_SHARE
        ] * 3
        inp.max_jerk = [limits.jerk * _AXIS_SHARE] * 3 + [limits.angular_jerk * _AXIS_SHARE] * 3

    def set_tcp(self, tcp: Sequence[float]) -> None:
        """Make ``tcp`` (6 finite values) the TCP offset; GoalRejected otherwise."""
        if len(tcp) != 6 or not all(math.isfinite(v) for v in tcp):
            raise GoalRejected(f"set_tcp: the pose must be 6 finite numbers, got {list(tcp)}")
        self.tcp = tuple(float(v) for v in tcp)

    def follow(
        self, twist: Sequence[float], frame: str, start: Sequence[float] | None, first: bool, now: float
    ) -> None:
        """Make ``twist`` in ``frame`` the target (GoalRejected if not allowed); ``start``: the measured
        pose to start at from rest, None to continue from the setpoint; ``first``: no twist ran before."""
        if self._kin is None or self._caps is None:
            raise GoalRejected("twist: this robot has no arm kinematics for Cartesian commands")
        values = check_twist(twist, frame, self._caps)
        self._streams.follow_computed(start, first, now, synchronized=True)
        if first:
            self._seed_smoothing()
        self._target[:] = values
        self._tool = frame == "tool"

    def _seed_smoothing(self) -> None:
        """Start the Cartesian smoothing at the TCP twist the setpoint moves with (zero at rest)."""
        assert self._kin is not None
        rows = self._kin.jacobian_rows(self._pos, self.tcp)
        vel = self._vel
        twist = [sum(r[j] * vel[j] for j in range(len(vel))) for r in rows]
        self.sigma = singularity(rows)
        inp = self._cart_inp
        inp.current_position = [0.0] * 6
        inp.current_velocity = twist
        inp.current_acceleration = [0.0] * 6
        self._target_base[:] = [math.nan] * 6  # the first tick hands the target over

    def tick(self, command: JointCommand, now: float) -> int:
        """One cycle of the twist stream: STREAM_FOLLOWED, STREAM_FAILED or STREAM_EXPIRED."""
        streams = self._streams
        if now - streams.last_command > streams.timeout:
            return STREAM_EXPIRED
        kin = self._kin
        if kin is None:
            return STREAM_EXPIRED  # the arm was taken away (set_arm(None)): brake to rest as for the deadman
        q = self._pos
        tcp = self.tcp
        if self._set_target(kin, q, tcp) is None:
            return STREAM_FAILED
        rows = kin.jacobian_rows(q, tcp)
        qd, sigma = damped_velocity(rows, self._cart_out.new_velocity)
        self.sigma = sigma
        wanted = list(qd)
        self.scale = uniform_scale(wanted, self._vmax)
        streams.want_velocities(wanted)
        return streams.tick_velocities(command, now)

    def _set_target(self, kin: ArmKinematics, q: Sequence[float], tcp: Sequence[float]) -> Any:
        """The target in base (turned with the tool for a tool twist, slowed near a singularity by the
        last cycle's ``singular_share``), one smoothing cycle; None if ruckig failed."""
        t = self._target
        base = self._target_base
        if self._tool:
            pose = kin.forward(q, tcp)
            tool = frame_of_pose(pose)
            want = [*rotate(tool, t[0:3]), *rotate(tool, t[3:6])]
        else:
            want = t
        share = singular_share(self.sigma, self._slow_below)
        if share < 1.0:
            want = [v * share for v in want]
        if want != base:
            base[:] = want
            self._cart_inp.target_velocity = base
        try:
            result = run_robustly(self._cart_update, self._cart_inp)
        except RUCKIG_ERRORS:
            return None
        if result != WORKING and result != FINISHED:
            return None
        self._cart_out.pass_to_input(self._cart_inp)
        return result
