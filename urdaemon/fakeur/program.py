"""The fake controller's program executor: what a real controller does running External Control.

A real controller runs UR's ``external_control.urscript`` (ur-protocols.md §5): it dials back to the
daemon's trajectory (50003), script-command (50004) and reverse (50001) servers and then executes the
protocol of §4 until the daemon sends STOPPED or stops talking. ``ProgramRunner`` does the same over
the robot side of our codecs, moving a ``FakeArm``.

Model (how the script's threads map onto asyncio and the controller clock):

* ``run()`` is the script's main loop: it reads reverse frames (each frame's timeout bounds the next
  read, the first read blocks), switches control modes and applies setpoints (§5.4).
* A task per callback socket stands for the controller's socket buffers: trajectory points are read
  as they arrive into a bounded queue; script commands are executed as they arrive (§4.5).
* ``step(dt)`` is every thread's per-cycle work, called by the controller's clock before
  ``arm.step(dt)``: the servo thread's servoj/extrapolation and the trajectory thread's spline or movej
  sampling. Robot-side motion advances by ``dt × speed slider`` (0 while the arm cannot move): the
  controller's own time scaling (§5.7). While the program is paused every thread is suspended.

Timeouts: socket reads (reverse frames, the 0.5 s wait for a trajectory point, the buffer drain) run
on the wall clock, like a real socket; the trajectory thread's "one step" read after a moving spline
segment is counted in controller cycles: the next point must arrive within one cycle of waiting.

What the fake cannot simulate (no inverse kinematics, no dynamics): SPEEDL, POSE and TORQUE modes hold
the arm still (reported once as a text message); pose-target and Cartesian trajectory motions end the
trajectory with FAILURE (reported); tool contact is never detected; blend radii are ignored (each
movej stops at its target).
"""

from __future__ import annotations

import asyncio
import contextlib
import enum
import math
import os
import re
import socket
import time
from collections import deque
from collections.abc import Callable, Coroutine, Sequence
from dataclasses import dataclass
from typing import Any, Final, Protocol

from urdaemon.errors import RemoteProtocolError, UrDaemonError
from urdaemon.fakeur.arm import FakeArm, RuntimeState
from urdaemon.protocols import script_command as sc
from urdaemon.protocols._buffer import Side
from urdaemon.protocols.reverse import (
    ControlMode,
    FreedriveAction,
    FreedriveControl,
    Idle,
    Pose,
    ReverseConnection,
    ReverseEvent,
    ServoJ,
    SpeedJ,
    SpeedL,
    Stopped,
    Torque,
    TrajectoryAction,
    TrajectoryControl,
    UnknownReverseCommand,
)
from urdaemon.protocols.trajectory_point import (
    MotionPoint,
    MotionType,
    SplinePoint,
    TrajectoryPointConnection,
    TrajectoryPointEvent,
    TrajectoryResultCode,
    TrajectoryResultMessage,
    UnknownTrajectoryPoint,
)

__all__ = [
    "CONNECT_ATTEMPTS",
    "CONNECT_RETRY_DELAY_S",
    "EVENT_RUNTIME",
    "EVENT_TEXT",
    "JOINT_IGNORE_SPEED",
    "POINT_READ_TIMEOUT_S",
    "REASON_CLOSED",
    "REASON_STOPPED",
    "REASON_TIMED_OUT",
    "REVERSE_TIMEOUT_MESSAGE",
    "STOPJ_DECELERATION",
    "CallbackSockets",
    "Endpoint",
    "JointMove",
    "Motion",
    "MotionSampler",
    "ProgramError",
    "ProgramRunner",
    "SplineSegment",
    "cubic_segment",
    "find_callback_sockets",
    "joint_move",
    "quintic_segment",
    "speed_violation",
]

# -- constants of the script (ur-protocols.md §5) --------------------------------------------------------

REVERSE_SOCKET: Final = "reverse_socket"
TRAJECTORY_SOCKET: Final = "trajectory_socket"
SCRIPT_COMMAND_SOCKET: Final = "script_command_socket"
CONNECT_ORDER: Final = (TRAJECTORY_SOCKET, SCRIPT_COMMAND_SOCKET, REVERSE_SOCKET)
"""The script dials in this order (§5.2)."""

CONNECT_ATTEMPTS: Final = 5
"""socket_open attempts per socket before the script gives up (§5.2)."""
CONNECT_RETRY_DELAY_S: Final = 0.2
"""Pause after each failed attempt, s (§5.2)."""
CONNECT_TIMEOUT_S: Final = 2.0
"""One socket_open attempt, s: URScript's default ``timeout`` of socket_open."""
STOPJ_DECELERATION: Final = 4.0
"""rad/s²: the script's ``STOPJ_ACCELERATION``, used by every stopj."""
SPEEDJ_ACCELERATION: Final = 40.0
"""rad/s²: the acceleration the speed thread passes to speedj (§5.3)."""
POINT_READ_TIMEOUT_S: Final = 0.5
"""s: read timeout of a trajectory point while the robot is at rest, and of each drained point (§5.5)."""
JOINT_IGNORE_SPEED: Final = 20.0
"""rad/s: a setpoint or spline segment needing more than this in any joint is refused (§5.4)."""
MAX_JOINT_SPEED: Final = 6.283185
"""rad/s: the joint speed the last-segment slow-down assumes as the maximum (§5.5)."""
SLOW_DOWN_DECELERATION: Final = 15.0
"""rad/s²: deceleration budget of the last spline segment (§5.5)."""
SLOW_DOWN_WINDOW_S: Final = MAX_JOINT_SPEED / SLOW_DOWN_DECELERATION
"""s: how long before its end the last segment starts checking whether it must slow down."""
SLOW_DOWN_END_S: Final = 1e-5
"""s: a slowing segment creeps on until less than this is left, then takes its final step."""
FIRST_POINT_SKIP_DISTANCE: Final = 0.01
"""rad (joint-space norm): a first spline point with time 0 this close to the arm is skipped silently."""
STREAMING_SENTINEL: Final = 2**31 - 1
"""points_left while a stream is open (STREAM_START until STREAM_END or CANCEL; §5.5)."""
VIOLATION_LOG_PERIOD_S: Final = 5.0
"""s: a continuing speed-limit violation is logged again this often (§5.4)."""
DEFAULT_VISCOUS_SCALE: Final = (0.9, 0.9, 0.8, 0.9, 0.9, 0.9)
"""The script's default torque-mode viscous friction scales (§5.2)."""
DEFAULT_COULOMB_SCALE: Final = (0.8, 0.8, 0.7, 0.8, 0.8, 0.8)
"""The script's default torque-mode Coulomb friction scales (§5.2)."""

# -- constants of the fake -------------------------------------------------------------------------------

EVENT_RUNTIME: Final = "runtime"
"""``on_event`` kind of runtime-exception-like reports (the program halts)."""
EVENT_TEXT: Final = "text"
"""``on_event`` kind of textmsg/popup-like reports."""
REASON_STOPPED: Final = "stopped"
"""``run()`` result when the daemon sent STOPPED (hand back control)."""
REASON_TIMED_OUT: Final = "reverse socket timed out"
"""``run()`` result when no reverse frame arrived within the timeout (the program halts)."""
REASON_CLOSED: Final = "reverse socket closed"
"""``run()`` result when the daemon closed the reverse socket (the script sees a failed read and halts)."""
REVERSE_TIMEOUT_MESSAGE: Final = (
    "Socket timed out waiting for command on reverse_socket. The script will exit now."
)
"""What the script logs before it halts on a failed reverse read (§4.2)."""

MAX_BUFFERED_POINTS: Final = 2048
"""Trajectory points held unread, like a socket receive buffer (~170 kB); beyond it TCP pushes back."""
COMMAND_LOG_LENGTH: Final = 256
"""Script commands kept in ``ProgramRunner.command_log`` for inspection."""
READ_CHUNK: Final = 65536
"""Bytes per socket read, B."""
CLOSE_TIMEOUT_S: Final = 1.0
"""s: how long closing one socket may take before we stop waiting."""
TIME_EPSILON_S: Final = 1e-9
"""s: a segment with less than this left after a cycle's advance ends in that cycle (float noise)."""
JOINTS: Final = 6

_PAUSED: Final = frozenset({RuntimeState.PAUSING, RuntimeState.PAUSED})
"""Runtime states in which the program's threads are suspended."""
_MOTION_THREAD_MODES: Final = frozenset(
    {ControlMode.SERVOJ, ControlMode.SPEEDJ, ControlMode.SPEEDL, ControlMode.POSE, ControlMode.TORQUE}
)
"""Modes whose motion thread ends with stopj when the mode changes (§5.4 step 3)."""
_UNSIMULATED_MODES: Final = frozenset({ControlMode.SPEEDL, ControlMode.POSE, ControlMode.TORQUE})
"""Modes that need inverse kinematics or dynamics, which the fake arm does not have."""
_KNOWN_MODES: Final = frozenset(int(m) for m in ControlMode)
_MODE_OF: Final[dict[type, int]] = {
    ServoJ: ControlMode.SERVOJ,
    SpeedJ: ControlMode.SPEEDJ,
    SpeedL: ControlMode.SPEEDL,
    Pose: ControlMode.POSE,
    Torque: ControlMode.TORQUE,
    Idle: ControlMode.IDLE,
    Stopped: ControlMode.STOPPED,
    TrajectoryControl: ControlMode.FORWARD,
    FreedriveControl: ControlMode.FREEDRIVE,
}


class ProgramError(UrDaemonError):
    """The program cannot run as External Control; ``reason`` says why."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


# -- finding the callback sockets --------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Endpoint:
    """Where the program dials: a host (IP literal or name) and a TCP port."""

    host: str
    port: int


@dataclass(frozen=True, slots=True)
class CallbackSockets:
    """The daemon's three servers the program connects back to (§4.1)."""

    reverse: Endpoint
    trajectory: Endpoint
    script_command: Endpoint


_TEMPLATE_TAG = re.compile(r"\{\{.*?\}\}|\{%.*?%\}")
"""urcl's template syntax (§5.1): a placeholder or a conditional tag left in the text."""
_SOCKET_CALL = re.compile(
    r"""\b(?:socket_open|connect_socket_with_retry)\s*\(\s*
        (?P<hq>["'])(?P<host>[^"'\n]*)(?P=hq)\s*,\s*
        (?P<port>[^,()\s]+)\s*,\s*
        (?P<nq>["'])(?P<name>[^"'\n]*)(?P=nq)""",
    re.VERBOSE,
)
"""``socket_open("host", port, "name")`` or the script's ``connect_socket_with_retry`` with the same
three leading arguments (UR's script opens its sockets through that helper)."""
_MAX_PORT: Final = 65535


def _code_only(text: str) -> str:
    """The program with ``#`` comments removed (a ``#`` inside a string literal is kept)."""
    lines = []
    for line in text.splitlines():
        quote = ""
        for index, char in enumerate(line):
            if quote:
                if char == quote:
                    quote = ""
            elif char in "\"'":
                quote = char
            elif char == "#":
                line = line[:index]
                break
        lines.append(line)
    return "\n".join(lines)


def find_callback_sockets(program_text: str) -> CallbackSockets:
    """The reverse, trajectory and script-command sockets the program opens; ProgramError if it cannot."""
    code = _code_only(program_text)
    tags = list(dict.fromkeys(_TEMPLATE_TAG.findall(code)))
    if tags:
        raise ProgramError(f"program has unfilled template placeholders: {', '.join(tags)}")
    found: dict[str, Endpoint] = {}
    for match in _SOCKET_CALL.finditer(code):
        name, host, port_text = match["name"], match["host"], match["port"]
        if name not in CONNECT_ORDER or name in found:
            continue  # the script opens each socket once; a later call would never run first
        if not port_text.isdigit() or not 0 < int(port_text) <= _MAX_PORT:
            raise ProgramError(f"{name}: port {port_text!r} is not a TCP port number")
        if not host.strip():
            raise ProgramError(f"{name}: empty host")
        found[name] = Endpoint(host.strip(), int(port_text))
    missing = [
        name for name in (REVERSE_SOCKET, TRAJECTORY_SOCKET, SCRIPT_COMMAND_SOCKET) if name not in found
    ]
    if missing:
        raise ProgramError(f"program does not open {', '.join(missing)}: not an External Control program")
    return CallbackSockets(found[REVERSE_SOCKET], found[TRAJECTORY_SOCKET], found[SCRIPT_COMMAND_SOCKET])


# -- motion math (pure) -----------------------------------------------------------------------------------


class Motion(Protocol):
    """A joint-space motion over ``[0, duration]`` seconds."""

    duration: float

    def position(self, t: float) -> list[float]:
        """Joint positions [rad] at time ``t``."""
        ...

    def velocity(self, t: float) -> list[float]:
        """Joint velocities [rad/s] at time ``t``."""
        ...


class SplineSegment:
    """A polynomial per joint, q(t) = c0 + c1·t + … + c5·t⁵ over ``[0, duration]`` (§5.5 spline points)."""

    __slots__ = ("_coefficients", "duration", "quintic")

    def __init__(self, coefficients: Sequence[Sequence[float]], duration: float, *, quintic: bool) -> None:
        self._coefficients = [tuple(c) for c in coefficients]
        self.duration = duration
        self.quintic = quintic

    def position(self, t: float) -> list[float]:
        """Joint positions [rad] at ``t`` (Horner's rule: the hot path of every spline cycle)."""
        return [a + t * (b + t * (c + t * (d + t * (e + t * f)))) for a, b, c, d, e, f in self._coefficients]

    def velocity(self, t: float) -> list[float]:
        """Joint velocities [rad/s] at ``t``."""
        return [
            b + t * (2 * c + t * (3 * d + t * (4 * e + t * 5 * f))) for _, b, c, d, e, f in self._coefficients
        ]

    def acceleration(self, t: float) -> list[float]:
        """Joint accelerations [rad/s²] at ``t``."""
        return [2 * c + t * (6 * d + t * (12 * e + t * 20 * f)) for _, _, c, d, e, f in self._coefficients]


def cubic_segment(
    start_q: Sequence[float],
    start_qd: Sequence[float],
    end_q: Sequence[float],
    end_qd: Sequence[float],
    duration: float,
) -> SplineSegment:
    """The cubic from (position, velocity) at 0 to (position, velocity) at ``duration`` > 0, per joint."""
    t = duration
    coefficients = []
    for q0, v0, q1, v1 in zip(start_q, start_qd, end_q, end_qd, strict=True):
        span = q1 - q0
        c2 = (3 * span - (2 * v0 + v1) * t) / t**2
        c3 = (-2 * span + (v0 + v1) * t) / t**3
        coefficients.append((q0, v0, c2, c3, 0.0, 0.0))
    return SplineSegment(coefficients, duration, quintic=False)


def quintic_segment(
    start_q: Sequence[float],
    start_qd: Sequence[float],
    start_qdd: Sequence[float],
    end_q: Sequence[float],
    end_qd: Sequence[float],
    end_qdd: Sequence[float],
    duration: float,
) -> SplineSegment:
    """The quintic matching position, velocity and acceleration at 0 and at ``duration`` > 0, per joint."""
    t = duration
    t2 = t * t
    coefficients = []
    for q0, v0, a0, q1, v1, a1 in zip(start_q, start_qd, start_qdd, end_q, end_qd, end_qdd, strict=True):
        span = q1 - q0
        c3 = (20 * span - (12 * v0 + 8 * v1) * t - (3 * a0 - a1) * t2) / (2 * t**3)
        c4 = (-30 * span + (16 * v0 + 14 * v1) * t + (3 * a0 - 2 * a1) * t2) / (2 * t**4)
        c5 = (12 * span - 6 * (v0 + v1) * t + (a1 - a0) * t2) / (2 * t**5)
        coefficients.append((q0, v0, 0.5 * a0, c3, c4, c5))
    return SplineSegment(coefficients, duration, quintic=True)


class JointMove:
    """movej: every joint follows the leading joint's trapezoidal profile, so all arrive together."""

    __slots__ = ("_delta", "_distance", "_peak", "_ramp", "_start", "duration")

    def __init__(self, start: Sequence[float], target: Sequence[float], ramp: float, peak: float) -> None:
        self._start = list(start)
        self._delta = [b - a for a, b in zip(start, target, strict=True)]
        self._distance = max((abs(d) for d in self._delta), default=0.0)
        self._ramp = ramp
        """s: acceleration (and deceleration) phase."""
        self._peak = peak
        """rad/s: the leading joint's cruise speed."""
        self.duration = self._distance / peak + ramp if self._distance > 0 else 0.0

    def _travel(self, t: float) -> tuple[float, float]:
        """The leading joint's distance covered and speed at ``t``."""
        ramp, peak, total = self._ramp, self._peak, self.duration
        if t <= 0:
            return 0.0, 0.0
        if t >= total:
            return self._distance, 0.0
        if t < ramp:
            return 0.5 * peak / ramp * t * t, peak / ramp * t
        if t <= total - ramp:
            return peak * (t - 0.5 * ramp), peak
        left = total - t
        return self._distance - 0.5 * peak / ramp * left * left, peak / ramp * left

    def position(self, t: float) -> list[float]:
        """Joint positions [rad] at ``t``."""
        if self._distance <= 0:
            return list(self._start)
        fraction = self._travel(t)[0] / self._distance
        return [a + d * fraction for a, d in zip(self._start, self._delta, strict=True)]

    def velocity(self, t: float) -> list[float]:
        """Joint velocities [rad/s] at ``t``."""
        if self._distance <= 0:
            return [0.0] * len(self._start)
        rate = self._travel(t)[1] / self._distance
        return [d * rate for d in self._delta]


def joint_move(
    start: Sequence[float],
    target: Sequence[float],
    *,
    velocity: float,
    acceleration: float,
    duration: float = 0.0,
) -> JointMove:
    """movej(target, a, v, t) from ``start``; ValueError for a speed or acceleration that cannot move.

    ``duration`` > 0 overrides ``velocity`` (URScript: t given ⇒ v and a ignored). How a real controller
    shapes a timed movej is unverified; we keep ``acceleration`` if it can make the time, else the
    gentlest triangle that does.
    """
    distance = max((abs(b - a) for a, b in zip(start, target, strict=True)), default=0.0)
    if distance <= 0:
        return JointMove(start, target, 0.0, 1.0)
    if duration > 0:
        a = acceleration
        discriminant = (a * duration) ** 2 - 4 * a * distance if a > 0 else -1.0
        if discriminant >= 0:
            peak = (a * duration - math.sqrt(discriminant)) / 2
            return JointMove(start, target, peak / a, peak)
        return JointMove(start, target, duration / 2, 2 * distance / duration)
    if not (velocity > 0 and acceleration > 0 and math.isfinite(velocity) and math.isfinite(acceleration)):
        raise ValueError(f"movej needs a > 0 and v > 0 (got a={acceleration}, v={velocity})")
    ramp = velocity / acceleration
    if distance < velocity * ramp:  # never reaches v: a triangle at acceleration a
        ramp = math.sqrt(distance / acceleration)
        return JointMove(start, target, ramp, acceleration * ramp)
    return JointMove(start, target, ramp, velocity)


def speed_violation(start: Sequence[float], end: Sequence[float], time: float) -> tuple[int, float] | None:
    """The first joint (and its speed) needing more than JOINT_IGNORE_SPEED to go start → end in ``time``."""
    for joint in range(len(end)):
        speed = abs(end[joint] - start[joint]) / time
        if speed > JOINT_IGNORE_SPEED:
            return joint, speed
    return None


class MotionSampler:
    """Plays a motion cycle by cycle on the controller's clock (the script's jointSplineRun, §5.5).

    ``advance(budget)`` moves ``budget`` seconds of motion time along (one cycle × time scaling) and
    updates ``positions``; a motion always ends on a cycle, with its exact end position. With
    ``slow_down_at_end`` (the last spline segment) the motion time slows near the end when the path is
    too fast to stop within the script's deceleration budget, following the path to rest.
    """

    __slots__ = (
        "_scaling",
        "_slow_down",
        "_slowing",
        "_slowing_time",
        "done",
        "elapsed",
        "motion",
        "positions",
        "step_time",
    )

    def __init__(self, motion: Motion, step_time: float, *, slow_down_at_end: bool = False) -> None:
        self.motion = motion
        self.step_time = step_time
        self.elapsed = 0.0
        self.positions = motion.position(0.0)
        self.done = motion.duration <= 0
        self._slow_down = slow_down_at_end
        self._slowing = False
        self._slowing_time = 0.0
        self._scaling = 1.0

    def advance(self, budget: float) -> bool:
        """Advance ``budget`` s of motion time; True once the motion has reached its end."""
        if self.done:
            return True
        if budget <= 0.0:
            return False  # the arm cannot move (or the slider is at 0): the motion waits
        motion = self.motion
        left = motion.duration - self.elapsed
        if self._slow_down:
            step = self.step_time
            if not self._slowing and step < left <= SLOW_DOWN_WINDOW_S:
                # peek one step ahead: could the arm still stop from there within the budget?
                spare = SLOW_DOWN_WINDOW_S - (left - step)
                allowed = MAX_JOINT_SPEED - spare * SLOW_DOWN_DECELERATION
                if any(abs(v) > allowed for v in motion.velocity(self.elapsed + step)):
                    self._slowing = True
                    self._slowing_time = left + step
            if self._slowing:
                if left >= SLOW_DOWN_END_S:
                    self._scaling = left / self._slowing_time
                    self.elapsed += budget * self._scaling
                    self.positions = motion.position(self.elapsed)
                    return False
                self._scaling = 0.0
                return self._finish()
        if left <= budget + TIME_EPSILON_S:
            return self._finish()
        self.elapsed += budget
        self.positions = motion.position(self.elapsed)
        return False

    def _finish(self) -> bool:
        self.elapsed = self.motion.duration
        self.positions = self.motion.position(self.elapsed)
        self.done = True
        return True

    def end_velocity(self) -> list[float]:
        """The commanded velocity at the end (zero if the motion slowed down to rest)."""
        return [v * self._scaling for v in self.motion.velocity(self.motion.duration)]


# -- the executor -----------------------------------------------------------------------------------------


class _Servo(enum.IntEnum):
    """The servo thread's setpoint state (the script's cmd_servo_state)."""

    UNINITIALIZED = -1  # no setpoint yet: sync()
    IDLE = 0  # no new setpoint this cycle: extrapolate
    RUNNING = 1  # a new setpoint arrived


class _LinkClosed(Exception):
    """The peer closed a socket we were reading."""


@dataclass(slots=True)
class _Link:
    """One connected callback socket."""

    reader: asyncio.StreamReader
    writer: asyncio.StreamWriter

    def write(self, data: bytes) -> None:
        """Queue bytes unless the socket is closing (a dead socket's write is dropped, as socket_send is)."""
        if data and not self.writer.is_closing():
            self.writer.write(data)


@dataclass(slots=True)
class _Execution:
    """State of the trajectory thread (§5.5)."""

    was_streaming: bool
    result: TrajectoryResultCode = TrajectoryResultCode.SUCCESS
    moving: bool = False
    """The last spline segment left the arm moving: the next point must come within one step."""
    first: bool = True
    sampler: MotionSampler | None = None
    waited: bool = False
    """One cycle of the one-step wait has passed."""
    deadline: float | None = None
    """time.monotonic() at which the 0.5 s wait for a point ends (a socket timeout: wall-clock time)."""
    awaiting_cleanup: bool = False


class ProgramRunner:
    """Runs one External Control program against a FakeArm (see the module docstring for the model).

    ``on_event(kind, text)`` receives what the controller reports on the primary interface: kind
    ``"runtime"`` for runtime-exception-like reports, ``"text"`` for textmsg/popup-like ones. It must
    not raise. Script-command effects land on the arm (payload, TCP, gravity, tool voltage, force mode)
    or, where the arm has no field, on this object (``ft_sensor_zeroed``, ``ft_rtde_input`` …).
    """

    def __init__(
        self,
        arm: FakeArm,
        program_text: str,
        *,
        step_time: float,
        name: str = "externalControl",
        on_event: Callable[[str, str], None] | None = None,
        local_address: str | None = None,
        poll_reverse: bool = False,
    ) -> None:
        self.arm = arm
        self.local_address = local_address
        """The robot's own address: its connections come from there, as a real robot's do."""
        self.polls_reverse = poll_reverse
        """Read the reverse socket only in ``poll()``, once per controller cycle, instead of waking for
        every frame (the controller must call ``poll()`` each cycle; see ``poll``)."""
        self.program_text = program_text
        self.step_time = step_time
        self.name = name
        self._on_event = on_event
        # what script commands set where the arm has no field
        self.ft_sensor_zeroed = 0
        """How many ZERO_FTSENSOR commands arrived."""
        self.ft_rtde_input: sc.FtRtdeInputEnable | None = None
        self.force_mode_parameters: sc.StartForceMode | None = None
        self.tool_contact_armed = False
        self.friction_compensation = True
        """Legacy friction compensation of torque mode (the script's default: on)."""
        self.viscous_scale = list(DEFAULT_VISCOUS_SCALE)
        self.coulomb_scale = list(DEFAULT_COULOMB_SCALE)
        self.payload_transition_time = 0.0
        self.command_log: deque[sc.ScriptCommand | sc.UnknownScriptCommand] = deque(maxlen=COMMAND_LOG_LENGTH)
        # program state
        self._mode: int = ControlMode.UNINITIALIZED
        self._started = False
        self._finished = False
        self._fail_reason: str | None = None
        self._links: dict[str, _Link] = {}
        self._tasks: list[asyncio.Task[None]] = []
        self._reverse_codec = ReverseConnection(Side.ROBOT)
        self._reverse_events: deque[ReverseEvent] = deque()
        self._reverse_sock: socket.socket | None = None
        """Poll mode: our own handle on the reverse socket (its transport never reads)."""
        self._reverse_waiter: asyncio.Future[None] | None = None
        self._reverse_deadline: float | None = None
        self._reverse_eof = False
        self._violations = 0
        self._violation_log_every = max(1, round(VIOLATION_LOG_PERIOD_S / step_time))
        # servo thread
        self._servo_state = _Servo.UNINITIALIZED
        self._servo_q = list(arm.q)
        self._servo_qd = [0.0] * JOINTS
        """rad/s: the setpoint's rate, at which a missing setpoint is extrapolated."""
        self._servo_frame = list(arm.q)
        """The last accepted setpoint as the daemon sent it (never an extrapolated one)."""
        self._servo_cycles = 0
        """Servo cycles run since that setpoint came."""
        # trajectory thread and its socket buffer
        self._trajectory: _Execution | None = None
        self._trajectory_codec = TrajectoryPointConnection(Side.ROBOT)
        self._points: deque[TrajectoryPointEvent] = deque()
        self._points_closed = False
        self._points_arrived = asyncio.Event()
        self._points_space = asyncio.Event()
        self._points_left = 0
        self._streaming = False
        self._cleanup: asyncio.Task[None] | None = None
        self._spline_qd = [0.0] * JOINTS
        self._spline_qdd = [0.0] * JOINTS

    # ---- public state ----------------------------------------------------------------------------------

    @property
    def control_mode(self) -> int:
        """The script's control_mode (a ControlMode value, or whatever unknown mode the daemon sent)."""
        return self._mode

    @property
    def trajectory_running(self) -> bool:
        """True while the trajectory thread runs (from START/STREAM_START until its result is sent)."""
        return self._trajectory is not None

    # ---- the main loop ---------------------------------------------------------------------------------

    async def run(self) -> str:
        """Connect back to the daemon and execute the program; returns why it ended.

        Results: ``REASON_STOPPED``, ``REASON_TIMED_OUT``, ``REASON_CLOSED``, a connection failure or a
        program/protocol error (each also reported through ``on_event``). Cancelling stops the arm
        (stopj) and closes every socket.
        """
        if self._started:
            raise RuntimeError("a ProgramRunner runs once")
        self._started = True
        try:
            try:
                sockets = find_callback_sockets(self.program_text)
            except ProgramError as err:
                self._emit(EVENT_RUNTIME, err.reason)
                return err.reason
            failure = await self._connect(sockets)
            if failure is not None:
                return failure
            if self.polls_reverse:
                self._start_polling(self._links[REVERSE_SOCKET])
            self._emit(EVENT_TEXT, "ExternalControl: External control active")
            self._spawn(self._serve_script_commands(self._links[SCRIPT_COMMAND_SOCKET]))
            self._spawn(self._read_points(self._links[TRAJECTORY_SOCKET]))
            return await self._main_loop()
        except asyncio.CancelledError:
            self._halt_threads()
            raise
        finally:
            await self._close()

    async def _connect(self, sockets: CallbackSockets) -> str | None:
        """Dial the three sockets in the script's order; the failure reason, or None when all connected."""
        endpoints = {
            TRAJECTORY_SOCKET: sockets.trajectory,
            SCRIPT_COMMAND_SOCKET: sockets.script_command,
            REVERSE_SOCKET: sockets.reverse,
        }
        for name in CONNECT_ORDER:
            link = await self._open_with_retry(endpoints[name])
            if link is None:
                # A real controller closes what it opened and shows a blocking popup whose "Continue"
                # retries; the fake ends the program (run() closes the opened sockets) and reports the
                # popup's content instead.
                summary = ", ".join(
                    f"{other} ({endpoints[other].host}:{endpoints[other].port}) connected: "
                    f"{other in self._links}"
                    for other in CONNECT_ORDER
                )
                self._emit(
                    EVENT_TEXT,
                    f"Error connecting to remote: {summary}. Please check that the external control end "
                    f"at {endpoints[name].host} is running correctly.",
                )
                return f"could not connect: {summary}"
            self._links[name] = link
            self._emit(EVENT_TEXT, f"Successfully connected to {name}")
        return None

    async def _open_with_retry(self, endpoint: Endpoint) -> _Link | None:
        """socket_open with the script's retries (§5.2); None when every attempt failed."""
        local = (self.local_address, 0) if self.local_address else None
        for _ in range(CONNECT_ATTEMPTS):
            try:
                async with asyncio.timeout(CONNECT_TIMEOUT_S):
                    reader, writer = await asyncio.open_connection(
                        endpoint.host, endpoint.port, local_addr=local
                    )
            except (OSError, TimeoutError):
                await asyncio.sleep(CONNECT_RETRY_DELAY_S)  # the script sleeps after every failure
                continue
            sock = writer.get_extra_info("socket")
            if sock is not None:
                with contextlib.suppress(OSError):
                    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            return _Link(reader, writer)
        return None

    async def _main_loop(self) -> str:
        timeout: float | None = None  # the first read blocks (§5.2)
        while True:
            try:
                event = await self._read_reverse(timeout)
            except TimeoutError:
                return self._halt(REASON_TIMED_OUT)
            except _LinkClosed:
                return self._halt(REASON_CLOSED)
            mode = event.mode if isinstance(event, UnknownReverseCommand) else _MODE_OF[type(event)]
            if not isinstance(event, Stopped):
                timeout = event.timeout if event.timeout > 0 else None  # ≤ 0: the next read blocks
            await self._apply(event, mode)
            if self._mode <= ControlMode.STOPPED:  # the loop runs while control_mode > MODE_STOPPED
                self._emit(EVENT_TEXT, "ExternalControl: Stopping communication and control")
                self._halt_threads()
                self._emit(EVENT_TEXT, "ExternalControl: All threads ended")
                return REASON_STOPPED

    async def _read_reverse(self, timeout: float | None) -> ReverseEvent:
        """The next reverse frame; TimeoutError after ``timeout`` s, _LinkClosed when the socket closed."""
        pending = self._reverse_events
        while not pending:
            try:
                await self._fill_reverse(timeout)
            except TimeoutError:
                # a paused program's threads are suspended: its read does not time out (real controllers
                # wait; UR's drivers send nothing while the program is paused, §6.2)
                if self.arm.runtime_state is RuntimeState.PAUSED:
                    continue
                raise
        return pending.popleft()

    async def _fill_reverse(self, timeout: float | None) -> None:
        if self._reverse_sock is not None:
            await self._wait_polled(timeout)
            return
        pending = self._reverse_events
        reader = self._links[REVERSE_SOCKET].reader
        async with asyncio.timeout(timeout):
            while not pending:
                try:
                    data = await reader.read(READ_CHUNK)
                except ConnectionError:
                    data = b""
                if not data:
                    with contextlib.suppress(RemoteProtocolError):  # a torn frame is a read failure too
                        self._reverse_codec.receive_eof()
                    raise _LinkClosed
                pending.extend(self._reverse_codec.receive_data(data))

    # ---- poll mode: the reverse socket read once per controller cycle ------------------------------------

    def _start_polling(self, link: _Link) -> None:
        sock = link.writer.get_extra_info("socket")
        if sock is None:
            self.polls_reverse = False  # no socket to poll (an unusual transport): read as usual
            return
        transport: Any = link.writer.transport
        transport.pause_reading()  # the event loop no longer wakes for reverse frames
        raw = socket.socket(fileno=os.dup(sock.fileno()))
        raw.setblocking(False)
        self._reverse_sock = raw
        # bytes the transport read before the pause (the daemon writes as soon as it accepts) are in
        # the stream reader, not the socket: they come first
        buffered: Any = getattr(link.reader, "_buffer", b"")
        if buffered:
            self._reverse_events.extend(self._reverse_codec.receive_data(bytes(buffered)))
            buffered.clear()
        if link.reader.at_eof():
            self._reverse_eof = True

    def poll(self) -> None:
        """One controller cycle's read of the reverse socket (poll mode; a no-op otherwise).

        Decodes every frame that arrived since the last cycle and wakes the main loop, which applies
        them before the cycle's ``step()`` when the controller calls ``step`` after yielding to the
        loop once; a read waiting past its timeout fails here, to the cycle (2 ms at 500 Hz).
        """
        sock = self._reverse_sock
        if sock is None or self._finished:
            return
        pending = self._reverse_events
        while not self._reverse_eof:
            try:
                data = sock.recv(READ_CHUNK)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:
                data = b""
            if not data:
                self._reverse_eof = True
                break
            try:
                pending.extend(self._reverse_codec.receive_data(data))
            except RemoteProtocolError as err:
                self._wake_reader(err)
                return
        waiter = self._reverse_waiter
        if waiter is None or waiter.done():
            return
        if pending:
            waiter.set_result(None)
        elif self._reverse_eof:
            self._wake_reader(_LinkClosed())
        elif self._reverse_deadline is not None and time.monotonic() >= self._reverse_deadline:
            self._wake_reader(TimeoutError())

    def _wake_reader(self, error: BaseException) -> None:
        waiter = self._reverse_waiter
        if waiter is not None and not waiter.done():
            waiter.set_exception(error)

    async def _wait_polled(self, timeout: float | None) -> None:
        if self._reverse_eof:
            with contextlib.suppress(RemoteProtocolError):  # a torn frame is a read failure too
                self._reverse_codec.receive_eof()
            raise _LinkClosed
        waiter = self._reverse_waiter = asyncio.get_running_loop().create_future()
        self._reverse_deadline = None if timeout is None else time.monotonic() + timeout
        try:
            await waiter
        except RemoteProtocolError:
            raise _LinkClosed from None
        finally:
            self._reverse_waiter = None
            self._reverse_deadline = None

    def _halt(self, reason: str) -> str:
        """The script's abort path (§4.2): log, end freedrive, stop every thread, stopj, halt."""
        if self._fail_reason is not None:
            reason = self._fail_reason  # we closed the socket ourselves; the cause was reported already
        else:
            self._emit(EVENT_RUNTIME, REVERSE_TIMEOUT_MESSAGE)
        self._halt_threads()
        return reason

    def _halt_threads(self) -> None:
        if self._mode == ControlMode.FREEDRIVE:
            self.arm.freedrive = False
        self._mode = ControlMode.STOPPED
        self._trajectory = None
        self._stopj()

    def _fail(self, reason: str) -> None:
        """Halt the program from a helper task: report it, then close the reverse socket to wake run()."""
        if self._fail_reason is not None or self._finished:
            return
        self._fail_reason = reason
        self._emit(EVENT_RUNTIME, reason)
        reverse = self._links.get(REVERSE_SOCKET)
        if reverse is not None:
            reverse.writer.close()
        if self._reverse_sock is not None:  # poll mode: closing the writer does not reach the reader
            self._reverse_eof = True
        self._wake_reader(_LinkClosed())

    async def _close(self) -> None:
        self._finished = True
        self._trajectory = None
        tasks = [t for t in (*self._tasks, self._cleanup) if t is not None and not t.done()]
        for task in tasks:
            task.cancel()
        if tasks:
            await asyncio.wait(tasks, timeout=CLOSE_TIMEOUT_S)
        if self._reverse_sock is not None:
            self._reverse_sock.close()
        links = list(self._links.values())
        for link in links:
            link.writer.close()
        for link in links:
            with contextlib.suppress(OSError, TimeoutError):
                async with asyncio.timeout(CLOSE_TIMEOUT_S):
                    await link.writer.wait_closed()

    def _spawn(self, coroutine: Coroutine[Any, Any, None]) -> None:
        task = asyncio.get_running_loop().create_task(coroutine)
        task.add_done_callback(self._helper_done)
        self._tasks.append(task)

    def _helper_done(self, task: asyncio.Task[None]) -> None:
        if not task.cancelled() and task.exception() is not None:
            self._fail(f"fake controller internal error: {task.exception()!r}")

    def _emit(self, kind: str, text: str) -> None:
        if self._on_event is not None:
            self._on_event(kind, text)

    def _stopj(self) -> None:
        self.arm.stop(STOPJ_DECELERATION)

    # ---- per-frame handling (§5.4) -----------------------------------------------------------------------

    async def _apply(self, event: ReverseEvent, mode: int) -> None:
        if mode != self._mode:
            await self._change_mode(mode)
        current = self._mode
        if current == ControlMode.SERVOJ:
            if isinstance(event, ServoJ):
                self._set_servo_setpoint(event.positions)
        elif current == ControlMode.SPEEDJ:
            if isinstance(event, SpeedJ) and self.arm.runtime_state not in _PAUSED:
                self.arm.speedj(event.velocities, SPEEDJ_ACCELERATION)
        elif current == ControlMode.FORWARD:
            if isinstance(event, TrajectoryControl):
                await self._trajectory_control(event)
        elif current == ControlMode.FREEDRIVE and isinstance(event, FreedriveControl):
            if event.action is FreedriveAction.START:
                self._emit(EVENT_TEXT, "Entering freedrive mode")
                self.arm.freedrive = True
            elif event.action is FreedriveAction.STOP:
                self._end_freedrive()

    async def _change_mode(self, new: int) -> None:
        old = self._mode
        if old == ControlMode.FORWARD:
            self._trajectory = None  # kill thread_trajectory: no result for what it was doing …
            if self._points_left > 0:  # … unless points were still due: those are drained and CANCELED
                self._request_cleanup()
                self._stopj()
                await self._wait_cleanup()
                self._send_result(TrajectoryResultCode.CANCELED)
        elif old == ControlMode.FREEDRIVE:
            self._end_freedrive()
        if old == ControlMode.TOOL_IN_CONTACT and self.tool_contact_armed:
            return  # the mode only changes once tool contact has been ended
        self._mode = new
        if old in _MOTION_THREAD_MODES:
            self._stopj()  # the old motion thread is joined; it ends with stopj
        if new == ControlMode.SERVOJ:
            self._servo_q = list(self.arm.q)  # the new setpoint's rate is measured from here
            self._servo_frame = list(self.arm.q)
            self._servo_cycles = 0
        elif new == ControlMode.FORWARD:
            self._stopj()
        elif new in _UNSIMULATED_MODES:
            self._emit(
                EVENT_TEXT,
                f"fake controller: {ControlMode(new).name} control is not simulated; the arm holds still",
            )
        elif new not in _KNOWN_MODES and new > ControlMode.STOPPED:
            # the script just takes the value: no thread runs, fields are not applied
            self._emit(EVENT_TEXT, f"fake controller: unknown control mode {new}; the arm holds still")

    def _end_freedrive(self) -> None:
        self._emit(EVENT_TEXT, "Leaving freedrive mode")
        self.arm.freedrive = False

    def _set_servo_setpoint(self, positions: Sequence[float]) -> None:
        """set_servo_setpoint: accept a target reachable in one step from the last command or the arm."""
        self._servo_state = _Servo.RUNNING
        step = self.step_time
        # Like the script: a target too far from the last command is still accepted when it is close to
        # where the arm is (recovery after the daemon held position); otherwise the old command stays.
        if self._target_within_limits(self._servo_q, positions, step) or self._target_within_limits(
            self.arm.q, positions, step
        ):
            # The rate of the setpoint stream, from the previous setpoint the daemon sent over the
            # cycles since (not from the extrapolated setpoint: a frame that corrects an extrapolation
            # would read as a speed spike). A real arm's target speed, which the script extrapolates
            # with, follows the stream smoothly through servoj's lookahead filter.
            previous, span = self._servo_frame, max(1, self._servo_cycles) * step
            self._servo_q = list(positions)
            self._servo_frame = list(positions)
            self._servo_qd = [(b - a) / span for a, b in zip(previous, positions, strict=True)]
            self._servo_cycles = 0

    def _target_within_limits(self, start: Sequence[float], end: Sequence[float], duration: float) -> bool:
        """targetWithinLimits (§5.4): refuse > 20 rad/s; popup once, log every 5 s, note the recovery."""
        violation = speed_violation(start, end, duration)
        if violation is None:
            if self._violations:
                self._emit(EVENT_TEXT, "Received valid command. Resuming execution.")
                self._violations = 0
            return True
        if self._violations % self._violation_log_every == 0:
            joint, speed = violation
            self._emit(
                EVENT_TEXT,
                f"Velocity {speed:.6g} required in joint {joint} to go from {start[joint]:.6g} to "
                f"{end[joint]:.6g} within {duration:.6g} seconds is exceeding the joint velocity limits. "
                "Ignoring commands until a valid command is received.",
            )
        self._violations += 1
        return False

    # ---- trajectory control (§5.5) ------------------------------------------------------------------------

    async def _trajectory_control(self, event: TrajectoryControl) -> None:
        if self._cleanup is not None and not self._cleanup.done():
            # a real controller shows this as a blocking popup; the frame is ignored either way
            self._emit(EVENT_TEXT, "Trajectory buffer cleanup in progress, new trajectory ignored")
            return
        action = event.action
        if action is TrajectoryAction.START or action is TrajectoryAction.STREAM_START:
            self._trajectory = None
            self._request_cleanup()
            await self._wait_cleanup()
            self._streaming = action is TrajectoryAction.STREAM_START
            self._points_left = STREAMING_SENTINEL if self._streaming else event.point_count
            self._trajectory = _Execution(was_streaming=self._streaming)
            self._spline_qd = [0.0] * JOINTS
            self._spline_qdd = [0.0] * JOINTS
            self._emit(EVENT_TEXT, f"Executing trajectory. Number of points: {self._points_left}")
        elif action is TrajectoryAction.STREAM_END:
            if self._streaming:  # a stray STREAM_END outside a stream must not corrupt the count
                self._points_left = event.point_count - (STREAMING_SENTINEL - self._points_left)
                self._streaming = False
        elif action is TrajectoryAction.CANCEL:
            self._emit(EVENT_TEXT, "cancel received")
            self._trajectory = None
            if self._streaming:
                self._points_left = event.point_count - (STREAMING_SENTINEL - self._points_left)
                self._streaming = False
            self._request_cleanup()
            self._stopj()
            await self._wait_cleanup()
            self._send_result(TrajectoryResultCode.CANCELED)

    def _send_result(self, code: TrajectoryResultCode) -> None:
        link = self._links.get(TRAJECTORY_SOCKET)
        if link is not None:
            self._trajectory_codec.send(TrajectoryResultMessage(code))
            link.write(self._trajectory_codec.data_to_send())

    def _request_cleanup(self) -> None:
        """request_trajectory_cleanup: drain the points still due, once at a time."""
        if self._points_left > 0 and (self._cleanup is None or self._cleanup.done()):
            self._cleanup = asyncio.get_running_loop().create_task(self._clear_points())

    async def _wait_cleanup(self) -> None:
        if self._cleanup is not None:
            await self._cleanup
            self._cleanup = None

    async def _clear_points(self) -> None:
        """clearTrajectoryPointsThread: read and drop points until none are due or none arrive in 0.5 s."""
        while self._points_left > 0:
            if await self._take_point(POINT_READ_TIMEOUT_S) is None:
                self._points_left = 0
                self._emit(
                    EVENT_TEXT,
                    "No more trajectory points in the buffer. Resetting trajectory_points_left to 0.",
                )
                break
            self._points_left -= 1
        self._emit(EVENT_TEXT, "Trajectory point buffer cleared successfully.")

    async def _take_point(self, timeout: float) -> TrajectoryPointEvent | None:
        """The next buffered point, waiting up to ``timeout`` s; None if none came or the socket closed."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout
        while not self._points:
            remaining = deadline - loop.time()
            if self._points_closed or remaining <= 0:
                return None
            self._points_arrived.clear()
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(remaining):
                    await self._points_arrived.wait()
        return self._pop_point()

    def _pop_point(self) -> TrajectoryPointEvent:
        point = self._points.popleft()
        self._points_space.set()
        return point

    async def _read_points(self, link: _Link) -> None:
        """The trajectory socket's receive buffer: decode points as they arrive, up to MAX_BUFFERED_POINTS."""
        codec = self._trajectory_codec
        try:
            while True:
                while len(self._points) >= MAX_BUFFERED_POINTS:
                    self._points_space.clear()
                    await self._points_space.wait()
                try:
                    data = await link.reader.read(READ_CHUNK)
                except ConnectionError:
                    data = b""
                if not data:
                    codec.receive_eof()
                    return
                self._points.extend(codec.receive_data(data))
                self._points_arrived.set()
        except RemoteProtocolError as err:
            self._fail(f"fake controller: bad data on {TRAJECTORY_SOCKET}: {err}")
        finally:
            self._points_closed = True  # a read on a closed socket fails at once
            self._points_arrived.set()

    # ---- script commands (§4.5) ---------------------------------------------------------------------------

    async def _serve_script_commands(self, link: _Link) -> None:
        """The script_commands thread: execute each command as it arrives; results go back on 50004."""
        codec = sc.ScriptCommandConnection(Side.ROBOT)
        try:
            while True:
                try:
                    data = await link.reader.read(READ_CHUNK)
                except ConnectionError:
                    return
                if not data:
                    return  # the script's reads would fail from now on; it does nothing with them
                for command in codec.receive_data(data):
                    if not isinstance(command, sc.ToolContactResult):  # only the daemon side receives those
                        self._execute_command(command, codec)
                link.write(codec.data_to_send())
        except RemoteProtocolError as err:
            self._fail(f"fake controller: bad data on {SCRIPT_COMMAND_SOCKET}: {err}")

    def _execute_command(
        self, command: sc.ScriptCommand | sc.UnknownScriptCommand, codec: sc.ScriptCommandConnection
    ) -> None:
        self.command_log.append(command)
        arm = self.arm
        match command:
            case sc.ZeroFtSensor():
                self.ft_sensor_zeroed += 1
            case sc.SetPayload(mass=mass, cog=cog):
                arm.payload_mass = mass
                arm.payload_cog = list(cog)
                # set_payload(m, cog) gives no inertia; the fake models a point mass (unverified what
                # a real controller reports as inertia then)
                arm.payload_inertia = [0.0] * 6
            case sc.SetTargetPayload(mass=mass, cog=cog, inertia=inertia, transition_time=transition):
                # applied at once: the fake does not model the transition a real controller blends over
                arm.payload_mass = mass
                arm.payload_cog = list(cog)
                arm.payload_inertia = list(inertia)
                self.payload_transition_time = transition
            case sc.SetToolVoltage(volts=volts):
                arm.io.tool_voltage = volts
            case sc.StartForceMode():
                arm.force_mode = True
                self.force_mode_parameters = command
            case sc.EndForceMode():
                arm.force_mode = False
                self.force_mode_parameters = None
            case sc.StartToolContact():
                self.tool_contact_armed = True  # the fake never detects a contact
            case sc.EndToolContact():
                if self._mode != ControlMode.TOOL_IN_CONTACT:
                    codec.send(sc.ToolContactResultMessage(sc.ToolContactResultCode.CANCELED))
                self.tool_contact_armed = False
            case sc.SetFrictionCompensation(enabled=enabled):
                self.friction_compensation = enabled
            case sc.SetFrictionScales(viscous=viscous, coulomb=coulomb):
                self.viscous_scale = list(viscous)
                self.coulomb_scale = list(coulomb)
            case sc.FtRtdeInputEnable():
                self.ft_rtde_input = command
            case sc.SetGravity(gravity=gravity):
                arm.gravity = list(gravity)
            case sc.SetTcpOffset(pose=pose):
                arm.tcp_offset = list(pose)
            case sc.UnknownScriptCommand(command_id=command_id):
                # the script ignores an unknown id silently; the fake says so to help debugging
                self._emit(EVENT_TEXT, f"fake controller: ignored unknown script command {command_id}")

    # ---- the controller cycle ---------------------------------------------------------------------------

    def step(self, dt: float) -> None:
        """One controller cycle of the program's threads; call before ``arm.step(dt)``."""
        if self._finished or self.arm.runtime_state in _PAUSED:
            return  # a paused program's threads do nothing
        if self._mode == ControlMode.SERVOJ:
            self._servo_step(dt)
        execution = self._trajectory
        if execution is not None:
            self._trajectory_step(execution, dt)

    def _servo_step(self, dt: float) -> None:
        """servoThread: servoj to the newest setpoint, or extrapolate when none came this cycle."""
        state = self._servo_state
        if state == _Servo.UNINITIALIZED:
            return  # sync(): nothing commanded before the first setpoint
        q = self._servo_q
        self._servo_cycles += 1
        if state == _Servo.IDLE:
            # The script extrapolates at get_target_joint_speeds(). While servoj tracks a setpoint stream
            # that is the stream's own rate (measured frame to frame in _set_servo_setpoint), which we
            # use directly: the fake arm reaches each setpoint in one cycle, so its measured speed would
            # turn every late frame into a speed spike. A real arm's target speed never exceeds its
            # joint limits: the rate is clipped to them.
            qd, vmax = self._servo_qd, self.arm.max_velocity
            for joint in range(JOINTS):
                rate, limit = qd[joint], vmax[joint]
                q[joint] += (limit if rate > limit else -limit if rate < -limit else rate) * dt
        else:
            self._servo_state = _Servo.IDLE
        self.arm.servoj(q)

    def _trajectory_step(self, execution: _Execution, dt: float) -> None:
        """trajectoryThread, one cycle: play the current motion, or fetch and start the next point."""
        arm = self.arm
        while True:
            sampler = execution.sampler
            if sampler is not None:
                # the controller's time scaling: the speed slider, and nothing while the arm cannot move
                done = sampler.advance(dt * arm.speed_slider if arm.can_move else 0.0)
                arm.servoj(sampler.positions)
                if done:
                    self._motion_done(execution, sampler)
                return
            if execution.awaiting_cleanup:
                if self._cleanup is not None and not self._cleanup.done():
                    return
                execution.awaiting_cleanup = False
            if execution.result is not TrajectoryResultCode.SUCCESS or self._points_left <= 0:
                self._finish_trajectory(execution)
                return
            if self._points:
                point = self._pop_point()
            elif self._read_timed_out(execution):
                self._point_read_failed(execution)
                continue
            else:
                return  # still waiting for the point
            execution.waited = False
            execution.deadline = None
            self._points_left -= 1
            self._start_point(execution, point)
            execution.first = False

    def _read_timed_out(self, execution: _Execution) -> bool:
        """Whether the wait for the next point is over (socket closed, one step if moving, else 0.5 s)."""
        if self._points_closed:
            return True
        if execution.moving:
            if execution.waited:
                return True
            execution.waited = True
            return False
        now = time.monotonic()
        if execution.deadline is None:
            execution.deadline = now + POINT_READ_TIMEOUT_S
            return False
        return now >= execution.deadline

    def _point_read_failed(self, execution: _Execution) -> None:
        execution.waited = False
        execution.deadline = None
        execution.first = False
        self._points_left -= 1  # the script counts the failed read as a point
        if execution.was_streaming and not self._streaming and self._points_left < 0:
            # STREAM_END arrived after every streamed point had been read: a clean end, not an underrun
            self._points_left = 0
            return
        self._emit(EVENT_TEXT, "Receiving trajectory point failed!")
        execution.result = TrajectoryResultCode.FAILURE

    def _start_point(self, execution: _Execution, point: TrajectoryPointEvent) -> None:
        if isinstance(point, SplinePoint):
            self._start_spline(execution, point, is_last=self._points_left == 0)
        elif isinstance(point, MotionPoint):
            self._start_motion(execution, point)
        elif isinstance(point, UnknownTrajectoryPoint) and point.motion_type == MotionType.SPLINE:
            self._emit(EVENT_TEXT, f"Unknown spline type given: {point.ints[19]}")
            self._request_cleanup()
            self._stopj()
            execution.awaiting_cleanup = True
            execution.result = TrajectoryResultCode.FAILURE
        # an unknown motion type matches no branch of the script: the point is consumed and skipped

    def _start_spline(self, execution: _Execution, point: SplinePoint, *, is_last: bool) -> None:
        start = list(self.arm.q)  # get_joint_positions(): each segment starts where the arm is
        duration = point.segment_time
        execution.moving = False
        if duration <= 0:
            if (
                execution.first
                and duration == 0
                and math.dist(point.positions, start) < FIRST_POINT_SKIP_DISTANCE
            ):
                if point.accelerations is None:  # only the cubic branch of the script logs this
                    self._emit(EVENT_TEXT, "Ignoring first point with time 0")
                return
            self._emit(
                EVENT_TEXT,
                "Spline time shouldn't be zero as it would require infinite velocity to reach the target. "
                "Canceling motion.",
            )
            execution.result = TrajectoryResultCode.CANCELED
            return
        if not self._target_within_limits(start, point.positions, duration):
            execution.result = TrajectoryResultCode.CANCELED
            return
        velocities = point.velocities if point.velocities is not None else (0.0,) * JOINTS
        if point.accelerations is None:
            segment = cubic_segment(start, self._spline_qd, point.positions, velocities, duration)
        else:
            segment = quintic_segment(
                start,
                self._spline_qd,
                self._spline_qdd,
                point.positions,
                velocities,
                point.accelerations,
                duration,
            )
        execution.sampler = MotionSampler(segment, self.step_time, slow_down_at_end=is_last)
        execution.moving = not is_last

    def _start_motion(self, execution: _Execution, point: MotionPoint) -> None:
        kind = point.motion_type
        if kind is MotionType.MOVEJ:
            velocity, acceleration, duration = point.velocity, point.acceleration, point.duration
        elif kind is MotionType.OPTIMOVEJ:
            # optimovej's v and a are fractions of the joint limits; it takes no duration (§4.4)
            velocity = point.velocity * min(self.arm.max_velocity)
            acceleration = point.acceleration * min(j.max_acceleration for j in self.arm.model.joints)
            duration = 0.0
        else:
            self._emit(
                EVENT_TEXT,
                f"fake controller: {kind.name} needs inverse kinematics, which the fake does not simulate; "
                "trajectory failed",
            )
            execution.result = TrajectoryResultCode.FAILURE
            return
        try:
            move = joint_move(
                self.arm.q, point.target, velocity=velocity, acceleration=acceleration, duration=duration
            )
        except ValueError as err:
            self._emit(EVENT_TEXT, f"fake controller: {kind.name}: {err}; trajectory failed")
            execution.result = TrajectoryResultCode.FAILURE
            return
        execution.sampler = MotionSampler(move, self.step_time)

    def _motion_done(self, execution: _Execution, sampler: MotionSampler) -> None:
        """Remember the end state the next spline segment starts from (zero after a movej)."""
        execution.sampler = None
        motion = sampler.motion
        if isinstance(motion, SplineSegment):
            self._spline_qd = sampler.end_velocity()
            # the script resets spline_qdd after a cubic segment; a quintic hands on its end acceleration
            self._spline_qdd = motion.acceleration(motion.duration) if motion.quintic else [0.0] * JOINTS
        else:
            self._spline_qd = [0.0] * JOINTS
            self._spline_qdd = [0.0] * JOINTS

    def _finish_trajectory(self, execution: _Execution) -> None:
        """The trajectory thread's end: stopj, then the result on the trajectory socket."""
        self._trajectory = None
        self._stopj()
        self._send_result(execution.result)
        self._emit(EVENT_TEXT, f"Trajectory finished with result {execution.result.name}")
