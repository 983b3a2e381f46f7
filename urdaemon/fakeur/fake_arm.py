"""The fake controller's robot: joint motion, speed slider, IO, and its life (power, brakes, safety stops).

Pure: no asyncio, no clock. ``step(dt)`` advances the simulation one controller cycle; every
command (of the arm or of its life) returns a refusal reason (or None) the way the real controller
would refuse it (e.g. brake release while powered off). Joint motion follows the active motion mode
(servoj target, speedj velocity, a ``Motion`` of fakeur/joint_motion.py or fakeur/tcp_motion.py
played on the program's time, joint torques by the arm's dynamics (``direct_torque``), or a stop with a
given deceleration), always within the model's joint velocity limits; a command outside the joint
position limits triggers a protective stop as on a real arm.

A played motion is its ``playback`` (``Playback``, fakeur/playback.py): it advances
``dt × speed slider × speed scaling`` of program time per cycle (nothing while the arm cannot move),
and says where the joints head; the arm moves them there within their velocity limits. When it is
over and no new motion replaced it, the arm stops with the motion's deceleration (a speedj or servoj
that is not renewed decelerates to rest).

Pausing a program (PLAYING → PAUSING → PAUSED) ramps the speed scaling to 0: the motion being played
goes on along its path with time slowed to a stop, decelerating within the joint limits. Resuming
(PAUSED → PLAYING) ramps it back to 1 the same way. The controller steps the program while it plays
or pauses, never while it is PAUSED.

What the arm touches (walls, a push on the tool: ``surroundings``, fakeur/contact.py) is stepped after
the motion and says what it does to the arm: the wrench the arm measures (``tcp_force``), a protective
stop when a wall pushes back harder than the force limit, and the TCP twist the compliant axes (force
mode) or the free ones (freedrive) move at, which the arm turns into joint motion. Without
surroundings (None) the arm moves in free air and the step costs one attribute check.

The arm's life (power, brakes, safety stops, the program's run state and the status bits) is its
``life`` (``ArmLife``, fakeur/life.py), a pure decider: the arm is the one writer of its motion.
What only changes the life is asked of the life (``arm.life.power_on(arm.timestamp)``); what moves
the arm too is asked of the arm (``power_off``, ``protective_stop``, ``emergency_stop``,
``unlock_protective_stop`` and the program's ``start_program``, ``pause_program``,
``resume_program``, ``stop_program``), which asks its life and does what the life's answer says
(``life.Do``). The arm halts or stops its motion when the life says it cannot move. Its modes are
readable on the arm too (``arm.robot_mode``). Its flange and TCP poses come from fakeur/pose.py
(``TcpPoses``).
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
from urdaemon.fakeur.joint_motion import Motion
from urdaemon.fakeur.life import (
    EMERGENCY_STOP_DECELERATION,
    PROTECTIVE_STOP_DECELERATION,
    ArmLife,
    Do,
    LifeStep,
)
from urdaemon.fakeur.playback import Playback
from urdaemon.fakeur.pose import TcpPoses
from urdaemon.fakeur.torque_drive import TorqueDrive, payload_of
from urdaemon.model import RobotMode, SafetyMode
from urdaemon.protocols.rtde_variables import RuntimeState
from urdaemon.urscript import SPEEDJ_ACCELERATION

if TYPE_CHECKING:
    from urdaemon.description.dynamics import Payload
    from urdaemon.description.ik import UrKinematics
    from urdaemon.fakeur.contact import Surroundings

__all__ = [
    "HISTORY_STEPS",
    "FakeArm",
    "IoState",
    "JointHistory",
    "MotionMode",
    "RuntimeState",  # defined in protocols/rtde_variables.py, kept importable here
    "arm_payload",
    "joint_torques",
]

HISTORY_STEPS = 1000
"""Cycles of actual joint positions kept for ``get_actual_joint_positions_history``."""
_HOME = (0.0, -1.57, 1.57, -1.57, -1.57, 0.0)
"""rad: the joints of an arm made without initial positions."""


class MotionMode(enum.Enum):
    """What drives the joints this cycle."""

    HOLD = "hold"
    SERVO = "servo"
    SPEED = "speed"
    STOP = "stop"
    PLAY = "play"
    TORQUE = "torque"


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


class JointHistory:
    """The actual joint positions of the last ``HISTORY_STEPS`` cycles (a ring, one row per cycle)."""

    __slots__ = ("_at", "_rows")

    def __init__(self, q: Sequence[float]) -> None:
        self._rows = [list(q) for _ in range(HISTORY_STEPS)]
        self._at = 0

    def record(self, q: Sequence[float]) -> None:
        """This cycle's joint positions."""
        at = (self._at + 1) % HISTORY_STEPS
        self._rows[at][:] = q
        self._at = at

    def ago(self, steps: int) -> list[float]:
        """rad: the actual joint positions ``steps`` cycles ago (0 = now), at most HISTORY_STEPS - 1."""
        steps = max(0, min(int(steps), HISTORY_STEPS - 1))
        return list(self._rows[(self._at - steps) % HISTORY_STEPS])


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
        self.life = ArmLife(powered=powered)
        """Power, brakes, safety stops and the program's run state (fakeur/life.py): a pure decider."""

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
        self.playback = Playback(self.q, PROTECTIVE_STOP_DECELERATION)
        """The motion a program plays, on its time, and its time scaling (fakeur/playback.py)."""
        self._servo_target: list[float] | None = None
        self._speed_target = [0.0] * 6
        self._acceleration = PROTECTIVE_STOP_DECELERATION
        """rad/s²: the speedj acceleration or the stop's deceleration (set by ``speedj`` and ``stop``)."""
        self._ik: UrKinematics | None = None
        self.drive = TorqueDrive(self.model, self.dh)  # its dynamics, direct_torque's command
        self.torques_kept: tuple[tuple[float, ...], list[float]] | None = None
        """The joint torques last computed and the state they are for (``joint_torques``)."""
        self.history = JointHistory(self.q)
        """The actual joint positions of the last ``HISTORY_STEPS`` cycles."""
        self._last_dt = 0.002
        """s: the last cycle's time (a pause or resume ramp shorter than one cycle happens at once)."""

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

    def direct_torque(self, torque: Sequence[float]) -> None:
        """Torques (N·m) on top of gravity compensation, for this cycle (fakeur/torque_drive.py)."""
        if self.life.can_move:
            self._mode = MotionMode.TORQUE
            self.drive.command(torque)
            self._servo_target = None
            self.playback.drop()

    def stop(self, deceleration: float) -> None:
        """Decelerate every joint to rest at ``deceleration`` (rad/s²)."""
        self._mode = MotionMode.STOP
        self._speed_target = [0.0] * 6
        self._acceleration = max(float(deceleration), 1e-6)
        self._servo_target = None
        self.playback.drop()

    def play(self, motion: Motion, stop_deceleration: float) -> bool:
        """Follow ``motion`` from its start on the program's time; False (ignored) if the arm cannot move.

        Once it is over, unless another motion replaced it, the arm stops from the motion's end velocity
        at ``stop_deceleration`` (leading joint, rad/s²), along the path it was on."""
        if not self.life.can_move:
            return False
        self._mode = MotionMode.PLAY
        self.playback.start(motion, stop_deceleration)
        self._servo_target = None
        return True

    @property
    def motion(self) -> Motion | None:
        """The motion being played (None when the arm holds, stops, or follows servoj/speedj)."""
        return self.playback.motion if self._mode is MotionMode.PLAY else None

    @property
    def played(self) -> Motion | None:
        """The last motion given to ``play``, until a stop took the arm (it stays once played out)."""
        return self.playback.played

    @property
    def motion_time(self) -> float:
        """s: program time played of ``motion``."""
        return self.playback.time

    @property
    def commanded_velocity(self) -> list[float]:
        """rad/s of program time: the velocity the arm is driven at (a new motion starts from it)."""
        if self._mode is MotionMode.PLAY:
            return list(self.playback.program_qd)
        if self._mode is MotionMode.HOLD:
            return [0.0] * 6
        return list(self.qd)

    @property
    def target_q(self) -> list[float]:
        """rad: the joint positions being commanded (the actual ones unless a motion is played)."""
        return self.playback.target_q if self._mode is MotionMode.PLAY else self.q

    @property
    def target_qd(self) -> list[float]:
        """rad/s: the joint velocities being commanded."""
        return self.playback.target_qd if self._mode is MotionMode.PLAY else self.qd

    @property
    def steady(self) -> bool:
        """True when the arm is fully at rest and nothing commands motion (``is_steady()``)."""
        return self._mode is MotionMode.HOLD and not any(self.qd)

    # ---- the life's commands that move the arm (fakeur/life.py) ------------------------------------

    def power_off(self) -> None:
        """Cut arm power: the arm halts (the brakes hold the joints), the program stops."""
        self._obey(self.life.power_off())

    def protective_stop(self) -> None:
        """Trigger a protective stop: motion decelerates to rest, the program pauses."""
        self._obey(self.life.protective_stop())

    def unlock_protective_stop(self) -> str | None:
        """Clear a protective stop; a reason if there is none to clear or the arm still moves."""
        return self.life.unlock_protective_stop(moving=any(abs(v) > 1e-9 for v in self.qd))

    def emergency_stop(self) -> None:
        """Press the emergency stop: the arm stops, the program is stopped, power is off."""
        self._obey(self.life.emergency_stop())

    def start_program(self) -> str | None:
        """The program starts playing; a reason if it cannot."""
        return self._obey(self.life.start_program())

    def pause_program(self) -> None:
        """Pause the program: a played motion slows down along its path (PAUSING) to rest (PAUSED).

        Any other motion (a stop, a legacy servo or speed target) stops at once as a protective stop
        does, and the program is PAUSED."""
        self._obey(self.life.pause_program())

    def resume_program(self) -> str | None:
        """Resume a paused program: PLAYING, the paused motion speeding up along its path."""
        return self._obey(self.life.resume_program())

    def stop_program(self) -> None:
        """Stop the program (motion stops). Every program stop comes through here."""
        self._obey(self.life.stop_program())

    def _obey(self, step: LifeStep) -> str | None:
        """Do what the life's answer says the motion does, in order; the answer's refusal reason."""
        for do in step.then:
            if do is Do.HALT:
                self._halt()
            elif do is Do.PROTECTIVE_STOP:
                self.stop(PROTECTIVE_STOP_DECELERATION)
            elif do is Do.EMERGENCY_STOP:
                self.stop(EMERGENCY_STOP_DECELERATION)
            elif do is Do.STOP_PROGRAM:
                self.stop_program()
            elif do is Do.FREEZE_TIME or do is Do.FULL_TIME:
                self.playback.scaling.set(0.0 if do is Do.FREEZE_TIME else 1.0)
            elif do is Do.SLOW_TO_REST:
                if not self._slow_to_rest():
                    self.life.came_to_rest()
            elif do is Do.SPEED_UP:
                self._speed_up()
        return step.refused

    def _halt(self) -> None:
        """Stand still at once, nothing played (power is cut: the brakes hold the joints)."""
        self._mode = MotionMode.HOLD
        self._servo_target = None
        self.playback.forget()
        self.qd = [0.0] * 6
        self.qdd = [0.0] * 6

    def _slow_to_rest(self) -> bool:
        """Slow down for a pause; True while a played motion still slows down along its path.

        A played motion's time scaling ramps to 0 within ``PAUSE_ACCELERATION_SHARE`` of the joints'
        acceleration limits (``Playback.pause``); any other motion stops at once as a protective stop
        does."""
        if self._mode is MotionMode.PLAY:
            return self.playback.pause(self.qd, self.max_acceleration, self._last_dt)
        if self._mode is not MotionMode.HOLD:
            self.stop(PROTECTIVE_STOP_DECELERATION)
        self.playback.scaling.set(0.0)
        return False

    def _speed_up(self) -> None:
        """Resume: a paused motion's time scaling ramps back to 1 the way it came down."""
        playing = self._mode is MotionMode.PLAY
        self.playback.resume(self.speed_slider, self.max_acceleration, self._last_dt, playing=playing)

    # ---- simulation ------------------------------------------------------------------------------

    def step(self, dt: float) -> None:
        """Advance one controller cycle of ``dt`` seconds."""
        self.timestamp += dt
        self._last_dt = dt
        playback = self.playback
        playback.next_cycle()
        life = self.life
        life.advance(self.timestamp)
        if life.robot_mode is not RobotMode.RUNNING and self._mode is not MotionMode.STOP:
            self._halt()
        if (
            life.safety_mode is not SafetyMode.NORMAL
            and life.safety_mode is not SafetyMode.REDUCED
            and self._mode is not MotionMode.STOP
        ):
            self.stop(PROTECTIVE_STOP_DECELERATION)
        runtime = life.runtime_state
        scaling = playback.scaling
        scale = scaling.scale if scaling.settled else scaling.step(dt)
        playing = runtime is RuntimeState.PLAYING or runtime is RuntimeState.PAUSING
        self.speed_scaling = scale if playing else 0.0
        mode = self._mode
        if mode is MotionMode.PLAY:
            self._step_play(dt, scale)
        elif mode is MotionMode.SERVO and self._servo_target is not None:
            self._step_servo(dt, self._servo_target)
        elif mode is MotionMode.TORQUE:
            if not self.drive.step(
                self.q, self.qd, self.qdd, self.gravity, arm_payload(self), self.max_velocity, dt
            ):
                self.stop(PROTECTIVE_STOP_DECELERATION)  # not renewed: back to position control, to rest
                self._step_speed(dt, self._speed_target, self._acceleration)
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
            self._feel(surroundings, dt)
        self._check_limits()
        self.history.record(self.q)

    def _step_play(self, dt: float, scale: float) -> None:
        playback = self.playback
        if playback.motion is None:
            return
        slider = self.speed_slider * scale
        goal = playback.advance(dt, slider, self.q)
        if goal is None:  # over, and its stop takes no time: the arm holds
            self._mode = MotionMode.HOLD
            self.qd = [0.0] * 6
            self.qdd = [0.0] * 6
            return
        if self._step_servo(dt, goal):
            playback.held_back(self.q, self.qd, slider)
        end = playback.played_out(self.q)
        if end is not None:  # played out at rest: the arm stands on its target from here on
            self.q[:] = end
            self._mode = MotionMode.HOLD
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

    def _feel(self, surroundings: Surroundings, dt: float) -> None:
        """One cycle of what the arm touches, and what it does to the arm (fakeur/contact.py)."""
        felt = surroundings.step(
            dt,
            self.actual_tcp_pose() if surroundings.walls else None,
            can_move=self.life.can_move,
            force_mode=self.force_mode,
            freedrive=self.freedrive,
        )
        if felt is None:
            return
        self.tcp_force = felt.force
        if felt.stop:
            self.protective_stop()
        if felt.twist is not None:
            _comply(self, felt.twist, dt)

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


def arm_payload(arm: FakeArm) -> Payload:
    """The payload set on ``arm`` (``set_target_payload``), as the dynamics take it."""
    return payload_of(arm.payload_mass, arm.payload_cog, arm.payload_inertia)


def joint_torques(arm: FakeArm) -> list[float]:
    """N·m: the torques ``arm``'s joints exert now, M q'' + c + g with its payload (the arm follows its
    model exactly: under direct_torque, the command plus the gravity compensation). Computed at most once
    a cycle, and not again while the arm, its payload and gravity stay as they were (an arm at rest with
    a real-time client would otherwise cost its dynamics every cycle)."""
    state = (*arm.q, *arm.qd, *arm.qdd, *arm.gravity, arm.payload_mass, *arm.payload_cog)
    state += tuple(arm.payload_inertia)
    kept = arm.torques_kept
    if kept is not None and kept[0] == state:
        return list(kept[1])
    torques = arm.drive.joint_torques(arm.timestamp, arm.q, arm.qd, arm.qdd, arm.gravity, arm_payload(arm))
    arm.torques_kept = (state, torques)
    return list(torques)


def _comply(arm: FakeArm, twist: Sequence[float], dt: float) -> None:
    """Drive the joints at the velocities that give the TCP ``twist`` (base frame), scaled down
    together into the joint velocity limits, on top of this cycle's motion."""
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
