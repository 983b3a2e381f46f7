"""URScript motion builtins: servoj, speedj, speedl, movej, movel, movep, stopj, stopl.

Each builtin hands the fake arm a ``Motion`` (fakeur/joint_motion.py, fakeur/tcp_motion.py) and
blocks its thread, cycle by cycle, until the arm has played it (``FakeArm.play``: ``dt × speed
slider`` of program time per cycle). The slider slows a motion's progress, never servoj's tracking of
its setpoint nor a stop's braking (stopj, stopl): a stop never gets longer because the slider is low.
A motion starts from what the arm is commanded to do (position and velocity), so a command that
follows one still moving (a blend, a servoj or speedj stream) continues smoothly.

* One thread controls the arm at a time: the one blocked in a motion command (from the call until it
  returns, or its thread is killed). A motion command from another thread meanwhile is the runtime
  error :data:`ANOTHER_THREAD`, which stops the program (and so the arm), as on a controller; the
  thread in control keeps it until then. ``kill`` the controlling thread first to take over.
* A thread killed (or a program stopped) in the middle of its motion leaves the arm decelerating at
  that motion's stop deceleration.
* A movej/optimovej target outside the joint limits, or a pose with no inverse kinematics, is a
  runtime error: the controller checks a joint move's target before it plans, and the program stops.
* A movel/movep/servoc whose target or straight path the arm cannot reach (no inverse kinematics, or
  outside the joint limits) is a protective stop: the program pauses in the command, which tries again
  once the stop is unlocked and the program resumes. A servoj target outside the limits is one too.
* movej/movel with ``r`` > 0 return once the TCP is within ``r`` of the target; the arm goes on
  towards it until the next motion command blends out of it (or it arrives).
* servoj: for ``t`` rounded to whole cycles the joints are pulled toward the target by a model of the
  manual's gain (a P-term) and lookahead_time (the position projected forward with the velocity):
  ``q'' = gain·(q* − (q + lookahead_time·q'))`` (``ServoFilter``). The arm lags a moving target by
  about ``lookahead_time × speed`` and settles on a held one; low gain with short lookahead oscillates.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Generator, Sequence
from typing import Any, Final

from urdaemon.description.frames import compose, frame_of_pose, inverse, pose_of_frame
from urdaemon.fakeur.fake_arm import FakeArm
from urdaemon.fakeur.joint_motion import (
    TIME_EPSILON_S,
    LinearStop,
    Motion,
    ServoFilter,
    joint_move,
    leading_stop_time,
    profile,
    resumed_velocity,
    speed_command,
)
from urdaemon.fakeur.life import PROTECTIVE_STOP_DECELERATION
from urdaemon.fakeur.tcp_motion import ArcMove, CartesianMove, ToolSpeedRamp
from urdaemon.fakeur.urscript.runtime import ScriptRuntimeError, UrList, UrPose, builtin
from urdaemon.fakeur.urscript.script_host import ScriptHost
from urdaemon.fakeur.urscript.signatures import Computed
from urdaemon.urscript import SERVOJ_GAIN_RANGE, SERVOJ_LOOKAHEAD_RANGE_S

__all__ = [
    "ANOTHER_THREAD",
    "MotionState",
    "flange_pose",
    "inverse_near",
    "tcp_matrix",
    "tcp_pose",
    "tool_speed",
]

ANOTHER_THREAD: Final = "Another thread is already controlling the robot"
"""The controller's runtime error for a motion command while another thread's motion runs."""

SERVOJ_STOP_DECELERATION: Final = PROTECTIVE_STOP_DECELERATION
"""rad/s²: how a servoj stream that is not renewed comes to rest (unverified on a real arm)."""

JOINT_BLEND_DECELERATION: Final = 1.4
"""rad/s²: how fast a blend into movel/movep cancels the joint velocity it starts with (movej's
default acceleration)."""
SPEED_STEP_S: Final = 1e-3
"""s: the forward difference over which a TCP speed is computed from joint speeds."""

Gen = Generator[None, None, Any]

_DONE, _REPLACED, _INTERRUPTED = 0, 1, 2


class MotionState:
    """What lib_motion keeps per program (``host.motion``): which command owns the arm, and which
    thread is in control (``owner``, blocked in that command; None between commands)."""

    __slots__ = ("owner", "serial", "speed")

    def __init__(self) -> None:
        self.serial = 0
        self.owner: int | None = None
        self.speed: tuple[Sequence[float], float] = ((), 1.0)
        """The last speedj's joint speeds as asked, and how many times slower it was played."""


def _state(host: ScriptHost) -> MotionState:
    state = host.motion
    if state is None:
        state = host.motion = MotionState()
    return state  # type: ignore[no-any-return]


def _vector(name: str, value: Any) -> list[float]:
    """A new list of 6 finite floats (a copy: motions keep it)."""
    if not isinstance(value, (list, tuple)) or len(value) != 6:
        raise ScriptRuntimeError(f"{name}: expected a list of 6 numbers, got {value!r}")
    try:
        out = [float(v) for v in value]
    except (TypeError, ValueError):
        raise ScriptRuntimeError(f"{name}: expected a list of 6 numbers, got {value!r}") from None
    if not math.isfinite(sum(out)):
        raise ScriptRuntimeError(f"{name}: expected a list of 6 finite numbers, got {value!r}")
    return out


def _number(name: str, value: Any) -> float:
    kind = type(value)
    if (kind is float or kind is int) and math.isfinite(value):  # the hot path: one check
        return float(value)
    raise ScriptRuntimeError(f"{name}: expected a number, got {value!r}")


def _within_limits(arm: FakeArm, q: Sequence[float]) -> bool:
    for value, low, high in zip(q, arm.min_position, arm.max_position, strict=True):
        if not low <= value <= high:
            return False
    return True


def _play(host: ScriptHost, motion: Motion, stop: float, until: Callable[[], bool] | None = None) -> Gen:
    """Play ``motion`` and wait until it is over (or ``until()``); _DONE, _REPLACED or _INTERRUPTED."""
    arm = host.arm
    state = _state(host)
    thread = host.thread
    if state.owner is not None and state.owner != thread:
        raise ScriptRuntimeError(ANOTHER_THREAD)
    state.owner = thread
    state.serial += 1
    me = state.serial
    try:
        return (yield from _played(arm, state, me, motion, stop, until))
    finally:  # returned, replaced (set_pos), killed, or the program stopped: control is free again
        if state.owner == thread:
            state.owner = None


def _played(
    arm: FakeArm, state: MotionState, me: int, motion: Motion, stop: float, until: Callable[[], bool] | None
) -> Gen:
    while not arm.play(motion, stop):  # the arm cannot move (yet): wait, as a paused motion does
        yield
        if state.serial != me:
            return _REPLACED
    finished = False
    try:
        while True:
            yield
            if state.serial != me:
                finished = True
                return _REPLACED
            if arm.played is not motion:
                finished = True
                return _INTERRUPTED  # a safety stop or a pause took the arm
            if arm.motion_time >= motion.duration - TIME_EPSILON_S or (until is not None and until()):
                finished = True
                return _DONE
    finally:
        if not finished and arm.motion is motion:
            arm.stop(stop)  # the thread was killed or the program stopped in the middle of the motion


def _start(arm: FakeArm) -> tuple[list[float], list[float]]:
    """Where a new motion starts: the commanded joint positions and velocities."""
    return list(arm.target_q), arm.commanded_velocity


def _protective_stop(host: ScriptHost, what: str, q: Sequence[float]) -> None:
    host.message("text", _outside_limits(what, q))
    host.arm.protective_stop()


def _unreachable(host: ScriptHost, text: str) -> Gen:
    """A straight move the arm cannot make: a protective stop (the controller then reports its error
    code), and the command waits until the arm may move again (unlocked; resumed, if paused)."""
    host.message("text", text)
    arm = host.arm
    arm.protective_stop()
    yield
    while not arm.life.can_move:
        yield


def _outside_limits(name: str, q: Sequence[float]) -> str:
    return f"{name}: target {[round(v, 4) for v in q]} is outside the joint limits"


# ---- servoj, speedj, stopj, stopl ------------------------------------------------------------------------


@builtin("servoj", blocking=True)
def servoj(host: ScriptHost, q: Any, a: Any, v: Any, t: Any, lookahead_time: Any, gain: Any) -> Gen:
    """servoj(q, a, v, t, lookahead_time, gain): pull the joints toward ``q`` for ``t`` (whole cycles, at
    least one) with the gain and lookahead model of ``ServoFilter``."""
    target = _vector("servoj", q)
    duration = _number("servoj t", t)
    lookahead = _number("servoj lookahead_time", lookahead_time)
    proportional = _number("servoj gain", gain)
    if not SERVOJ_LOOKAHEAD_RANGE_S[0] <= lookahead <= SERVOJ_LOOKAHEAD_RANGE_S[1]:
        raise ScriptRuntimeError(
            f"servoj: lookahead_time {lookahead} is outside {list(SERVOJ_LOOKAHEAD_RANGE_S)}"
        )
    if not SERVOJ_GAIN_RANGE[0] <= proportional <= SERVOJ_GAIN_RANGE[1]:
        raise ScriptRuntimeError(f"servoj: gain {proportional} is outside {list(SERVOJ_GAIN_RANGE)}")
    arm = host.arm
    if not _within_limits(arm, target):
        _protective_stop(host, "servoj", target)
        return None
    step = host.step_time
    cycles = max(1, round(duration / step))
    start, moving = _start(arm)
    # the slider slows a motion's progress, never the servo's tracking: the law runs in the controller's
    # time (on the program's time, played ``dt × slider`` a cycle: gain / slider², lookahead × slider)
    slider = max(arm.speed_slider, 1e-3)
    servo = ServoFilter(
        start, moving, target, cycles * step * slider, proportional / (slider * slider), lookahead * slider
    )
    yield from _play(host, servo, SERVOJ_STOP_DECELERATION)
    return None


@builtin("speedj", blocking=True)
def speedj(host: ScriptHost, qd: Any, a: Any, t: Any) -> Gen:
    """speedj(qd, a, t): accelerate to joint speeds ``qd``; return after ``t``, or once at speed if t = 0.

    Faster than a joint's limit, the command is played slower in time, keeping its direction and the
    distance it asks for (``speed_command``); the next speedj ramps on from the speed asked here."""
    velocity = _vector("speedj", qd)
    acceleration = _number("speedj a", a)
    duration = _number("speedj t", t)
    arm, state = host.arm, _state(host)
    start, moving = _start(arm)
    moving = resumed_velocity(moving, *state.speed)
    if acceleration <= 0:
        # a = 0 with nothing to change is a hold at the present speed (urcl's spline follower sends
        # that on a segment's last, zero-speed step); a change no acceleration can make is an error
        if acceleration < 0 or any(abs(v - m) > 1e-12 for v, m in zip(velocity, moving, strict=True)):
            raise ScriptRuntimeError(f"speedj: acceleration must be > 0 to change speed, got {acceleration}")
        acceleration = 1e-9
    limits = (arm.max_velocity, max(arm.speed_slider, 1e-3))
    motion, factor = speed_command(start, moving, velocity, acceleration, (duration, host.step_time), limits)
    state.speed = (velocity, factor)
    yield from _play(host, motion, acceleration / (factor * factor))
    return None


@builtin("speedl", blocking=True)
def speedl(host: ScriptHost, xd: Any, a: Any, t: Any, aRot: Any) -> Gen:
    """speedl(xd, a, t, aRot): accelerate the TCP to twist ``xd`` (m/s, rad/s; base frame).

    ``a`` m/s² and ``aRot`` rad/s² (default: ``a``); returns after ``t``, or once at speed if t = 0."""
    twist = _vector("speedl", xd)
    linear = _number("speedl a", a)
    angular = linear if isinstance(aRot, Computed) or aRot is None else _number("speedl aRot", aRot)
    duration = _number("speedl t", t)
    if linear <= 0 or angular <= 0:
        raise ScriptRuntimeError(f"speedl: accelerations must be > 0, got {linear}, {angular}")
    arm = host.arm
    tcp = list(arm.tcp_offset)
    ik = arm.ik

    def joint_velocity(q: Sequence[float], wanted: Sequence[float]) -> Sequence[float]:
        return ik.joint_velocity(q, wanted, tcp)

    start, moving = _start(arm)
    now = tool_speed(arm, start, moving)
    ramp = ToolSpeedRamp(start, now, twist, linear, angular, duration, joint_velocity)
    if ramp.duration < host.step_time:
        ramp = ToolSpeedRamp(start, now, twist, linear, angular, host.step_time, joint_velocity)
    # when it is not renewed the arm stops in the time the tool accelerations need
    stop_time = max(
        math.sqrt(sum(v * v for v in twist[:3])) / linear, math.sqrt(sum(v * v for v in twist[3:])) / angular
    )
    peak = max((abs(v) for v in joint_velocity(start, twist)), default=0.0)
    yield from _play(host, ramp, peak / stop_time if stop_time > 0 else PROTECTIVE_STOP_DECELERATION)
    return None


@builtin("stopj", blocking=True)
def stopj(host: ScriptHost, a: Any) -> Gen:
    """stopj(a): decelerate to rest, linear in joint space, ``a`` for the leading joint."""
    deceleration = _number("stopj a", a)
    if deceleration <= 0:
        raise ScriptRuntimeError(f"stopj: deceleration must be > 0, got {deceleration}")
    arm = host.arm
    start, moving = _start(arm)
    # a stop brakes at ``a`` in the controller's time whatever the speed slider: played on the program's
    # time (``dt × slider`` a cycle) from the program-time velocity, that is a / slider² there
    braking = deceleration / _slider_squared(arm)
    yield from _play(host, LinearStop(start, moving, leading_stop_time(moving, braking)), braking)
    return None


def _slider_squared(arm: FakeArm) -> float:
    """The speed slider squared (floored): how a deceleration in controller time shrinks on the program's
    time, on which motions are played (velocities scale by the slider, decelerations by its square)."""
    slider = max(arm.speed_slider, 1e-3)
    return slider * slider


@builtin("stopl", blocking=True)
def stopl(host: ScriptHost, a: Any, aRot: Any) -> Gen:
    """stopl(a, aRot): decelerate the tool to rest along its path, ``a`` m/s² and ``aRot`` rad/s²."""
    deceleration = _number("stopl a", a)
    rotation = deceleration if isinstance(aRot, Computed) or aRot is None else _number("stopl aRot", aRot)
    if deceleration <= 0 or rotation <= 0:
        raise ScriptRuntimeError(f"stopl: decelerations must be > 0, got {deceleration}, {rotation}")
    arm = host.arm
    start, moving = _start(arm)
    speed = tool_speed(arm, start, moving)
    linear = math.sqrt(sum(v * v for v in speed[:3]))
    angular = math.sqrt(sum(v * v for v in speed[3:]))
    duration = max(linear / deceleration, angular / rotation)
    if duration <= 0 and any(moving):
        duration = leading_stop_time(moving, PROTECTIVE_STOP_DECELERATION)
    duration *= _slider_squared(arm)  # braking in controller time whatever the slider (as stopj)
    joint_deceleration = leading_stop_time(moving, 1.0) / duration if duration > 0 else 1.0
    yield from _play(host, LinearStop(start, moving, duration), joint_deceleration)
    return None


# ---- movej, movel, movep ---------------------------------------------------------------------------


def flange_pose(arm: FakeArm, q: Sequence[float]) -> tuple[float, float, float, float, float, float]:
    """The tool flange pose for joints ``q`` (base frame, rotation vector)."""
    if list(q) == arm.q:
        return arm.tcp_pose()
    x, y, z, qx, qy, qz, qw = arm.kinematics.tool_pose(q)
    norm = math.sqrt(qx * qx + qy * qy + qz * qz)
    if norm < 1e-12:
        return (x, y, z, 0.0, 0.0, 0.0)
    scale = 2.0 * math.atan2(norm, qw) / norm
    return (x, y, z, qx * scale, qy * scale, qz * scale)


def tcp_matrix(arm: FakeArm, q: Sequence[float], tcp: Sequence[float] | None = None) -> Any:
    """The TCP transform for joints ``q`` and TCP offset ``tcp`` (the arm's when None)."""
    return compose(frame_of_pose(flange_pose(arm, q)), frame_of_pose(arm.tcp_offset if tcp is None else tcp))


def tcp_pose(
    arm: FakeArm, q: Sequence[float], tcp: Sequence[float] | None = None
) -> tuple[float, float, float, float, float, float]:
    """The TCP pose for joints ``q`` and TCP offset ``tcp`` (the arm's when None)."""
    if tcp is None and q is arm.q:
        return arm.actual_tcp_pose()  # cached per cycle
    return pose_of_frame(tcp_matrix(arm, q, tcp))


def _joint_target(host: ScriptHost, name: str, target: Any) -> list[float] | None:
    """The joints of a movej/movel target: a joint list as is, a pose by IK nearest the arm's joints."""
    values = _vector(name, target)
    if not isinstance(target, UrPose):
        return values
    return _inverse(host, values, host.arm.target_q)


def _inverse(host: ScriptHost, pose: Sequence[float], near: Sequence[float]) -> list[float] | None:
    return inverse_near(host.arm, pose, near, host.arm.tcp_offset)


def inverse_near(
    arm: FakeArm,
    pose: Sequence[float],
    near: Sequence[float],
    tcp: Sequence[float] | None,
    max_position_error: float = 1e-10,
    max_orientation_error: float = 1e-10,
) -> list[float] | None:
    """Joints reaching TCP ``pose`` nearest ``near``, or None."""
    q = arm.ik.nearest(pose, near, tcp, max_position_error, max_orientation_error)
    return None if q is None else list(q)


def tool_speed(arm: FakeArm, q: Sequence[float], qd: Sequence[float]) -> UrList:
    """[vx, vy, vz, wx, wy, wz]: the TCP's speed at joints ``q`` moving at ``qd`` (base frame)."""
    if not any(qd):
        return UrList([0.0] * 6)
    h = SPEED_STEP_S
    here = tcp_matrix(arm, q)
    ahead = tcp_matrix(arm, [a + v * h for a, v in zip(q, qd, strict=True)])
    linear = [(b - a) / h for a, b in zip(here[9:], ahead[9:], strict=True)]
    wx, wy, wz = pose_of_frame(compose(ahead, inverse(here)))[3:]  # ahead · hereᵀ: the turn in base
    return UrList([*linear, wx / h, wy / h, wz / h])


def _blend_check(arm: FakeArm, target: Sequence[float], radius: float) -> Callable[[], bool] | None:
    """Whether the TCP is within ``radius`` of joints ``target``'s (None: no blend)."""
    return _pose_blend_check(arm, tcp_matrix(arm, target)[9:], radius) if radius > 0 else None


@builtin("movej", blocking=True)
def movej(host: ScriptHost, q: Any, a: Any, v: Any, t: Any, r: Any) -> Gen:
    """movej(q, a, v, t, r): to joints ``q`` (or a pose, by IK), linear in joint space."""
    acceleration, velocity = _number("movej a", a), _number("movej v", v)
    return (yield from _joint_motion(host, "movej", q, acceleration, velocity, _number("movej t", t), r))


@builtin("optimovej", blocking=True)
def optimovej(host: ScriptHost, q: Any, a: Any, v: Any, r: Any) -> Gen:
    """optimovej(q, a, v, r): movej with ``a`` and ``v`` as fractions (0, 1] of the joints' limits."""
    fraction_a, fraction_v = _number("optimovej a", a), _number("optimovej v", v)
    if not (0 < fraction_a <= 1 and 0 < fraction_v <= 1):
        raise ScriptRuntimeError(f"optimovej: a and v must be fractions in (0, 1], got a={a!r}, v={v!r}")
    arm = host.arm
    velocity = fraction_v * min(arm.max_velocity)
    acceleration = fraction_a * min(j.max_acceleration for j in arm.model.joints)
    return (yield from _joint_motion(host, "optimovej", q, acceleration, velocity, 0.0, r))


def _joint_motion(
    host: ScriptHost, name: str, q: Any, acceleration: float, velocity: float, duration: float, r: Any
) -> Gen:
    radius = _number(f"{name} r", r)
    arm = host.arm
    target = _joint_target(host, name, q)
    if target is None:
        raise ScriptRuntimeError(f"{name}: no inverse kinematics solution for {q!r}")
    if not _within_limits(arm, target):
        raise ScriptRuntimeError(_outside_limits(name, target))
    if duration <= 0 and (acceleration <= 0 or velocity <= 0):
        raise ScriptRuntimeError(f"{name}: needs a > 0 and v > 0 (got a={acceleration}, v={velocity})")
    until = _blend_check(arm, target, radius)
    while True:
        start, moving = _start(arm)
        move = joint_move(
            start,
            target,
            velocity=velocity,
            acceleration=acceleration,
            duration=duration,
            max_velocity=arm.max_velocity,
            start_velocity=moving,
        )
        outcome = yield from _play(host, move, max(acceleration, 1e-3), until)
        if outcome != _INTERRUPTED:
            return None
        duration = 0.0  # resumed after a stop: the rest at v and a


def _cartesian(host: ScriptHost, name: str, pose: Any, a: Any, v: Any, t: Any, r: Any) -> Gen:
    acceleration, velocity = _number(f"{name} a", a), _number(f"{name} v", v)
    duration, radius = _number(f"{name} t", t), _number(f"{name} r", r)
    arm = host.arm
    values = _vector(name, pose)
    goal = values if isinstance(pose, UrPose) else tcp_pose(arm, values)
    if duration <= 0 and (acceleration <= 0 or velocity <= 0):
        raise ScriptRuntimeError(f"{name}: needs a > 0 and v > 0 (got a={acceleration}, v={velocity})")
    while True:  # until the target is reachable: an unreachable one protective-stops, then tries again
        end = _inverse(host, goal, arm.target_q) if isinstance(pose, UrPose) else values
        if end is None:
            yield from _unreachable(host, f"{name}: no inverse kinematics solution for {pose!r}")
        elif not _within_limits(arm, end):
            yield from _unreachable(host, _outside_limits(name, end))
        else:
            break
    return (yield from _straight(host, name, pose, goal, end, (acceleration, velocity, duration, radius)))


def _straight(
    host: ScriptHost,
    name: str,
    pose: Any,
    goal: Sequence[float],
    end: Sequence[float],
    limits: tuple[float, float, float, float],
) -> Gen:
    """Play movel's straight line to ``goal`` (joints ``end``), from wherever the arm is commanded."""
    acceleration, velocity, duration, radius = limits
    arm = host.arm
    until = _blend_check(arm, end, radius)
    tcp = list(arm.tcp_offset)

    def solve(target: Sequence[float], near: Sequence[float]) -> list[float] | None:
        return inverse_near(arm, target, near, tcp)

    while True:
        start, moving = _start(arm)
        start_pose = tcp_pose(arm, start)
        distance = math.dist(start_pose[:3], goal[:3])
        if distance < 1e-6:  # a pure rotation: v and a taken as rad/s and rad/s²
            rel = compose(inverse(frame_of_pose(start_pose)), frame_of_pose(goal))
            distance = math.sqrt(sum(c * c for c in pose_of_frame(rel)[3:]))
        shape = profile(distance, velocity=velocity, acceleration=acceleration, duration=duration)
        # a blend: the joint velocity the arm has fades out decelerating at most at the joints' own
        # default acceleration (the tool acceleration a is not a joint-space one)
        fade = 4.0 * leading_stop_time(moving, JOINT_BLEND_DECELERATION)
        move = CartesianMove(start_pose, goal, shape, start, solve, moving, fade)
        outcome = yield from _play(host, move, PROTECTIVE_STOP_DECELERATION, _or_failed(move, until))
        if move.failed:  # the arm holds where the line left the reachable space
            yield from _unreachable(host, f"{name}: the straight line to {pose!r} leaves the reachable space")
        elif outcome != _INTERRUPTED:
            return None
        duration = 0.0


def _or_failed(move: CartesianMove, until: Callable[[], bool] | None) -> Callable[[], bool]:
    """``until``, or the move's path has left the reachable space (its arm holds)."""
    return (lambda: move.failed) if until is None else (lambda: move.failed or until())


@builtin("movec", blocking=True)
def movec(host: ScriptHost, pose_via: Any, pose_to: Any, a: Any, v: Any, r: Any, mode: Any) -> Gen:
    """movec(pose_via, pose_to, a, v, r, mode): the TCP on the circle through here, via and to.

    mode 0: the orientation interpolated from here to ``pose_to``; mode 1: fixed to the arc's tangent."""
    acceleration, velocity, radius = _number("movec a", a), _number("movec v", v), _number("movec r", r)
    if acceleration <= 0 or velocity <= 0:
        raise ScriptRuntimeError(f"movec: needs a > 0 and v > 0 (got a={acceleration}, v={velocity})")
    if mode not in (0, 1):
        raise ScriptRuntimeError(f"movec: mode must be 0 or 1, got {mode!r}")
    arm = host.arm
    via_values, to_values = _vector("movec", pose_via), _vector("movec", pose_to)
    via = via_values if isinstance(pose_via, UrPose) else tcp_pose(arm, via_values)
    goal = to_values if isinstance(pose_to, UrPose) else tcp_pose(arm, to_values)
    tcp = list(arm.tcp_offset)

    def solve(target: Sequence[float], near: Sequence[float]) -> list[float] | None:
        return inverse_near(arm, target, near, tcp)

    start, moving = _start(arm)
    try:
        move = ArcMove(
            tcp_pose(arm, start),
            via,
            goal,
            velocity,
            acceleration,
            start,
            solve,
            fixed_orientation=mode == 1,
            start_velocity=moving,
            fade_time=4.0 * leading_stop_time(moving, JOINT_BLEND_DECELERATION),
        )
    except ValueError as err:
        raise ScriptRuntimeError(f"movec: {err}") from None
    # (a movec interrupted by a safety stop is not resumed: the program goes on after it)
    yield from _play(host, move, PROTECTIVE_STOP_DECELERATION, _pose_blend_check(arm, goal, radius))
    if move.failed:
        raise ScriptRuntimeError(f"movec: the arc to {pose_to!r} leaves the reachable space")
    return None


def _pose_blend_check(arm: FakeArm, goal: Sequence[float], radius: float) -> Callable[[], bool] | None:
    if radius <= 0:
        return None
    point = list(goal[:3])

    def within() -> bool:
        return math.dist(tcp_matrix(arm, arm.target_q)[9:], point) <= radius

    return within


@builtin("movel", blocking=True)
def movel(host: ScriptHost, pose: Any, a: Any, v: Any, t: Any, r: Any) -> Gen:
    """movel(pose, a, v, t, r): the TCP on a straight line to ``pose`` (joints: their forward kinematics)."""
    return (yield from _cartesian(host, "movel", pose, a, v, t, r))


@builtin("movep", blocking=True)
def movep(host: ScriptHost, pose: Any, a: Any, v: Any, r: Any) -> Gen:
    """movep(pose, a, v, r): as movel (the fake keeps the tool speed constant along each line)."""
    return (yield from _cartesian(host, "movep", pose, a, v, 0.0, r))


@builtin("servoc", blocking=True)
def servoc(host: ScriptHost, pose: Any, a: Any, v: Any, r: Any) -> Gen:
    """servoc(pose, a, v, r): to ``pose`` at tool speed ``v``, on a straight line as movel (blends: r)."""
    return (yield from _cartesian(host, "servoc", pose, a, v, 0.0, r))


@builtin("set_pos")
def set_pos(host: ScriptHost, q: Any) -> None:
    """set_pos(q): put the simulated arm at joints ``q`` at once (a simulator-only builtin)."""
    target = _vector("set_pos", q)
    arm = host.arm
    if not _within_limits(arm, target):
        raise ScriptRuntimeError(f"set_pos: {target} is outside the joint limits")
    _state(host).serial += 1  # a motion in progress ends
    arm.stop(PROTECTIVE_STOP_DECELERATION)
    arm.q[:] = target
    arm.qd[:] = [0.0] * 6


@builtin("protective_stop")
def protective_stop(host: ScriptHost) -> None:
    """protective_stop(): the arm stops as on a protective stop; the program pauses."""
    host.arm.protective_stop()
