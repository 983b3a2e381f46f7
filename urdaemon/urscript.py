"""Our own control URScript: fill ``resources/urscript/urdaemon_control.urscript`` for one robot.

The template speaks the wire protocol of docs/protocols.md §4 and behaves as §5 describes (see
``resources/urscript/README.md`` for what it implements and leaves out). Placeholders are ``{{NAME}}``,
replaced by plain string substitution:

    {{SERVER_IP}}            daemon address the robot dials back to
    {{REVERSE_PORT}}         reverse interface (50001)
    {{TRAJECTORY_PORT}}      trajectory point interface (50003)
    {{SCRIPT_COMMAND_PORT}}  script command interface (50004)
    {{MULT_JOINTSTATE}}      scale of every scaled int (1 000 000)
    {{SERVOJ_LOOKAHEAD}}     servoj lookahead_time, s
    {{SERVOJ_GAIN}}          servoj gain
    {{KEEPALIVE_CYCLES}}     cycles without a frame the program goes on with the last command
    {{TOOL_SETUP}}           lines run once before connecting (e.g. tool voltage), or nothing

Rendering is pure: the same parameters and template give the same text. Headless wrapping is
``urdaemon.protocols.primary.headless_program``.
"""

from __future__ import annotations

import ipaddress
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Final

from urdaemon.paths import resource_path
from urdaemon.protocols._fixed import MULT_JOINTSTATE
from urdaemon.protocols.reverse import REVERSE_PORT
from urdaemon.protocols.script_command import SCRIPT_COMMAND_PORT
from urdaemon.protocols.trajectory_point import TRAJECTORY_PORT

__all__ = [
    "DEFAULT_KEEPALIVE_CYCLES",
    "DEFAULT_REVERSE_PORT",
    "DEFAULT_SCRIPT_COMMAND_PORT",
    "DEFAULT_SERVOJ_GAIN",
    "DEFAULT_SERVOJ_LOOKAHEAD_S",
    "DEFAULT_TRAJECTORY_PORT",
    "KEEPALIVE_CYCLES_RANGE",
    "PLACEHOLDERS",
    "SERVOJ_GAIN_RANGE",
    "SERVOJ_LOOKAHEAD_RANGE_S",
    "SPEEDJ_ACCELERATION",
    "TEMPLATE_NAME",
    "URCAP_MARKERS",
    "ScriptParameters",
    "render_control_script",
    "render_template",
]

TEMPLATE_NAME: Final = "urdaemon_control.urscript"
"""The template's file name under ``resources/urscript``."""

DEFAULT_REVERSE_PORT: Final = REVERSE_PORT
DEFAULT_TRAJECTORY_PORT: Final = TRAJECTORY_PORT
DEFAULT_SCRIPT_COMMAND_PORT: Final = SCRIPT_COMMAND_PORT
DEFAULT_SERVOJ_LOOKAHEAD_S: Final = 0.03
"""urcl's default servoj lookahead, s (§5.1)."""
DEFAULT_SERVOJ_GAIN: Final = 2000
"""urcl's default servoj gain (§5.1)."""
SERVOJ_LOOKAHEAD_RANGE_S: Final = (0.03, 0.2)
"""Allowed servoj lookahead_time, s (URScript servoj limits; §5.1)."""
SERVOJ_GAIN_RANGE: Final = (100.0, 2000.0)
"""Allowed servoj gain (URScript servoj limits; §5.1)."""
DEFAULT_KEEPALIVE_CYCLES: Final = 100
"""Controller cycles without a frame during which the program goes on with the last command, then
stops the arm (0.2 s at 500 Hz, 0.8 s at 125 Hz; docs/operating.md, busy PCs)."""
KEEPALIVE_CYCLES_RANGE: Final = (1, 5000)
"""Allowed keepalive cycles: at least one, at most 10 s of a 500 Hz controller."""
SPEEDJ_ACCELERATION: Final = 40.0
"""rad/s²: the acceleration the control script passes to every speedj step while the daemon streams
velocities (urcl's script does the same, §5.3). Our choice, not a URScript default: speedj has none."""

PLACEHOLDERS: Final = (
    "SERVER_IP",
    "REVERSE_PORT",
    "TRAJECTORY_PORT",
    "SCRIPT_COMMAND_PORT",
    "MULT_JOINTSTATE",
    "SERVOJ_LOOKAHEAD",
    "SERVOJ_GAIN",
    "KEEPALIVE_CYCLES",
    "SPEEDJ_ACCEL",
    "TOOL_SETUP",
    "TARGET_PAYLOAD_CALL",
    "TOOL_CONTACT_CALL",
)
"""Every placeholder the template must contain and the renderer fills."""

URCAP_MARKERS: Final = (
    "# HEADER_BEGIN",
    "# HEADER_END",
    "# NODE_CONTROL_LOOP_BEGINS",
    "# NODE_CONTROL_LOOP_ENDS",
)
"""Comment lines, in this order, by which the URCap splits header and control loop (§4.3, §5.8)."""

_MAX_PORT: Final = 65535
_PLACEHOLDER: Final = re.compile(r"\{\{\s*([A-Za-z0-9_]*)\s*\}\}")
# A DNS name: dot-separated labels of letters, digits and inner hyphens. Quotes, spaces and the like
# would end the URScript string literal the host is written into.
_HOST_LABEL: Final = re.compile(r"(?!-)[A-Za-z0-9-]{1,63}(?<!-)")


def _fail(name: str, reason: str) -> ValueError:
    return ValueError(f"ScriptParameters.{name}: {reason}")


def _check_host(value: object) -> None:
    if not isinstance(value, str) or not value:
        raise _fail("server_ip", f"must be a non-empty string, got {value!r}")
    try:
        address = ipaddress.ip_address(value)
    except ValueError:
        labels = value.removesuffix(".").split(".")
        if len(value) > 253 or not all(_HOST_LABEL.fullmatch(label) for label in labels):
            raise _fail("server_ip", f"{value!r} is neither an IPv4 address nor a host name") from None
        return
    if address.version != 4:
        # whether socket_open takes an IPv6 literal is not documented in our reference
        raise _fail("server_ip", f"{value!r}: only IPv4 addresses or host names are supported")


def _check_port(name: str, value: object) -> None:
    if type(value) is not int or not 0 < value <= _MAX_PORT:
        raise _fail(name, f"must be an int TCP port in [1, {_MAX_PORT}], got {value!r}")


def _check_range(name: str, value: object, low: float, high: float) -> None:
    if (
        isinstance(value, bool)
        or not isinstance(value, int | float)
        or not math.isfinite(value)
        or not low <= value <= high
    ):
        raise _fail(name, f"must be a number in [{low:g}, {high:g}], got {value!r}")


def _check_tool_setup(value: object) -> tuple[str, ...]:
    if isinstance(value, str) or not isinstance(value, Sequence):
        raise _fail("tool_setup", f"must be a sequence of lines, got {value!r}")
    lines = tuple(value)
    for line in lines:
        if not isinstance(line, str):
            raise _fail("tool_setup", f"every line must be a str, got {line!r}")
        if "\n" in line or "\r" in line:
            raise _fail("tool_setup", f"one line per item, no line breaks: {line!r}")
        if not line.isascii():
            raise _fail("tool_setup", f"the controller runs ASCII only (§2.4): {line!r}")
        if "{{" in line or "}}" in line:
            raise _fail("tool_setup", f"must not contain placeholder braces: {line!r}")
        if line.strip() in URCAP_MARKERS:
            raise _fail("tool_setup", f"must not contain a URCap marker line: {line!r}")
    return lines


TARGET_PAYLOAD_SINCE = (5, 10, 0)
"""First PolyScope version with ``set_target_payload`` (docs/protocols.md §5.1 version gates)."""
TOOL_CONTACT_SINCE = (5, 4, 0)
"""First PolyScope version with ``tool_contact`` (the URScript manual; fakeur/urscript/functions.yaml)."""


@dataclass(frozen=True, slots=True)
class ScriptParameters:
    """What differs per robot in the control script; checked on construction (ValueError names the field)."""

    server_ip: str
    reverse_port: int = DEFAULT_REVERSE_PORT
    trajectory_port: int = DEFAULT_TRAJECTORY_PORT
    script_command_port: int = DEFAULT_SCRIPT_COMMAND_PORT
    servoj_lookahead: float = DEFAULT_SERVOJ_LOOKAHEAD_S
    servoj_gain: float = DEFAULT_SERVOJ_GAIN
    tool_setup: tuple[str, ...] = field(default=())
    keepalive_cycles: int = DEFAULT_KEEPALIVE_CYCLES
    """Cycles without a frame the program goes on with the last command before it stops the arm."""
    controller_version: tuple[int, int, int] = (5, 10, 0)
    """The controller's version: ``set_target_payload`` exists from PolyScope 5.10 on; older ones
    (CB3 3.x included) get ``set_payload(mass, cog)`` for SET_TARGET_PAYLOAD instead."""

    def __post_init__(self) -> None:
        _check_host(self.server_ip)
        ports = {
            "reverse_port": self.reverse_port,
            "trajectory_port": self.trajectory_port,
            "script_command_port": self.script_command_port,
        }
        for name, port in ports.items():
            _check_port(name, port)
        seen: dict[int, str] = {}
        for name, port in ports.items():
            if port in seen:
                # the three links are separate servers on the daemon: one port cannot serve two
                raise _fail(name, f"port {port} is also {seen[port]}")
            seen[port] = name
        _check_range("servoj_lookahead", self.servoj_lookahead, *SERVOJ_LOOKAHEAD_RANGE_S)
        _check_range("servoj_gain", self.servoj_gain, *SERVOJ_GAIN_RANGE)
        if type(self.keepalive_cycles) is not int:
            raise _fail("keepalive_cycles", f"must be an int, got {self.keepalive_cycles!r}")
        _check_range("keepalive_cycles", self.keepalive_cycles, *KEEPALIVE_CYCLES_RANGE)
        object.__setattr__(self, "tool_setup", _check_tool_setup(self.tool_setup))


def _number(value: float) -> str:
    """A URScript number literal: whole values without a fraction, others as Python's shortest repr."""
    if float(value).is_integer():
        return str(int(value))
    return repr(float(value))


def _values(params: ScriptParameters) -> dict[str, str]:
    return {
        "SERVER_IP": params.server_ip,
        "REVERSE_PORT": str(params.reverse_port),
        "TRAJECTORY_PORT": str(params.trajectory_port),
        "SCRIPT_COMMAND_PORT": str(params.script_command_port),
        "MULT_JOINTSTATE": str(MULT_JOINTSTATE),
        "SERVOJ_LOOKAHEAD": _number(params.servoj_lookahead),
        "SERVOJ_GAIN": _number(params.servoj_gain),
        "KEEPALIVE_CYCLES": str(params.keepalive_cycles),
        "SPEEDJ_ACCEL": repr(SPEEDJ_ACCELERATION),
        "TOOL_SETUP": "\n".join(params.tool_setup),
        "TARGET_PAYLOAD_CALL": (
            "set_target_payload(raw[2] / UD_MULT, ud_scaled3(raw, 3), ud_scaled6(raw, 6), raw[12] / UD_MULT)"
            if params.controller_version >= TARGET_PAYLOAD_SINCE
            else "set_payload(raw[2] / UD_MULT, ud_scaled3(raw, 3))"
        ),
        # tool_contact exists on e-Series 5.4 and later only; elsewhere: never a contact
        "TOOL_CONTACT_CALL": (
            "tool_contact(direction=get_actual_tcp_speed())"
            if params.controller_version >= TOOL_CONTACT_SINCE
            else "0"
        ),
    }


def render_template(template: str, params: ScriptParameters) -> str:
    """``template`` with every placeholder filled; ValueError if one is unknown or a known one is absent."""
    found = set(_PLACEHOLDER.findall(template))
    unknown = sorted(found - set(PLACEHOLDERS))
    if unknown:
        raise ValueError(f"control script template has unknown placeholders: {', '.join(unknown)}")
    absent = [name for name in PLACEHOLDERS if name not in found]
    if absent:
        # a template without e.g. the reverse port would dial a fixed address: out of step with us
        raise ValueError(f"control script template lacks placeholders: {', '.join(absent)}")
    values = _values(params)
    text = _PLACEHOLDER.sub(lambda match: values[match[1]], template)
    if "{{" in text or "}}" in text:
        # only a malformed tag such as "{{ A B }}" survives the substitution above
        raise ValueError("control script still has placeholder braces after rendering")
    return text


def render_control_script(params: ScriptParameters) -> str:
    """The control script for one robot, from the shipped template."""
    template = resource_path("urscript", TEMPLATE_NAME).read_text(encoding="ascii")
    return render_template(template, params)
