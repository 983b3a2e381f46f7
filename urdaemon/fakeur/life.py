"""The fake arm's life: power, brakes, safety stops and the program's run state (``ArmLife``).

One ``ArmLife`` per ``FakeArm`` (fakeur/arm.py), which holds it as ``arm.life``. It owns the robot mode,
the safety mode, the RTDE ``runtime_state``, the timed transitions (booting, releasing the brakes)
and the status bits RTDE reports, and it answers each command with a refusal reason (or None) the way
a real controller refuses it (e.g. brake release while powered off). What a change of life does to the
motion (stop, halt, slow a played motion down for a pause) it asks of the arm; the arm advances the
transitions at the start of each cycle (``advance``) and enforces the modes on its motion.

Pure: no asyncio, no clock; the transitions' times are the arm's controller time (``arm.timestamp``).

State machine (robot mode, §6.1 of docs/protocols.md), as a real e-Series controller behaves:
POWER_OFF --power on--> BOOTING (power-up delay) --> IDLE --brake release--> RUNNING.
Power off from anywhere → POWER_OFF. A protective stop keeps the mode but stops motion until
unlocked; an emergency stop powers the arm off until released.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from urdaemon.model import RobotMode, SafetyMode
from urdaemon.protocols.rtde_variables import POWER_ON_BIT, PROGRAM_RUNNING_BIT, RuntimeState

if TYPE_CHECKING:
    from urdaemon.fakeur.arm import FakeArm

__all__ = [
    "BOOT_TIME_S",
    "BRAKE_RELEASE_TIME_S",
    "EMERGENCY_STOP_DECELERATION",
    "PROTECTIVE_STOP_DECELERATION",
    "ArmLife",
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

_MOVING_SAFETY = (SafetyMode.NORMAL, SafetyMode.REDUCED)
"""The safety modes in which the arm may move and a program may play."""
_EMERGENCY = (SafetyMode.ROBOT_EMERGENCY_STOP, SafetyMode.SYSTEM_EMERGENCY_STOP)
_POWERED = (RobotMode.IDLE, RobotMode.RUNNING, RobotMode.POWER_ON, RobotMode.BACKDRIVE)
"""The robot modes RTDE reports as powered on (``robot_status_bits`` bit 0)."""


class ArmLife:
    """Power, brakes, safety stops and the program's run state of one fake arm."""

    def __init__(self, arm: FakeArm, *, powered: bool = False) -> None:
        self._arm = arm
        self.robot_mode = RobotMode.RUNNING if powered else RobotMode.POWER_OFF
        self.safety_mode = SafetyMode.NORMAL
        self.runtime_state = RuntimeState.STOPPED
        self._transition_at: float | None = None
        """Controller time (s) at which BOOTING or releasing the brakes (POWER_ON) ends."""

    # ---- power, brakes, safety -----------------------------------------------------------------

    def power_on(self) -> str | None:
        """Start powering on; a reason if refused."""
        if self.safety_mode in _EMERGENCY:
            return "emergency stop active"
        if self.robot_mode is RobotMode.POWER_OFF:
            self.robot_mode = RobotMode.BOOTING
            self._transition_at = self._arm.timestamp + BOOT_TIME_S
        return None

    def power_off(self) -> None:
        """Cut arm power (brakes engage, program stops)."""
        self._arm.halt()
        self.robot_mode = RobotMode.POWER_OFF
        self._transition_at = None
        self._arm.stop_program()  # through the arm, where its users see every program stop

    def brake_release(self) -> str | None:
        """Release the brakes; refused unless powered (IDLE)."""
        if self.robot_mode is RobotMode.RUNNING:
            return None
        if self.robot_mode is not RobotMode.IDLE:
            return f"robot is {self.robot_mode.name}, not IDLE"
        if self.safety_mode is not SafetyMode.NORMAL:
            return f"safety mode is {self.safety_mode.name}"
        self.robot_mode = RobotMode.POWER_ON  # releasing
        self._transition_at = self._arm.timestamp + BRAKE_RELEASE_TIME_S
        return None

    def protective_stop(self) -> None:
        """Trigger a protective stop: motion decelerates to rest, the program pauses."""
        if self.safety_mode in _MOVING_SAFETY:
            self.safety_mode = SafetyMode.PROTECTIVE_STOP
            self._arm.stop(PROTECTIVE_STOP_DECELERATION)
            if self.runtime_state in (RuntimeState.PLAYING, RuntimeState.PAUSING):
                self.runtime_state = RuntimeState.PAUSED
                self._arm.set_time_scaling(0.0)

    def unlock_protective_stop(self) -> str | None:
        """Clear a protective stop; a reason if there is none to clear or it is too early."""
        if self.safety_mode is not SafetyMode.PROTECTIVE_STOP:
            return f"safety mode is {self.safety_mode.name}, not PROTECTIVE_STOP"
        if any(abs(v) > 1e-9 for v in self._arm.qd):
            return "robot still moving"
        self.safety_mode = SafetyMode.NORMAL
        return None

    def emergency_stop(self) -> None:
        """Press the emergency stop: stop, power off, program stopped."""
        self.safety_mode = SafetyMode.ROBOT_EMERGENCY_STOP
        self._arm.stop(EMERGENCY_STOP_DECELERATION)
        self._arm.stop_program()
        self.robot_mode = RobotMode.POWER_OFF
        self._transition_at = None

    def release_emergency_stop(self) -> None:
        """Release the emergency stop button; the arm stays powered off."""
        if self.safety_mode in _EMERGENCY:
            self.safety_mode = SafetyMode.NORMAL

    @property
    def can_move(self) -> bool:
        """True when motion commands are executed (brakes released, no safety stop)."""
        return self.robot_mode is RobotMode.RUNNING and self.safety_mode in _MOVING_SAFETY

    def advance(self, now: float) -> None:
        """Finish a timed transition (booting, releasing the brakes) due at controller time ``now``."""
        if self._transition_at is None or now < self._transition_at:
            return
        self._transition_at = None
        if self.robot_mode is RobotMode.BOOTING:
            self.robot_mode = RobotMode.IDLE
        elif self.robot_mode is RobotMode.POWER_ON:
            self.robot_mode = RobotMode.RUNNING

    # ---- program state (driven by the program executor and the dashboard) ------------------------

    def start_program(self) -> str | None:
        """The program starts playing; a reason if it cannot."""
        reason = self._why_not_playing()
        if reason is not None:
            return reason
        self.runtime_state = RuntimeState.PLAYING
        self._arm.set_time_scaling(1.0)
        return None

    def pause_program(self) -> None:
        """Pause the program: a played motion slows down along its path (PAUSING) to rest (PAUSED).

        Any other motion (a stop, a legacy servo or speed target) stops at once as a protective stop
        does, and the program is PAUSED."""
        if self.runtime_state is not RuntimeState.PLAYING:
            return
        slowing = self._arm.slow_to_rest()
        self.runtime_state = RuntimeState.PAUSING if slowing else RuntimeState.PAUSED

    def resume_program(self) -> str | None:
        """Resume a paused program: PLAYING, the paused motion speeding up along its path."""
        if self.runtime_state is not RuntimeState.PAUSED:
            return "no paused program"
        reason = self._why_not_playing()
        if reason is not None:
            return reason
        self.runtime_state = RuntimeState.PLAYING
        self._arm.speed_up()
        return None

    def stop_program(self) -> None:
        """Stop the program (motion stops)."""
        if self.runtime_state is not RuntimeState.STOPPED:
            self._arm.stop(PROTECTIVE_STOP_DECELERATION)
            self.runtime_state = RuntimeState.STOPPED
        self._arm.set_time_scaling(1.0)

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
