"""URScript's configuration builtins: payload, TCP, gravity, force mode, freedrive, tool contact, watchdog.

What they set lives on the arm where RTDE and the primary interface report it (``payload_mass``,
``payload_cog``, ``payload_inertia``, ``tcp_offset``, ``gravity``, ``force_mode``, ``freedrive``); the
parameters nothing reports (force mode's frame, damping and gain scaling, freedrive's free axes) are kept
in ``host.config`` (a :class:`ConfigState`). Force mode, freedrive, ``zero_ftsensor`` and ``tool_contact``
act on the arm's surroundings (fakeur/contact.py): the walls and the push a test or user put there move
a compliant or free arm, and make the TCP force and contacts. Force mode's types 1 and 3 (frames that
follow the TCP) are not simulated.
``rtde_set_watchdog`` records the request in ``host.watchdogs``; the controller enforces it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Final

from urdaemon.description.frames import IDENTITY, frame_of_pose
from urdaemon.fakeur.contact import ForceModeSettings, surroundings_of
from urdaemon.fakeur.fake_arm import HISTORY_STEPS
from urdaemon.fakeur.urscript.runtime import ScriptRuntimeError, UrList, UrPose, builtin
from urdaemon.fakeur.urscript.script_host import WATCHDOG_ACTIONS, ScriptHost, Watchdog
from urdaemon.fakeur.urscript.signatures import Computed
from urdaemon.protocols.rtde_variables import INPUT_VARIABLES

__all__ = ["DEFAULT_DAMPING", "DEFAULT_GAIN_SCALING", "ConfigState"]

DEFAULT_DAMPING: Final = 0.005
"""Force mode damping until ``force_mode_set_damping`` (UR's manual)."""
DEFAULT_GAIN_SCALING: Final = 1.0
"""Force mode gain scaling until ``force_mode_set_gain_scaling`` (UR's manual)."""
FORCE_MODE_TYPES: Final = (1, 2, 3)
SIMULATED_FORCE_MODE_TYPES: Final = (2,)
"""Type 2 (the task frame as given); 1 and 3 turn the frame with the TCP's position or motion."""
TOOL_BAUD_RATES: Final = (9600, 19200, 38400, 57600, 115200, 1_000_000, 2_000_000, 5_000_000)
"""Baud rates the tool's RS-485 interface supports (UR's manual)."""


@dataclass
class ConfigState:
    """A program's force mode and freedrive parameters (``host.config``)."""

    damping: float = DEFAULT_DAMPING
    gain_scaling: float = DEFAULT_GAIN_SCALING
    force_frame: list[float] = field(default_factory=lambda: [0.0] * 6)
    force_selection: list[int] = field(default_factory=lambda: [0] * 6)
    force_wrench: list[float] = field(default_factory=lambda: [0.0] * 6)
    force_type: int = 2
    force_limits: list[float] = field(default_factory=lambda: [0.0] * 6)
    free_axes: list[int] = field(default_factory=lambda: [1] * 6)
    freedrive_feature: list[float] = field(default_factory=lambda: [0.0] * 6)
    ft_zeroed_at: float | None = None
    """Controller time of the last ``zero_ftsensor``."""
    external_ft_sensor: tuple[float, list[float], list[float]] | None = None
    """``ft_rtde_input_enable``'s (sensor mass, measuring offset, centre of gravity) while enabled: the
    fake measures no force either way, so nothing reads it back."""
    tool_communication: tuple[bool, int, int, int, float, float] | None = None
    """``set_tool_communication``'s (enabled, baud rate, parity, stop bits, rx idle, tx idle)."""
    tool_output_modes: list[int] = field(default_factory=lambda: [2, 2])
    """Tool digital outputs 0 and 1: 1 sinking (NPN), 2 sourcing (PNP), 3 push-pull."""
    tool_output_mode: int = 0
    """Tool output pins: 0 digital outputs, 1 dual pin power."""


def _config(host: ScriptHost) -> ConfigState:
    config = host.config
    if config is None:
        config = host.config = ConfigState()
    return config  # type: ignore[no-any-return]


def _number(function: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ScriptRuntimeError(f"{function}: expected a number, got {value!r}")
    return float(value)


def _vector(function: str, value: Any, length: int) -> list[float]:
    if not isinstance(value, Sequence) or isinstance(value, str) or len(value) != length:
        raise ScriptRuntimeError(f"{function}: expected a list of {length} numbers, got {value!r}")
    return [_number(function, item) for item in value]


def _flags(function: str, value: Any) -> list[int]:
    flags = _vector(function, value, 6)
    if any(flag not in (0.0, 1.0) for flag in flags):
        raise ScriptRuntimeError(f"{function}: expected six 0s and 1s, got {value!r}")
    return [int(flag) for flag in flags]


def _mass(function: str, m: Any) -> float:
    mass = _number(function, m)
    if mass < 0:
        raise ScriptRuntimeError(f"{function}: mass {mass:g} kg is negative")
    return mass


def _in_range(function: str, what: str, value: Any, low: float, high: float) -> float:
    number = _number(function, value)
    if not low <= number <= high:
        raise ScriptRuntimeError(f"{function}: {what} {number:g} is not in {low:g}..{high:g}")
    return number


# ---- payload, TCP, gravity ------------------------------------------------------------------------------


@builtin("set_payload")
def set_payload(host: ScriptHost, m: Any, cog: Any = None) -> None:
    """Payload mass and centre of gravity; without ``cog``, the TCP position is the centre of gravity."""
    arm = host.arm
    if cog is None or isinstance(cog, Computed):
        centre = [float(v) for v in arm.tcp_offset[:3]]
    else:
        centre = _vector("set_payload", cog, 3)
    arm.payload_mass = _mass("set_payload", m)
    arm.payload_cog = centre
    arm.payload_inertia = [0.0] * 6


@builtin("set_payload_mass")
def set_payload_mass(host: ScriptHost, m: Any) -> None:
    host.arm.payload_mass = _mass("set_payload_mass", m)


@builtin("set_payload_cog")
def set_payload_cog(host: ScriptHost, cog: Any) -> None:
    host.arm.payload_cog = _vector("set_payload_cog", cog, 3)


@builtin("set_target_payload")
def set_target_payload(
    host: ScriptHost, m: Any, cog: Any, inertia: Any = (0, 0, 0, 0, 0, 0), transition_time: Any = 0
) -> None:
    """Payload mass, centre of gravity and inertia ``[Ixx, Iyy, Izz, Ixy, Ixz, Iyz]`` (kg m²); the fake
    applies it at once (``transition_time`` only smooths the controller's model change)."""
    mass = _mass("set_target_payload", m)
    centre = _vector("set_target_payload", cog, 3)
    matrix = _vector("set_target_payload", inertia, 6)
    if _number("set_target_payload", transition_time) < 0:
        raise ScriptRuntimeError("set_target_payload: transition_time is negative")
    arm = host.arm
    arm.payload_mass, arm.payload_cog, arm.payload_inertia = mass, centre, matrix


@builtin("get_target_payload")
def get_target_payload(host: ScriptHost) -> float:
    return float(host.arm.payload_mass)


@builtin("get_target_payload_cog")
def get_target_payload_cog(host: ScriptHost) -> UrList:
    return UrList(float(v) for v in host.arm.payload_cog)


@builtin("get_target_payload_inertia")
def get_target_payload_inertia(host: ScriptHost) -> UrList:
    return UrList(float(v) for v in host.arm.payload_inertia)


@builtin("set_tcp")
def set_tcp(host: ScriptHost, pose: Any) -> None:
    """The TCP offset from the tool flange, a pose."""
    host.arm.tcp_offset = _vector("set_tcp", pose, 6)


@builtin("get_tcp_offset")
def get_tcp_offset(host: ScriptHost) -> UrPose:
    return UrPose(float(v) for v in host.arm.tcp_offset)


@builtin("set_gravity")
def set_gravity(host: ScriptHost, d: Any) -> None:
    """The direction of the gravity acceleration (m/s²) in the base frame."""
    host.arm.gravity = _vector("set_gravity", d, 3)


@builtin("get_gravity")
def get_gravity(host: ScriptHost) -> UrList:
    return UrList(float(v) for v in host.arm.gravity)


# ---- force mode ----------------------------------------------------------------------------------------


@builtin("force_mode")
def force_mode(
    host: ScriptHost, task_frame: Any, selection_vector: Any, wrench: Any, type: Any, limits: Any
) -> None:
    """Enter force mode: the compliant axes move the arm against the wrench its surroundings put on the
    TCP (fakeur/contact.py); type 2 only, 1 and 3 are not simulated."""
    frame = _vector("force_mode", task_frame, 6)
    selection = _flags("force_mode", selection_vector)
    forces = _vector("force_mode", wrench, 6)
    kind = _number("force_mode", type)
    if kind not in FORCE_MODE_TYPES:
        raise ScriptRuntimeError(f"force_mode: type {kind:g} is not 1, 2 or 3")
    if kind not in SIMULATED_FORCE_MODE_TYPES:
        raise ScriptRuntimeError(f"force_mode: type {kind:g} is not simulated by the fake (only 2)")
    bounds = _vector("force_mode", limits, 6)
    config = _config(host)
    config.force_frame, config.force_selection, config.force_wrench = frame, selection, forces
    config.force_type, config.force_limits = int(kind), bounds
    surroundings_of(host.arm).force = ForceModeSettings(
        frame, selection, forces, bounds, config.damping, config.gain_scaling
    )
    host.arm.force_mode = True


@builtin("end_force_mode")
def end_force_mode(host: ScriptHost) -> None:
    host.arm.force_mode = False


@builtin("force_mode_set_damping")
def force_mode_set_damping(host: ScriptHost, damping: Any) -> None:
    """Force mode damping, 0 (none) to 1 (full)."""
    value = _config(host).damping = _in_range("force_mode_set_damping", "damping", damping, 0.0, 1.0)
    surroundings = host.arm.surroundings
    if surroundings is not None and surroundings.force is not None:
        surroundings.force.damping = value


@builtin("force_mode_get_damping")
def force_mode_get_damping(host: ScriptHost) -> float:
    return _config(host).damping


@builtin("force_mode_set_gain_scaling")
def force_mode_set_gain_scaling(host: ScriptHost, scaling: Any) -> None:
    """Force mode gain scaling, 0 to 2 (1 = nominal)."""
    value = _config(host).gain_scaling = _in_range(
        "force_mode_set_gain_scaling", "scaling", scaling, 0.0, 2.0
    )
    surroundings = host.arm.surroundings
    if surroundings is not None and surroundings.force is not None:
        surroundings.force.gain_scaling = value


@builtin("force_mode_get_gain_scaling")
def force_mode_get_gain_scaling(host: ScriptHost) -> float:
    return _config(host).gain_scaling


@builtin("zero_ftsensor")
def zero_ftsensor(host: ScriptHost) -> None:
    """Zero the force/torque reading: the external wrench felt now reads as zero from here on."""
    _config(host).ft_zeroed_at = host.now
    surroundings = host.arm.surroundings
    if surroundings is not None:
        surroundings.zero()


# ---- freedrive, tool contact -------------------------------------------------------------------------------


@builtin("freedrive_mode")
def freedrive_mode(host: ScriptHost, free_axes: Any = (1, 1, 1, 1, 1, 1), feature: Any = None) -> None:
    """Enter freedrive: a push on the tool moves the arm along the free axes (fakeur/contact.py); with
    nothing pushing it stays where it is."""
    config = _config(host)
    config.free_axes = _flags("freedrive_mode", free_axes)
    config.freedrive_feature = [0.0] * 6 if feature is None else _vector("freedrive_mode", feature, 6)
    surroundings = surroundings_of(host.arm)
    surroundings.free_axes = list(config.free_axes)
    surroundings.free_frame = IDENTITY if feature is None else frame_of_pose(config.freedrive_feature)
    host.arm.freedrive = True


@builtin("end_freedrive_mode")
def end_freedrive_mode(host: ScriptHost) -> None:
    host.arm.freedrive = False


@builtin("teach_mode")
def teach_mode(host: ScriptHost) -> None:
    """CB3's name for freedrive with every axis free."""
    _config(host).free_axes = [1] * 6
    surroundings = surroundings_of(host.arm)
    surroundings.free_axes, surroundings.free_frame = [1] * 6, IDENTITY
    host.arm.freedrive = True


@builtin("end_teach_mode")
def end_teach_mode(host: ScriptHost) -> None:
    host.arm.freedrive = False


@builtin("get_freedrive_status")
def get_freedrive_status(host: ScriptHost) -> int:
    """0: normal operation (the fake has no singularity or limit resistance to report)."""
    return 0


@builtin("tool_contact")
def tool_contact(host: ScriptHost, direction: Any = (0, 0, 0, 0, 0, 0), force_threshold: Any = 0.0) -> int:
    """Cycles back to just before the contact started, 0 if none: a contact is a measured TCP force that
    opposes ``direction`` (base frame; any direction if zero) by more than ``force_threshold`` N (the
    model's :data:`~urdaemon.fakeur.contact.TOOL_CONTACT_THRESHOLD_N` if 0)."""
    towards = _vector("tool_contact", direction, 6)
    threshold = _number("tool_contact", force_threshold)
    arm = host.arm
    surroundings = arm.surroundings
    if surroundings is None:
        return 0  # free air: nothing to touch
    return surroundings.contact_steps(arm.tcp_force, towards, threshold, HISTORY_STEPS - 1)


def _external_ft_sensor(
    name: str, host: ScriptHost, enable: Any, sensor_mass: Any, sensor_measuring_offset: Any, sensor_cog: Any
) -> None:
    if not isinstance(enable, bool):
        raise ScriptRuntimeError(f"{name}: enable must be True or False, got {enable!r}")
    mass = _number(name, sensor_mass)
    if mass < 0:
        raise ScriptRuntimeError(f"{name}: sensor_mass must be >= 0, got {mass}")
    offset = _vector(name, sensor_measuring_offset, 3)
    cog = _vector(name, sensor_cog, 3)
    _config(host).external_ft_sensor = (mass, offset, cog) if enable else None


@builtin("ft_rtde_input_enable")
def ft_rtde_input_enable(
    host: ScriptHost, enable: Any, sensor_mass: Any, sensor_measuring_offset: Any, sensor_cog: Any
) -> None:
    """Take the F/T readings from RTDE's ``external_force_torque`` input (an external sensor)."""
    _external_ft_sensor(
        "ft_rtde_input_enable", host, enable, sensor_mass, sensor_measuring_offset, sensor_cog
    )


@builtin("enable_external_ft_sensor")
def enable_external_ft_sensor(
    host: ScriptHost, enable: Any, sensor_mass: Any, sensor_measuring_offset: Any, sensor_cog: Any
) -> None:
    """The deprecated name of ``ft_rtde_input_enable`` (before 5.9)."""
    _external_ft_sensor(
        "enable_external_ft_sensor", host, enable, sensor_mass, sensor_measuring_offset, sensor_cog
    )


# ---- tool IO configuration ------------------------------------------------------------------------------


def _choice(function: str, what: str, value: Any, allowed: Sequence[int]) -> int:
    number = _number(function, value)
    if number not in allowed:
        raise ScriptRuntimeError(
            f"{function}: {what} {number:g} is not one of {', '.join(map(str, allowed))}"
        )
    return int(number)


@builtin("set_tool_communication")
def set_tool_communication(
    host: ScriptHost,
    enabled: Any,
    baud_rate: Any,
    parity: Any,
    stop_bits: Any,
    rx_idle_chars: Any,
    tx_idle_chars: Any,
) -> None:
    """Configure the tool's RS-485 interface (the fake has no tool device to talk to: it is recorded)."""
    function = "set_tool_communication"
    if not isinstance(enabled, bool):
        raise ScriptRuntimeError(f"{function}: enabled must be True or False, got {enabled!r}")
    _config(host).tool_communication = (
        enabled,
        _choice(function, "baud_rate", baud_rate, TOOL_BAUD_RATES),
        _choice(function, "parity", parity, (0, 1, 2)),
        _choice(function, "stop_bits", stop_bits, (1, 2)),
        _in_range(function, "rx_idle_chars", rx_idle_chars, 1.0, 40.0),
        _in_range(function, "tx_idle_chars", tx_idle_chars, 0.0, 40.0),
    )


@builtin("set_tool_digital_output_mode")
def set_tool_digital_output_mode(host: ScriptHost, n: Any, mode: Any) -> None:
    """Tool digital output ``n`` (0..1): 1 sinking (NPN), 2 sourcing (PNP), 3 push-pull."""
    pin = _choice("set_tool_digital_output_mode", "output", n, (0, 1))
    _config(host).tool_output_modes[pin] = _choice("set_tool_digital_output_mode", "mode", mode, (1, 2, 3))


@builtin("set_tool_output_mode")
def set_tool_output_mode(host: ScriptHost, mode: Any) -> None:
    """Tool output pins as digital outputs (0) or dual pin power (1)."""
    _config(host).tool_output_mode = _choice("set_tool_output_mode", "mode", mode, (0, 1))


# ---- RTDE watchdog -----------------------------------------------------------------------------------------


@builtin("rtde_set_watchdog")
def rtde_set_watchdog(
    host: ScriptHost, variable_name: Any, min_frequency: Any, action: Any = "pause"
) -> None:
    """Watch RTDE input ``variable_name``: if it is not updated at ``min_frequency`` Hz or more, the
    controller ignores it, pauses or stops the program (``action``). Setting it again replaces the old one.
    The action is named in any case: UR's own RTDE example program passes ``"PAUSE"`` where the script
    manual writes ``'pause'``."""
    if not isinstance(variable_name, str) or variable_name not in INPUT_VARIABLES:
        raise ScriptRuntimeError(f"rtde_set_watchdog: {variable_name!r} is not an RTDE input variable")
    frequency = _number("rtde_set_watchdog", min_frequency)
    if frequency <= 0:
        raise ScriptRuntimeError(f"rtde_set_watchdog: min_frequency {frequency:g} Hz is not positive")
    if isinstance(action, str):
        action = action.lower()
    if action not in WATCHDOG_ACTIONS:
        raise ScriptRuntimeError(f"rtde_set_watchdog: action {action!r} is not 'ignore', 'pause' or 'stop'")
    host.watchdogs[variable_name] = Watchdog(variable_name, frequency, action, host.now)
