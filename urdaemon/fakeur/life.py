"""The fake arm's life: power, brakes, safety stops and the program's run state (``ArmLife``).

One ``ArmLife`` per ``FakeArm`` (fakeur/fake_arm.py), which holds it as ``arm.life``. It owns the robot mode,
the safety mode, the RTDE ``runtime_state``, the timed transitions (booting, releasing the brakes)
and the status bits RTDE reports, and it answers each command with a refusal reason (or None) the way
a real controller refuses it (e.g. brake release while powered off).

Pure, and a decider like backends/ur/reverse_channel.py: it holds no arm and calls nothing back. A
command that only changes the life (power on, brake release, releasing the emergency stop button) is
called on the life itself, time passed in. A command that changes the arm's motion too (a stop, the
program playing, pausing or stopping) returns a :class:`LifeStep`: the refusal reason and what the
motion does (:class:`Do`, in order), which the arm, the one writer of its motion, carries out
(``FakeArm.power_off`` and the others). The arm advances the timed transitions at the start of each
cycle (``advance``) and enforces the modes on its motion.

State machine (robot mode, §6.1 of docs/protocols.md), as a real e-Series controller behaves:
POWER_OFF --power on--> BOOTING (power-up delay) --> IDLE --brake release--> RUNNING.
Power off from anywhere → POWER_OFF. A protective stop keeps the mode but stops motion until
unlocked; an emergency stop powers the arm off until released.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from urdaemon.model import RobotMode, SafetyMode
from urdaemon.protocols.rtde_variables import POWER_ON_BIT, PROGRAM_RUNNING_BIT, RuntimeState

__all__ = [
    "BOOT_TIME_S",
    "BRAKE_RELEASE_TIME_S",
    "EMERGENCY_STOP_DECELERATION",
    "PROTECTIVE_STOP_DECELERATION",
    "UNLOCK_TOO_SOON",
    "UNLOCK_WAIT_S",
    "ArmLife",
    "Do",
    "LifeStep",
    "RuntimeState",  # defined in protocols/rtde_variables.py, kept importable here
]

BOOT_TIME_S = 0.5
"""Simulated time from 'power on' until the arm is IDLE (a real arm takes several seconds)."""
BRAKE_RELEASE_TIME_S = 0.3
"""Simulated time from 'brake release' until RUNNING (brakes audibly release over ~1 s on a real arm)."""
PROTECTIVE_STOP_DECELERATION = 10.0
"""Joint deceleration (rad/s²) of the category-2 stop that a protective stop performs."""
EMERGENCY_STOP_DECELERATION = 20.0
"""Joint deceleration (rad/s²) of an emergency stop before power is cut."""
UNLOCK_WAIT_S = 5.0
"""s of controller time after a protective stop before it may be unlocked (UR's dashboard guide)."""
UNLOCK_TOO_SOON = (
    "Cannot unlock protective stop until 5s after occurrence. "
    "Always inspect cause of protective stop before unlocking"
)
"""The refusal of an unlock within UNLOCK_WAIT_S of the stop: the dashboard's reply, word for word."""

_MOVING_SAFETY = (SafetyMode.NORMAL, SafetyMode.REDUCED)
"""The safety modes in which the arm may move and a program may play."""
_EMERGENCY = (SafetyMode.ROBOT_EMERGENCY_STOP, SafetyMode.SYSTEM_EMERGENCY_STOP)
_POWERED = (RobotMode.IDLE, RobotMode.RUNNING, RobotMode.POWER_ON, RobotMode.BACKDRIVE)
"""The robot modes RTDE reports as powered on (``robot_status_bits`` bit 0)."""


class Do(enum.Enum):
    """What the arm's motion does for a change of its life (``LifeStep.then``, done in order)."""

    HALT = "stand still at once, nothing played: power is cut, the brakes hold the joints"
    PROTECTIVE_STOP = "decelerate every joint to rest at PROTECTIVE_STOP_DECELERATION"
    EMERGENCY_STOP = "decelerate every joint to rest at EMERGENCY_STOP_DECELERATION"
    STOP_PROGRAM = "stop the program through the arm's stop_program, where its users see every stop"
    FREEZE_TIME = "the played motions' time scaling to 0 at once"
    FULL_TIME = "the played motions' time scaling to 1 at once"
    SLOW_TO_REST = "ramp the time scaling to 0: a played motion slows along its path, then came_to_rest"
    SPEED_UP = "ramp the time scaling back to 1 the way it came down"


@dataclass(frozen=True, slots=True)
class LifeStep:
    """A command's outcome: why it was refused (None: done), and what the arm's motion does."""

    refused: str | None = None
    then: tuple[Do, ...] = ()


_DONE = LifeStep()


class ArmLife:
    """Power, brakes, safety stops and the program's run state of one fake arm."""

    def __init__(self, *, powered: bool = False) -> None:
        self.robot_mode = RobotMode.RUNNING if powered else RobotMode.POWER_OFF
        self.safety_mode = SafetyMode.NORMAL
        self.runtime_state = RuntimeState.STOPPED
        self._transition_at: float | None = None
        """Controller time (s) at which BOOTING or releasing the brakes (POWER_ON) ends."""
        self._now = 0.0
        """Controller time (s) of the latest cycle (``advance``): when a stop happens."""
        self.unlockable_at = 0.0
        """Controller time (s) from which the latest protective stop may be unlocked."""

    # ---- power, brakes, safety -----------------------------------------------------------------

    def power_on(self, now: float) -> str | None:
        """Start powering on at controller time ``now``; a reason if refused."""
        if self.safety_mode in _EMERGENCY:
            return "emergency stop active"
        if self.robot_mode is RobotMode.POWER_OFF:
            self.robot_mode = RobotMode.BOOTING
            self._transition_at = now + BOOT_TIME_S
        return None

    def power_off(self) -> LifeStep:
        """Cut arm power: the arm halts (brakes engage), then the program stops."""
        self.robot_mode = RobotMode.POWER_OFF
        self._transition_at = None
        return LifeStep(then=(Do.HALT, Do.STOP_PROGRAM))

    def brake_release(self, now: float) -> str | None:
        """Release the brakes at controller time ``now``; refused unless powered (IDLE)."""
        if self.robot_mode is RobotMode.RUNNING:
            return None
        if self.robot_mode is not RobotMode.IDLE:
            return f"robot is {self.robot_mode.name}, not IDLE"
        if self.safety_mode is not SafetyMode.NORMAL:
            return f"safety mode is {self.safety_mode.name}"
        self.robot_mode = RobotMode.POWER_ON  # releasing
        self._transition_at = now + BRAKE_RELEASE_TIME_S
        return None

    def protective_stop(self) -> LifeStep:
        """A protective stop: motion decelerates to rest, a playing or pausing program is PAUSED."""
        if self.safety_mode not in _MOVING_SAFETY:
            return _DONE
        self.safety_mode = SafetyMode.PROTECTIVE_STOP
        self.unlockable_at = self._now + UNLOCK_WAIT_S
        if self.runtime_state not in (RuntimeState.PLAYING, RuntimeState.PAUSING):
            return LifeStep(then=(Do.PROTECTIVE_STOP,))
        self.runtime_state = RuntimeState.PAUSED
        return LifeStep(then=(Do.PROTECTIVE_STOP, Do.FREEZE_TIME))

    def unlock_protective_stop(self, *, moving: bool) -> str | None:
        """Clear a protective stop; a reason if there is none to clear, the arm is still ``moving`` or
        the stop happened less than UNLOCK_WAIT_S of controller time ago (:data:`UNLOCK_TOO_SOON`)."""
        if self.safety_mode is not SafetyMode.PROTECTIVE_STOP:
            return f"safety mode is {self.safety_mode.name}, not PROTECTIVE_STOP"
        if moving:
            return "robot still moving"
        if self._now < self.unlockable_at:
            return UNLOCK_TOO_SOON
        self.safety_mode = SafetyMode.NORMAL
        return None

    def emergency_stop(self) -> LifeStep:
        """Press the emergency stop: the arm stops, the program is stopped, power is off."""
        self.safety_mode = SafetyMode.ROBOT_EMERGENCY_STOP
        self.robot_mode = RobotMode.POWER_OFF
        self._transition_at = None
        return LifeStep(then=(Do.EMERGENCY_STOP, Do.STOP_PROGRAM))

    def release_emergency_stop(self) -> None:
        """Release the emergency stop button; the arm stays powered off."""
        if self.safety_mode in _EMERGENCY:
            self.safety_mode = SafetyMode.NORMAL

    def restart_safety(self) -> None:
        """The dashboard's ``restart safety`` (the arm powered off first): a safety stop other than an
        emergency stop is cleared."""
        if self.safety_mode not in _EMERGENCY:
            self.safety_mode = SafetyMode.NORMAL

    @property
    def can_move(self) -> bool:
        """True when motion commands are executed (brakes released, no safety stop)."""
        return self.robot_mode is RobotMode.RUNNING and self.safety_mode in _MOVING_SAFETY

    def advance(self, now: float) -> None:
        """Finish a timed transition (booting, releasing the brakes) due at controller time ``now``."""
        self._now = now
        if self._transition_at is None or now < self._transition_at:
            return
        self._transition_at = None
        if self.robot_mode is RobotMode.BOOTING:
            self.robot_mode = RobotMode.IDLE
        elif self.robot_mode is RobotMode.POWER_ON:
            self.robot_mode = RobotMode.RUNNING

    # ---- program state (driven by the program executor and the dashboard) ------------------------

    def start_program(self) -> LifeStep:
        """The program starts playing, its motions at full time scaling; a reason if it cannot."""
        reason = self._why_not_playing()
        if reason is not None:
            return LifeStep(reason)
        self.runtime_state = RuntimeState.PLAYING
        return LifeStep(then=(Do.FULL_TIME,))

    def wait_for_script(self) -> None:
        """The program ``play`` started hands over to the script it runs, compiled first: STOPPED until
        that script starts (``start_program``), the motion and the time scaling left as they are."""
        self.runtime_state = RuntimeState.STOPPED

    def pause_program(self) -> LifeStep:
        """Pause the program: PAUSING while a played motion slows down along its path to rest
        (``came_to_rest``: PAUSED). Any other motion stops at once as a protective stop does, and the
        arm says so at once (``came_to_rest``)."""
        if self.runtime_state is not RuntimeState.PLAYING:
            return _DONE
        self.runtime_state = RuntimeState.PAUSING
        return LifeStep(then=(Do.SLOW_TO_REST,))

    def resume_program(self) -> LifeStep:
        """Resume a paused program: PLAYING, the paused motion speeding up along its path."""
        if self.runtime_state is not RuntimeState.PAUSED:
            return LifeStep("no paused program")
        reason = self._why_not_playing()
        if reason is not None:
            return LifeStep(reason)
        self.runtime_state = RuntimeState.PLAYING
        return LifeStep(then=(Do.SPEED_UP,))

    def stop_program(self) -> LifeStep:
        """Stop the program (motion stops); the time scaling is full again for the next one."""
        if self.runtime_state is RuntimeState.STOPPED:
            return LifeStep(then=(Do.FULL_TIME,))
        self.runtime_state = RuntimeState.STOPPED
        return LifeStep(then=(Do.PROTECTIVE_STOP, Do.FULL_TIME))

    def came_to_rest(self) -> None:
        """A pausing program's played motion has slowed to rest on its path: the program is PAUSED."""
        if self.runtime_state is RuntimeState.PAUSING:
            self.runtime_state = RuntimeState.PAUSED

    def _why_not_playing(self) -> str | None:
        if self.robot_mode is not RobotMode.RUNNING:
            return f"robot is {self.robot_mode.name}, not RUNNING"
        if self.safety_mode not in _MOVING_SAFETY:
            return f"safety mode is {self.safety_mode.name}"
        return None

    @property
    def program_running(self) -> bool:
        """RTDE robot_status_bits bit 1."""
        return self.runtime_state in (RuntimeState.PLAYING, RuntimeState.PAUSING)

    # ---- status bits ---------------------------------------------------------------------------------

    @property
    def robot_status_bits(self) -> int:
        """RTDE ``robot_status_bits``: power on, program running."""
        return (POWER_ON_BIT if self.robot_mode in _POWERED else 0) | (
            PROGRAM_RUNNING_BIT if self.program_running else 0
        )

    @property
    def safety_status_bits(self) -> int:
        """RTDE ``safety_status_bits`` (docs/protocols.md §1.9)."""
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
