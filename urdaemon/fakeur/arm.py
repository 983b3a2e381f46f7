"""The fake controller's robot: power and brakes, safety stops, speed slider, joint motion, IO.

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

State machine (robot mode, §6.1 of ur-protocols.md), as a real e-Series controller behaves:
POWER_OFF --power on--> BOOTING (power-up delay) --> IDLE --brake release--> RUNNING.
Power off from anywhere → POWER_OFF. A protective stop keeps the mode but stops motion until
unlocked; an emergency stop powers the arm off until released.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from urdaemon.description.frames import compose, frame_of_pose, pose_of_frame
from urdaemon.description.kinematics import DhKinematics
from urdaemon.description.urmodels import DhParameters, UrModel
from urdaemon.fakeur.motion import (
    TIME_EPSILON_S,
    LinearStop,
    Motion,
    ScalingRamp,
    leading_stop_time,
)
from urdaemon.model import RobotMode, SafetyMode

if TYPE_CHECKING:
    from urdaemon.description.ik import UrKinematics
    from urdaemon.fakeur.contact import Surroundings

__all__ = [
    "BOOT_TIME_S",
    "BRAKE_RELEASE_TIME_S",
    "HISTORY_STEPS",
    "PAUSE_ACCELERATION_SHARE",
    "PROTECTIVE_STOP_DECELERATION",
    "FakeArm",
    "IoState",
    "MotionMode",
    "RuntimeState",
]

BOOT_TIME_S = 0.5
"""Simulated time from 'power on' until the arm is IDLE (a real arm takes several seconds)."""
BRAKE_RELEASE_TIME_S = 0.3
"""Simulated time from 'brake release' until RUNNING (brakes audibly release over ~1 s on a real arm)."""
PROTECTIVE_STOP_DECELERATION = 10.0
"""Joint deceleration (rad/s²) of the category-2 stop that a protective stop performs."""
EMERGENCY_STOP_DECELERATION = 20.0
"""Joint deceleration (rad/s²) of an emergency stop before power is cut."""
SPEEDJ_DEFAULT_ACCELERATION = 40.0
"""rad/s²: the acceleration the control script passes to speedj (ur-protocols.md §5.3)."""
HISTORY_STEPS = 1000
"""Cycles of actual joint positions kept for ``get_actual_joint_positions_history``."""
ACCELERATION_STEP_S = 1e-5
"""s of program time: the backward difference over which a motion's acceleration at its end is taken."""
PAUSE_ACCELERATION_SHARE = 0.5
"""The share of each joint's acceleration limit that the speed scaling's ramp may use when the
controller pauses or resumes a program (the motion's own acceleration comes on top, scaled down)."""


class RuntimeState(enum.IntEnum):
    """RTDE ``runtime_state`` (ur-protocols.md §1.9)."""

    STOPPING = 0
    STOPPED = 1
    PLAYING = 2
    PAUSING = 3
    PAUSED = 4
    RESUMING = 5


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
        self.q = (
            list(initial_positions)
            if initial_positions is not None
            else [0.0, -1.57, 1.57, -1.57, -1.57, 0.0]
        )
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
        self._pose_cache: tuple[tuple[float, ...], tuple[float, float, float, float, float, float]] | None = (
            None
        )
        """The last ``tcp_pose()`` and the joint values it is for."""
        self._tcp_cache: tuple[Any, tuple[float, float, float, float, float, float]] | None = None
        """The last ``actual_tcp_pose()`` and the flange pose and offset it is for."""
        self.robot_mode = RobotMode.POWER_OFF
        self.safety_mode = SafetyMode.NORMAL
        self.runtime_state = RuntimeState.STOPPED
        self.speed_slider = 1.0
        """RTDE ``target_speed_fraction``."""
        self.speed_scaling = 1.0
        """RTDE ``speed_scaling``: the controller's own scaling (1 unless stopping or paused; ramped
        while the program pauses and resumes)."""
        self._scaling = ScalingRamp()
        """The time scaling of played motions that pausing and resuming ramp."""
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
        self._transition_at: float | None = None
        self._init_motion()
        if powered:
            self.robot_mode = RobotMode.RUNNING

    def _init_motion(self) -> None:
        """The motion state at boot: holding still at ``q``, no motion played, a full history."""
        self._mode = MotionMode.HOLD
        self._servo_target: list[float] | None = None
        self._speed_target = [0.0] * 6
        self._acceleration = SPEEDJ_DEFAULT_ACCELERATION
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

    # ---- power, brakes, safety -----------------------------------------------------------------

    def power_on(self) -> str | None:
        """Start powering on; a reason if refused."""
        if self.safety_mode in (SafetyMode.ROBOT_EMERGENCY_STOP, SafetyMode.SYSTEM_EMERGENCY_STOP):
            return "emergency stop active"
        if self.robot_mode is RobotMode.POWER_OFF:
            self.robot_mode = RobotMode.BOOTING
            self._transition_at = self.timestamp + BOOT_TIME_S
        return None

    def power_off(self) -> None:
        """Cut arm power (brakes engage, program stops)."""
        self._halt_motion()
        self.robot_mode = RobotMode.POWER_OFF
        self._transition_at = None
        self.stop_program()

    def brake_release(self) -> str | None:
        """Release the brakes; refused unless powered (IDLE)."""
        if self.robot_mode is RobotMode.RUNNING:
            return None
        if self.robot_mode is not RobotMode.IDLE:
            return f"robot is {self.robot_mode.name}, not IDLE"
        if self.safety_mode is not SafetyMode.NORMAL:
            return f"safety mode is {self.safety_mode.name}"
        self.robot_mode = RobotMode.POWER_ON  # releasing
        self._transition_at = self.timestamp + BRAKE_RELEASE_TIME_S
        return None

    def protective_stop(self) -> None:
        """Trigger a protective stop: motion decelerates to rest, the program pauses."""
        if self.safety_mode is SafetyMode.NORMAL or self.safety_mode is SafetyMode.REDUCED:
            self.safety_mode = SafetyMode.PROTECTIVE_STOP
            self.stop(PROTECTIVE_STOP_DECELERATION)
            if self.runtime_state in (RuntimeState.PLAYING, RuntimeState.PAUSING):
                self.runtime_state = RuntimeState.PAUSED
                self._scaling.set(0.0)

    def unlock_protective_stop(self) -> str | None:
        """Clear a protective stop; a reason if there is none to clear or it is too early."""
        if self.safety_mode is not SafetyMode.PROTECTIVE_STOP:
            return f"safety mode is {self.safety_mode.name}, not PROTECTIVE_STOP"
        if any(abs(v) > 1e-9 for v in self.qd):
            return "robot still moving"
        self.safety_mode = SafetyMode.NORMAL
        return None

    def emergency_stop(self) -> None:
        """Press the emergency stop: stop, power off, program stopped."""
        self.safety_mode = SafetyMode.ROBOT_EMERGENCY_STOP
        self.stop(EMERGENCY_STOP_DECELERATION)
        self.stop_program()
        self.robot_mode = RobotMode.POWER_OFF
        self._transition_at = None

    def release_emergency_stop(self) -> None:
        """Release the emergency stop button; the arm stays powered off."""
        if self.safety_mode in (SafetyMode.ROBOT_EMERGENCY_STOP, SafetyMode.SYSTEM_EMERGENCY_STOP):
            self.safety_mode = SafetyMode.NORMAL

    @property
    def can_move(self) -> bool:
        """True when motion commands are executed (brakes released, no safety stop)."""
        return self.robot_mode is RobotMode.RUNNING and self.safety_mode in (
            SafetyMode.NORMAL,
            SafetyMode.REDUCED,
        )

    # ---- program state (driven by the program executor and the dashboard) ------------------------

    def start_program(self) -> str | None:
        """The program starts playing; a reason if it cannot."""
        if self.robot_mode is not RobotMode.RUNNING:
            return f"robot is {self.robot_mode.name}, not RUNNING"
        if self.safety_mode not in (SafetyMode.NORMAL, SafetyMode.REDUCED):
            return f"safety mode is {self.safety_mode.name}"
        self.runtime_state = RuntimeState.PLAYING
        self._scaling.set(1.0)
        return None

    def pause_program(self) -> None:
        """Pause the program: a played motion slows down along its path (PAUSING) to rest (PAUSED).

        Any other motion (a stop, a legacy servo or speed target) stops at once as a protective stop
        does, and the program is PAUSED."""
        if self.runtime_state is not RuntimeState.PLAYING:
            return
        if self._mode is MotionMode.PLAY:
            self.runtime_state = RuntimeState.PAUSING
            self._scaling.ramp_to(
                0.0, self.qd, self.max_acceleration, PAUSE_ACCELERATION_SHARE, self._last_dt
            )
            if self._scaling.scale == 0.0:  # at rest: paused at once
                self.runtime_state = RuntimeState.PAUSED
            return
        if self._mode is not MotionMode.HOLD:
            self.stop(PROTECTIVE_STOP_DECELERATION)
        self._scaling.set(0.0)
        self.runtime_state = RuntimeState.PAUSED

    def resume_program(self) -> str | None:
        """Resume a paused program: PLAYING, the paused motion speeding up along its path."""
        if self.runtime_state is not RuntimeState.PAUSED:
            return "no paused program"
        if self.robot_mode is not RobotMode.RUNNING:
            return f"robot is {self.robot_mode.name}, not RUNNING"
        if self.safety_mode not in (SafetyMode.NORMAL, SafetyMode.REDUCED):
            return f"safety mode is {self.safety_mode.name}"
        self.runtime_state = RuntimeState.PLAYING
        slider = self.speed_slider
        velocity = [v * slider for v in self._program_qd] if self._mode is MotionMode.PLAY else [0.0] * 6
        self._scaling.ramp_to(1.0, velocity, self.max_acceleration, PAUSE_ACCELERATION_SHARE, self._last_dt)
        return None

    def stop_program(self) -> None:
        """Stop the program (motion stops)."""
        if self.runtime_state is not RuntimeState.STOPPED:
            self.stop(PROTECTIVE_STOP_DECELERATION)
            self.runtime_state = RuntimeState.STOPPED
        self._scaling.set(1.0)

    @property
    def program_running(self) -> bool:
        """RTDE robot_status_bits bit 1."""
        return self.runtime_state in (RuntimeState.PLAYING, RuntimeState.PAUSING)

    # ---- motion commands -------------------------------------------------------------------------

    def servoj(self, target: Sequence[float]) -> None:
        """Track joint position ``target`` (reached as fast as the velocity limits allow)."""
        if not self.can_move:
            return
        self._mode = MotionMode.SERVO
        self._servo_target = [float(v) for v in target]

    def speedj(self, velocities: Sequence[float], acceleration: float = SPEEDJ_DEFAULT_ACCELERATION) -> None:
        """Accelerate toward joint ``velocities`` (rad/s) at ``acceleration`` (rad/s²)."""
        if not self.can_move:
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
        if not self.can_move:
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

    def _halt_motion(self) -> None:
        self._mode = MotionMode.HOLD
        self._servo_target = None
        self._motion = self._played = None
        self.qd = [0.0] * 6
        self.qdd = [0.0] * 6

    # ---- simulation ------------------------------------------------------------------------------

    def step(self, dt: float) -> None:
        """Advance one controller cycle of ``dt`` seconds."""
        self.timestamp += dt
        self._last_dt = dt
        self._carry = 0.0
        self._advance_transitions()
        if self.robot_mode is not RobotMode.RUNNING and self._mode is not MotionMode.STOP:
            self._halt_motion()
        if (
            self.safety_mode not in (SafetyMode.NORMAL, SafetyMode.REDUCED)
            and self._mode is not MotionMode.STOP
        ):
            self.stop(PROTECTIVE_STOP_DECELERATION)
        runtime = self.runtime_state
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
        if runtime is RuntimeState.PAUSING and scale == 0.0 and self.runtime_state is RuntimeState.PAUSING:
            self.runtime_state = RuntimeState.PAUSED  # the scaling has come to 0: at rest on the path
        surroundings = self.surroundings
        if surroundings is not None:
            surroundings.step(self, dt)
        self._check_limits()
        at = (self._history_at + 1) % HISTORY_STEPS
        self._history[at][:] = self.q
        self._history_at = at

    def _advance_transitions(self) -> None:
        if self._transition_at is None or self.timestamp < self._transition_at:
            return
        self._transition_at = None
        if self.robot_mode is RobotMode.BOOTING:
            self.robot_mode = RobotMode.IDLE
        elif self.robot_mode is RobotMode.POWER_ON:
            self.robot_mode = RobotMode.RUNNING

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

    def tcp_pose(self) -> tuple[float, float, float, float, float, float]:
        """tool0 pose in the base frame as UR reports it: x, y, z and a rotation vector.

        Kept for the joint values it was computed for: one RTDE package asks for it twice (actual and
        target TCP pose) and several clients may each ask once per cycle."""
        q = tuple(self.q)
        cached = self._pose_cache
        if cached is not None and cached[0] == q:
            return cached[1]
        x, y, z, qx, qy, qz, qw = self.kinematics.tool_pose(q)
        pose = (x, y, z, *_rotation_vector(qx, qy, qz, qw))
        self._pose_cache = (q, pose)
        return pose

    def actual_tcp_pose(self) -> tuple[float, float, float, float, float, float]:
        """The TCP pose (the flange pose with ``tcp_offset`` applied), as RTDE ``actual_TCP_pose``."""
        flange = self.tcp_pose()
        offset = self.tcp_offset
        if not any(offset):
            return flange
        cached = self._tcp_cache
        key = (flange, tuple(offset))
        if cached is not None and cached[0] == key:
            return cached[1]
        pose = pose_of_frame(compose(frame_of_pose(flange), frame_of_pose(offset)))
        self._tcp_cache = (key, pose)
        return pose

    @property
    def robot_status_bits(self) -> int:
        """RTDE ``robot_status_bits``: bit 0 power on, bit 1 program running."""
        powered = self.robot_mode in (
            RobotMode.IDLE,
            RobotMode.RUNNING,
            RobotMode.POWER_ON,
            RobotMode.BACKDRIVE,
        )
        return int(powered) | (int(self.program_running) << 1)

    @property
    def safety_status_bits(self) -> int:
        """RTDE ``safety_status_bits`` (ur-protocols.md §1.9)."""
        mode = self.safety_mode
        bits = 0
        if mode is SafetyMode.NORMAL:
            bits |= 1
        if mode is SafetyMode.REDUCED:
            bits |= 1 << 1
        if mode is SafetyMode.PROTECTIVE_STOP:
            bits |= 1 << 2
        if mode is SafetyMode.SYSTEM_EMERGENCY_STOP:
            bits |= (1 << 5) | (1 << 7)
        if mode is SafetyMode.ROBOT_EMERGENCY_STOP:
            bits |= (1 << 6) | (1 << 7)
        return bits


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


def _rotation_vector(qx: float, qy: float, qz: float, qw: float) -> tuple[float, float, float]:
    """Axis-angle (rotation vector) of a unit quaternion."""
    norm = math.sqrt(qx * qx + qy * qy + qz * qz)
    if norm < 1e-12:
        return (0.0, 0.0, 0.0)
    angle = 2.0 * math.atan2(norm, qw)
    scale = angle / norm
    return (qx * scale, qy * scale, qz * scale)
