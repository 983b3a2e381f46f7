"""Controller settings a program changes for later: base acceleration, error handling, base light, power.

A real controller keeps these for the robot's life (until it reboots or the installation is loaded
again), not for one program: the fake keeps them in one :class:`ControllerSettings` per arm
(:func:`settings_of`), which later programs and tests read. Most have nothing to act on in the fake (it
has no mobile base, no joint that deviates from its target, no light ring): they are checked as the
manual asks and recorded, never silently dropped. ``powerdown`` acts: it powers the arm off and ends
the program, as URSim does.
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass, field
from typing import Any, Final

from urdaemon.fakeur.fake_arm import FakeArm
from urdaemon.fakeur.urscript.runtime import ProgramHalt, ScriptRuntimeError, UrList, builtin
from urdaemon.fakeur.urscript.script_host import ScriptHost

__all__ = ["BASELIGHT_MODES", "ControllerSettings", "pause_on_error_of", "settings_of"]

BASELIGHT_MODES: Final = ("iec", "off", "solid")
"""What the base light shows: the IEC status colours (the default), nothing, or one colour."""
INPUT_ACTIONS: Final = ("default", "freedrive")
"""What a digital input may do when high (the manual's ``set_*_input_action`` actions)."""


@dataclass
class ControllerSettings:
    """What programs set on the controller for later; the defaults are a freshly booted controller's."""

    base_acceleration: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    """m/s² in the base frame (``set_base_acceleration``): the mobile platform's acceleration."""
    safety_transition_hardness: int | None = None
    """``set_safety_mode_transition_hardness``: 0 hard (maximum torque, like an emergency stop), 1 soft;
    None until a program sets it (the installation's choice)."""
    deviation_warning: tuple[bool, float] = (False, 0.8)
    """``position_deviation_warning``: enabled, threshold (share of the protective-stop deviation)."""
    high_holding_torque: bool = True
    """Holding torque while the arm stands still (on after boot)."""
    baselight: tuple[str, tuple[float, float, float]] = ("iec", (0.0, 0.0, 0.0))
    """The base light: a mode of :data:`BASELIGHT_MODES` and the colour of ``solid``."""
    input_actions: dict[tuple[str, int], str] = field(default_factory=dict)
    """(group, port) -> action of :data:`INPUT_ACTIONS` for inputs not at ``"default"``; groups:
    ``standard``, ``configurable``, ``tool``, ``gp_boolean``."""
    runstate_outputs: dict[tuple[str, int], int] = field(default_factory=dict)
    """(group, output) -> the manual's run-state choice for outputs not at 0 (keep their value);
    groups: ``standard``, ``configurable``, ``tool``, ``gp_boolean``, ``analog``."""
    tool_analog_input_domain: list[int] = field(default_factory=lambda: [1, 1])
    """Per tool analog input: 0 current (4-20 mA), 1 voltage (0-10 V)."""
    port_registers: dict[int, int] = field(default_factory=dict)
    """The Modbus server's general purpose 16-bit registers (addresses 128-255) written so far."""


_SETTINGS: Final[weakref.WeakKeyDictionary[FakeArm, ControllerSettings]] = weakref.WeakKeyDictionary()


_PAUSE_ON_ERROR: Final[weakref.WeakKeyDictionary[ScriptHost, set[tuple[int, int]]]] = (
    weakref.WeakKeyDictionary()
)


def pause_on_error_of(host: ScriptHost) -> set[tuple[int, int]]:
    """The (code, argument) pairs ``pause_on_error_code`` set in the program of ``host``: the manual
    resets them when the program stops, so they belong to the program, not the robot."""
    found = _PAUSE_ON_ERROR.get(host)
    if found is None:
        found = _PAUSE_ON_ERROR[host] = set()
    return found


def settings_of(arm: FakeArm) -> ControllerSettings:
    """The controller settings of ``arm`` (made on first use; they live as long as the arm)."""
    found = _SETTINGS.get(arm)
    if found is None:
        found = _SETTINGS[arm] = ControllerSettings()
    return found


def _integer(name: str, value: Any) -> int:
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    if value.__class__ is not int:
        raise ScriptRuntimeError(f"{name}: expected an integer, got {value!r}")
    return int(value)


def _vector3(name: str, value: Any) -> list[float]:
    if not isinstance(value, list) or len(value) != 3:
        raise ScriptRuntimeError(f"{name}: expected [x, y, z], got {value!r}")
    result = []
    for item in value:
        if isinstance(item, bool) or not isinstance(item, (int, float)) or not math.isfinite(item):
            raise ScriptRuntimeError(f"{name}: expected [x, y, z], got {value!r}")
        result.append(float(item))
    return result


# ---- mobile base --------------------------------------------------------------------------------------


@builtin("set_base_acceleration")
def set_base_acceleration(host: ScriptHost, a: Any) -> None:
    """The acceleration of the platform the robot stands on (m/s², base frame): recorded (the fake's
    base never moves, and its dynamics have no gravity model for it to correct)."""
    settings_of(host.arm).base_acceleration = _vector3("set_base_acceleration", a)


@builtin("get_base_acceleration")
def get_base_acceleration(host: ScriptHost) -> UrList:
    """The base acceleration last set (``[0, 0, 0]`` until one is)."""
    return UrList(settings_of(host.arm).base_acceleration)


# ---- errors and safety ---------------------------------------------------------------------------------


@builtin("set_safety_mode_transition_hardness")
def set_safety_mode_transition_hardness(host: ScriptHost, type: Any) -> None:
    """How hard the arm stops between normal, reduced and safeguard stop: 1 soft, what the fake's stops
    do (fakeur/fake_arm.py); 0 hard stops the program with "not simulated"."""
    hardness = _integer("set_safety_mode_transition_hardness", type)
    if hardness not in (0, 1):
        raise ScriptRuntimeError(f"set_safety_mode_transition_hardness: type must be 0 or 1, got {hardness}")
    if hardness == 0:
        raise ScriptRuntimeError(
            "set_safety_mode_transition_hardness: a hard transition (0) is not simulated by the fake "
            "controller: its stops always decelerate softly"
        )
    settings_of(host.arm).safety_transition_hardness = hardness


@builtin("pause_on_error_code")
def pause_on_error_code(host: ScriptHost, code: Any, argument: Any) -> None:
    """Pause the program when error ``code`` with ``argument`` occurs: recorded for this program (the
    fake raises no coded controller errors of its own, so it never matches)."""
    pair = (_integer("pause_on_error_code code", code), _integer("pause_on_error_code argument", argument))
    pause_on_error_of(host).add(pair)


@builtin("position_deviation_warning")
def position_deviation_warning(host: ScriptHost, enabled: Any, threshold: Any) -> None:
    """Warn when the arm deviates from its target by ``threshold`` (0..1) of what protective-stops it:
    recorded (the fake arm follows its target exactly, so it never warns)."""
    if not isinstance(enabled, bool):
        raise ScriptRuntimeError(f"position_deviation_warning: enabled must be a boolean, got {enabled!r}")
    if isinstance(threshold, bool) or not isinstance(threshold, (int, float)) or not 0 <= threshold <= 1:
        raise ScriptRuntimeError(f"position_deviation_warning: threshold must be in 0..1, got {threshold!r}")
    settings_of(host.arm).deviation_warning = (enabled, float(threshold))


@builtin("high_holding_torque_enable")
def high_holding_torque_enable(host: ScriptHost) -> None:
    settings_of(host.arm).high_holding_torque = True


@builtin("high_holding_torque_disable")
def high_holding_torque_disable(host: ScriptHost) -> None:
    """Recorded: the fake arm holds its joints still either way (no load pulls on them)."""
    settings_of(host.arm).high_holding_torque = False


# ---- base light -----------------------------------------------------------------------------------------


@builtin("set_baselight_off")
def set_baselight_off(host: ScriptHost) -> None:
    settings_of(host.arm).baselight = ("off", (0.0, 0.0, 0.0))


@builtin("set_baselight_iec")
def set_baselight_iec(host: ScriptHost) -> None:
    settings_of(host.arm).baselight = ("iec", (0.0, 0.0, 0.0))


@builtin("set_baselight_solid")
def set_baselight_solid(host: ScriptHost, r: Any, g: Any, b: Any) -> None:
    """One colour; each channel a number from 0 to 255."""
    colour = []
    for channel in (r, g, b):
        if isinstance(channel, bool) or not isinstance(channel, (int, float)) or not 0 <= channel <= 255:
            raise ScriptRuntimeError(f"set_baselight_solid: a colour channel is in 0..255, got {channel!r}")
        colour.append(float(channel))
    settings_of(host.arm).baselight = ("solid", (colour[0], colour[1], colour[2]))


# ---- power ----------------------------------------------------------------------------------------------


@builtin("powerdown")
def powerdown(host: ScriptHost) -> None:
    """Power the arm off (brakes engage, robot mode POWER_OFF) and end the program, as URSim does.

    The arm's ``power_off`` stops the program's run state; the controller then ends every program
    (``fakeur/programs.py``). The program calling it ends at once, like ``halt``."""
    host.arm.power_off()
    raise ProgramHalt
