"""The fake controller's robot: joint motion, speed slider, IO, and its life (power, brakes, safety stops).

Pure: no asyncio, no clock. ``step(dt)`` advances the simulation one controller cycle; every
command is a method that returns a refusal reason (or None) the way the real controller would
refuse it (e.g. brake release while powered off). Joint motion follows the active motion mode
(servoj target, speedj velocity, a ``Motion`` of fakeur/motion.py played on the program's time, or a
stop with a given deceleration), always within the model's joint velocity limits; a command outside
the joint position limits triggers a protective stop as on a real arm.

A played motion advances ``dt × speed slider × speed scaling`` of program time per cycle (nothing while
the arm cannot move): the controller's time scaling. When it is over and no new motion replaced it, the
arm stops with the motion's deceleration (a speedj or servoj that is not renewed decelerates to rest).

Pausing a program (PLAYING → PAUSING → PAUSED) ramps the speed scaling to 0: the motion being played
goes on along its path with time slowed to a stop, decelerating within the joint limits. Resuming
(PAUSED → PLAYING) ramps it back to 1 the same way. The controller steps the program while it plays
or pauses, never while it is PAUSED.

What the arm touches (walls, a push on the tool: ``surroundings``, fakeur/contact.py) is stepped after
the motion: it makes ``tcp_force``, moves the compliant axes in force mode and the free ones in
freedrive, and protective-stops the arm when a wall pushes back harder than the force limit. Without
surroundings (None) the arm moves in free air and the step costs one attribute check.

The arm's life (power, brakes, safety stops, the program's run state and the status bits) is its
``life`` (``ArmLife``, fakeur/life.py). Its modes and commands are on the arm too, as every user of
the arm calls them (``arm.robot_mode``, ``arm.power_on()``); the arm halts or stops its motion when
the life says it cannot move, and offers the life the motion side of each change (``halt``,
``set_time_scaling``, ``slow_to_rest``, ``speed_up``). Its flange and TCP poses come from
fakeur/pose.py (``TcpPoses``).
"""

from __future__ import annotations

import enum
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from urdaemon.description.frames import Pose
from urdaemon.description.kinematics import DhKinematics
from urdaemon.description.urmodels import DhParameters, UrModel
from urdaemon.fakeur.life import (
    BOOT_TIME_S,
    BRAKE_RELEASE_TIME_S,
    EMERGENCY_STOP_DECELERATION,
    PROTECTIVE_STOP_DECELERATION,
    ArmLife,
    RuntimeState,
)
from urdaemon.fakeur.motion import (
    TIME_EPSILON_S,
    LinearStop,
    Motion,
    ScalingRamp,
    leading_stop_time,
)
from urdaemon.fakeur.pose import TcpPoses
from urdaemon.model import RobotMode, SafetyMode
from urdaemon.urscript import SPEEDJ_ACCELERATION

if TYPE_CHECKING:
    from urdaemon.description.ik import UrKinematics
    from urdaemon.fakeur.contact import Surroundings

__all__ = [
    "BOOT_TIME_S",
    "BRAKE_RELEASE_TIME_S",
    "EMERGENCY_STOP_DECELERATION",
    "HISTORY_STEPS",
    "PAUSE_ACCELERATION_SHARE",
    "PROTECTIVE_STOP_DECELERATION",
    "ArmLife",
    "FakeArm",
    "IoState",
    "MotionMode",
    "RuntimeState",
]

HISTORY_STEPS = 1000
"""Cycles of actual joint positions kept for ``get_actual_joint_positions_history``."""
ACCELERATION_STEP_S = 1e-5
"""s of program time: the backward difference over which a motion's acceleration at its end is taken."""
_HOME = (0.0, -1.57, 1.57, -1.57, -1.57, 0.0)
"""rad: the joints of an arm made without initial positions."""
PAUSE_ACCELERATION_SHARE = 0.5
"""The share of each joint's acceleration limit that the speed scaling's ramp may use when the
controller pauses or resumes a program (the motion's own acceleration comes on top, scaled down)."""


class MotionMode(enum.Enum):
    """What drives the joints this cycle."""

    HOLD = "hold"
    SERVO = "servo"
    SPEED = "speed"
    STOP = "stop"
    PLAY = "play"


@dataclass
class IoState:
    """Controller IO as RTDE reports it."""

    digital_out: int = 0
    """Standard digital outputs 0–7 (bits 0–7) and configurable 0–7 (bits 8–15), tool 0–1 (bits 16–17)."""
    digital_in: int = 0
    analog_out: list[float] = field(default_factory=lambda: [0.0, 0.0])
    analog_out_types: int = 0
    """Bit 2: output 0 is voltage, bit 3: output 1 (RTDE ``analog_io_types``)."""
    analog_in: list[float] = field(default_factory=lambda: [0.0, 0.0])
    tool_analog_in: list[float] = field(default_factory=lambda: [0.0, 0.0])
    tool_voltage: int = 0
    registers_int: dict[int, int] = field(default_factory=dict)
    registers_double: dict[int, float] = field(default_factory=dict)
    registers_bit: dict[int, bool] = field(default_factory=dict)
    flags: int = 0
    """The 32 program flags (``set_flag``): internal outputs that keep their value between programs."""


class FakeArm:
    """One simulated UR arm."""

    def __init__(
        self,
        model: UrModel,
        dh: DhParameters,
        *,
        initial_positions: Sequence[float] | None = None,
        powered: bool = False,
    ) -> None:
        self.model = model
        self.dh = dh
        self.kinematics = DhKinematics(dh)
        self.q = list(initial_positions if initial_positions is not None else _HOME)
        self.qd = [0.0] * 6
        self.qdd = [0.0] * 6
        self.current = [0.0] * 6
        self.max_velocity = [j.max_velocity for j in model.joints]
        self.max_acceleration = [j.max_acceleration for j in model.joints]
        self.min_position = [
            j.min_position if j.min_position is not None else -math.inf for j in model.joints
        ]
        self.max_position = [j.max_position if j.max_position is not None else math.inf for j in model.joints]
        self.timestamp = 0.0
        """Controller time since boot (s), RTDE ``timestamp``."""
        self._poses = TcpPoses(self.kinematics)
        """The flange and TCP poses, each kept for the joint values it is for (fakeur/pose.py)."""
        self.speed_slider = 1.0
        """RTDE ``target_speed_fraction``."""
        self.speed_scaling = 1.0
        """RTDE ``speed_scaling``: the controller's own scaling (1 unless stopping or paused; ramped
        while the program pauses and resumes)."""
        self.io = IoState()
        self.payload_mass = 0.0
        self.payload_cog = [0.0, 0.0, 0.0]
        self.payload_inertia = [0.0] * 6
        self.tcp_offset = [0.0] * 6
        self.gravity = [0.0, 0.0, 9.82]
        self.tcp_force = [0.0] * 6
        """N, N·m in the base frame: the wrench measured at the TCP (RTDE ``actual_TCP_force``)."""
        self.force_mode = False
        self.freedrive = False
        self.surroundings: Surroundings | None = None
        """Walls and a push on the tool (fakeur/contact.py), stepped after the motion; None: free air."""
        self.remote_control = True
        self._init_motion()
        life = self.life = ArmLife(self, powered=powered)
        """Power, brakes, safety stops and the program's run state (fakeur/life.py)."""
        # the life's commands, called on the arm as its users always have
        self.power_on = life.power_on
        self.power_off = life.power_off
        self.brake_release = life.brake_release
        self.protective_stop = life.protective_stop
        self.unlock_protective_stop = life.unlock_protective_stop
        self.emergency_stop = life.emergency_stop
        self.release_emergency_stop = life.release_emergency_stop
        self.start_program = life.start_program
        self.pause_program = life.pause_program
        self.resume_program = life.resume_program
        self.stop_program = life.stop_program

    @property
    def robot_mode(self) -> RobotMode:
        """The life's robot mode (``life.robot_mode``)."""
        return self.life.robot_mode

    @property
    def safety_mode(self) -> SafetyMode:
        """The life's safety mode (``life.safety_mode``)."""
        return self.life.safety_mode

    @property
    def runtime_state(self) -> RuntimeState:
        """The life's program run state, RTDE ``runtime_state`` (``life.runtime_state``)."""
        return self.life.runtime_state

    @property
    def program_running(self) -> bool:
        """RTDE robot_status_bits bit 1 (``life.program_running``)."""
        return self.life.program_running

    def _init_motion(self) -> None:
        """The motion state at boot: holding still at ``q``, no motion played, a full history."""
        self._mode = MotionMode.HOLD
        self._scaling = ScalingRamp()
        """The time scaling of played motions that pausing and resuming ramp."""
        self._servo_target: list[float] | None = None
        self._speed_target = [0.0] * 6
        self._acceleration = PROTECTIVE_STOP_DECELERATION
        """rad/s²: the speedj acceleration or the stop's deceleration (set by ``speedj`` and ``stop``)."""
        self._motion: Motion | None = None
        self._played: Motion | None = None
        self._ik: UrKinematics | None = None
        self._motion_time = 0.0
        self._motion_stop = PROTECTIVE_STOP_DECELERATION
        self._target_q = list(self.q)
        self._target_qd = [0.0] * 6
        self._program_qd = [0.0] * 6
        """rad/s of program time: the played motion's velocity before the speed slider's scaling."""
        self._history = [list(self.q) for _ in range(HISTORY_STEPS)]
        self._history_at = 0
        self._last_dt = 0.002
        """s: the last cycle's time (a pause or resume ramp shorter than one cycle happens at once)."""
        self._carry = 0.0
        """s of program time: how far the last cycle went on past the end of the motion it ended."""

    # ---- motion commands -------------------------------------------------------------------------

    def servoj(self, target: Sequence[float]) -> None:
        """Track joint position ``target`` (reached as fast as the velocity limits allow)."""
        if not self.life.can_move:
            return
        self._mode = MotionMode.SERVO
        self._servo_target = [float(v) for v in target]

    def speedj(self, velocities: Sequence[float], acceleration: float = SPEEDJ_ACCELERATION) -> None:
        """Accelerate toward joint ``velocities`` (rad/s) at ``acceleration`` (rad/s²). URScript's speedj
        has no default acceleration; without one this takes our control script's (urscript.py)."""
        if not self.life.can_move:
            return
        self._mode = MotionMode.SPEED
        self._speed_target = [float(v) for v in velocities]
        self._acceleration = max(float(acceleration), 1e-6)

    def stop(self, deceleration: float) -> None:
        """Decelerate every joint to rest at ``deceleration`` (rad/s²)."""
        self._mode = MotionMode.STOP
        self._speed_target = [0.0] * 6
        self._acceleration = max(float(deceleration), 1e-6)
        self._servo_target = None
        self._motion = None
        self._played = None
        self._carry = 0.0

    def play(self, motion: Motion, stop_deceleration: float) -> bool:
        """Follow ``motion`` from its start on the program's time; False (ignored) if the arm cannot move.

        Once it is over, unless another motion replaced it, the arm stops from the motion's end velocity
        at ``stop_deceleration`` (leading joint, rad/s²), along the path it was on."""
        if not self.life.can_move:
            return False
        self._mode = MotionMode.PLAY
        self._motion = self._played = motion
        self._motion_time = self._carry  # program time the arm already went on past the last motion
        self._carry = 0.0
        self._motion_stop = max(float(stop_deceleration), 1e-6)
        self._servo_target = None
        return True

    @property
    def motion(self) -> Motion | None:
        """The motion being played (None when the arm holds, stops, or follows servoj/speedj)."""
        return self._motion if self._mode is MotionMode.PLAY else None

    @property
    def played(self) -> Motion | None:
        """The last motion given to ``play``, until a stop took the arm (it stays once played out)."""
        return self._played

    @property
    def motion_time(self) -> float:
        """s: program time played of ``motion``."""
        return self._motion_time

    @property
    def commanded_velocity(self) -> list[float]:
        """rad/s of program time: the velocity the arm is driven at (a new motion starts from it)."""
        if self._mode is MotionMode.PLAY:
            return list(self._program_qd)
        if self._mode is MotionMode.HOLD:
            return [0.0] * 6
        return list(self.qd)

    @property
    def target_q(self) -> list[float]:
        """rad: the joint positions being commanded (the actual ones unless a motion is played)."""
        return self._target_q if self._mode is MotionMode.PLAY else self.q

    @property
    def target_qd(self) -> list[float]:
        """rad/s: the joint velocities being commanded."""
        return self._target_qd if self._mode is MotionMode.PLAY else self.qd

    @property
    def steady(self) -> bool:
        """True when the arm is fully at rest and nothing commands motion (``is_steady()``)."""
        return self._mode is MotionMode.HOLD and not any(self.qd)

    def history(self, steps: int) -> list[float]:
        """rad: the actual joint positions ``steps`` cycles ago (0 = now), at most HISTORY_STEPS - 1."""
        steps = max(0, min(int(steps), HISTORY_STEPS - 1))
        return list(self._history[(self._history_at - steps) % HISTORY_STEPS])

    def hold(self) -> None:
        """Stand still (no motion thread)."""
        self.stop(PROTECTIVE_STOP_DECELERATION)

    # ---- the motion side of the life's changes (fakeur/life.py) -----------------------------------

    def halt(self) -> None:
        """Stand still at once, nothing played (power is cut: the brakes hold the joints)."""
        self._mode = MotionMode.HOLD
        self._servo_target = None
        self._motion = self._played = None
        self.qd = [0.0] * 6
        self.qdd = [0.0] * 6

    def set_time_scaling(self, scale: float) -> None:
        """Set the played motions' time scaling to ``scale`` at once (a program starts or stops)."""
        self._scaling.set(scale)

    def slow_to_rest(self) -> bool:
        """Slow down for a pause; True while a played motion still slows down along its path.

        A played motion's time scaling ramps to 0 within ``PAUSE_ACCELERATION_SHARE`` of the joints'
        acceleration limits; any other motion stops at once as a protective stop does."""
        if self._mode is MotionMode.PLAY:
            self._scaling.ramp_to(
                0.0, self.qd, self.max_acceleration, PAUSE_ACCELERATION_SHARE, self._last_dt
            )
            return self._scaling.scale != 0.0
        if self._mode is not MotionMode.HOLD:
            self.stop(PROTECTIVE_STOP_DECELERATION)
        self._scaling.set(0.0)
        return False

    def speed_up(self) -> None:
        """Resume: a paused motion's time scaling ramps back to 1 the way it came down."""
        slider = self.speed_slider
        velocity = [v * slider for v in self._program_qd] if self._mode is MotionMode.PLAY else [0.0] * 6
        self._scaling.ramp_to(1.0, velocity, self.max_acceleration, PAUSE_ACCELERATION_SHARE, self._last_dt)

    # ---- simulation ------------------------------------------------------------------------------

    def step(self, dt: float) -> None:
        """Advance one controller cycle of ``dt`` seconds."""
        self.timestamp += dt
        self._last_dt = dt
        self._carry = 0.0
        life = self.life
        life.advance(self.timestamp)
        if life.robot_mode is not RobotMode.RUNNING and self._mode is not MotionMode.STOP:
            self.halt()
        if (
            life.safety_mode is not SafetyMode.NORMAL
            and life.safety_mode is not SafetyMode.REDUCED
            and self._mode is not MotionMode.STOP
        ):
            self.stop(PROTECTIVE_STOP_DECELERATION)
        runtime = life.runtime_state
        scaling = self._scaling
        scale = scaling.scale if scaling.settled else scaling.step(dt)
        playing = runtime is RuntimeState.PLAYING or runtime is RuntimeState.PAUSING
        self.speed_scaling = scale if playing else 0.0
        mode = self._mode
        if mode is MotionMode.PLAY:
            self._step_play(dt, scale)
        elif mode is MotionMode.SERVO and self._servo_target is not None:
            self._step_servo(dt, self._servo_target)
        elif mode is MotionMode.SPEED or mode is MotionMode.STOP:
            self._step_speed(dt, self._speed_target, self._acceleration)
            if mode is MotionMode.STOP and not any(self.qd):
                self._mode = MotionMode.HOLD
        else:
            self.qd = [0.0] * 6
            self.qdd = [0.0] * 6
        if runtime is RuntimeState.PAUSING and scale == 0.0:
            life.came_to_rest()  # the scaling has come to 0: at rest on the path
        surroundings = self.surroundings
        if surroundings is not None:
            surroundings.step(self, dt)
        self._check_limits()
        at = (self._history_at + 1) % HISTORY_STEPS
        self._history[at][:] = self.q
        self._history_at = at

    def _step_play(self, dt: float, scale: float) -> None:
        motion = self._motion
        if motion is None:
            return
        elapsed = self._motion_time
        if elapsed >= motion.duration - TIME_EPSILON_S:
            # over, and nothing replaced it: stop along the path from the commanded velocity
            velocity = self._program_qd
            self._motion = LinearStop(self.q, velocity, leading_stop_time(velocity, self._motion_stop))
            self._motion_time = elapsed = 0.0
            motion = self._motion
            if motion.duration <= 0:
                self._mode = MotionMode.HOLD
                self._motion = None
                self._target_qd = [0.0] * 6
                self._program_qd = [0.0] * 6
                self.qd = [0.0] * 6
                self.qdd = [0.0] * 6
                return
        slider = self.speed_slider * scale
        budget = dt * slider
        wanted = elapsed + budget
        elapsed = min(wanted, motion.duration)
        self._motion_time = elapsed
        target = motion.position(elapsed)
        self._target_q = target
        velocity = self._program_qd = motion.velocity(elapsed)
        self._target_qd = [v * slider for v in velocity]
        goal = target
        carry = wanted - elapsed
        if carry > TIME_EPSILON_S and any(velocity):
            # the motion ended within this cycle (its time is not a whole number of cycles at this
            # scaling): the arm goes on at its end velocity for the rest of the cycle, and a motion
            # played next starts that far into its own time (``play``), so a stream of short motions
            # (one speedj per cycle) moves smoothly at any scaling. The target stays the motion's end.
            self._carry = carry
            goal = _went_on(motion, target, velocity, carry)
        if self._step_servo(dt, goal):
            # the motion asks more than the joints can do: what is commanded is what the arm does
            # (the controller's target speeds never exceed the joint limits), and a following
            # motion or stop starts from that
            self._target_q = list(self.q)
            self._target_qd = list(self.qd)
            if slider > 0:
                self._program_qd = [v / slider for v in self.qd]
            velocity = self._program_qd
        if elapsed >= motion.duration - TIME_EPSILON_S and not any(velocity):
            q = self.q
            if all(abs(q[i] - target[i]) < 1e-9 for i in range(6)):
                # played out at rest: the arm stands on its target from here on
                q[:] = target
                self._mode = MotionMode.HOLD
                self._motion = None
                self.qd = [0.0] * 6

    def _step_servo(self, dt: float, target: list[float]) -> bool:
        """Move towards ``target`` within the velocity limits; True if a limit held a joint back."""
        q, qd, vmax = self.q, self.qd, self.max_velocity
        limited = False
        for i in range(6):
            want = (target[i] - q[i]) / dt
            limit = vmax[i]
            if want > limit:
                v, limited = limit, True
            elif want < -limit:
                v, limited = -limit, True
            else:
                v = want
            self.qdd[i] = (v - qd[i]) / dt
            qd[i] = v
            q[i] += v * dt
        return limited

    def _step_speed(self, dt: float, target: list[float], acceleration: float) -> None:
        q, qd, vmax = self.q, self.qd, self.max_velocity
        dv_max = acceleration * dt
        for i in range(6):
            want = max(-vmax[i], min(vmax[i], target[i]))
            dv = max(-dv_max, min(dv_max, want - qd[i]))
            new_v = qd[i] + dv
            if abs(new_v) < 1e-12:
                new_v = 0.0
            self.qdd[i] = dv / dt
            q[i] += 0.5 * (qd[i] + new_v) * dt
            qd[i] = new_v

    def _check_limits(self) -> None:
        for i in range(6):
            if not self.min_position[i] <= self.q[i] <= self.max_position[i]:
                self.q[i] = min(max(self.q[i], self.min_position[i]), self.max_position[i])
                self.protective_stop()
                return

    # ---- derived values ----------------------------------------------------------------------------

    @property
    def ik(self) -> UrKinematics:
        """Inverse kinematics and the Jacobian on the arm's calibrated model (made on first use)."""
        solver = self._ik
        if solver is None:
            from urdaemon.description.ik import UrKinematics  # numpy: only for arms that need IK

            solver = self._ik = UrKinematics(self.model, self.dh)
        return solver

    def tcp_pose(self) -> Pose:
        """tool0 pose in the base frame as UR reports it: x, y, z and a rotation vector."""
        return self._poses.flange(self.q)

    def actual_tcp_pose(self) -> Pose:
        """The TCP pose (the flange pose with ``tcp_offset`` applied), as RTDE ``actual_TCP_pose``."""
        return self._poses.tcp(self.q, self.tcp_offset)


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
