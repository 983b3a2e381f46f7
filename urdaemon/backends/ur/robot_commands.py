"""The UR backend's commands over the robot's links: outputs and the speed slider as RTDE inputs,
the payload, the TCP offset (sent again whenever the control program connects), the force/torque
sensor, the tool voltage, force mode and tool contact as script commands, and dashboard command lines.

Each refuses (``BackendError``, one line naming what is wrong) a value the robot cannot take, a
read-only robot, or a link that is not there; the backend's ``Backend`` methods call these. They send
through ``UrLinks`` (RTDE, primary, dashboard) and the control program's script command link.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from typing import Any

from urdaemon.backends.base import Backend
from urdaemon.backends.ur.links import UrLinks
from urdaemon.backends.ur.servers import CallbackServer
from urdaemon.errors import BackendError, ConnectionLostError, LocalProtocolError
from urdaemon.model import IO_SIZES, TOOL_VOLTAGES
from urdaemon.protocols import dashboard as dash
from urdaemon.protocols import primary as prim
from urdaemon.protocols import script_command

__all__ = ["UR_IO_SIZES", "UrRobotCommands"]

log = logging.getLogger("urdaemon.ur")

UR_IO_SIZES = IO_SIZES
"""A UR controller's IO (model.py's ``IO_SIZES``; the name stays for the backend's users)."""
_VOLTAGES_TEXT = ", ".join(str(v) for v in TOOL_VOLTAGES[:-1]) + f" or {TOOL_VOLTAGES[-1]}"


class UrRobotCommands:
    """The commands of one UR robot: sent through ``links`` (RTDE inputs, the primary interface, the
    dashboard) and ``script_link`` (the control program's script command connection); ``notice``
    tells users a tool contact's outcome, ``name`` is the robot's (for the log)."""

    def __init__(
        self,
        links: UrLinks,
        script_link: CallbackServer,
        *,
        notice: Callable[[str, str], None],
        name: str,
    ) -> None:
        self.links = links
        self.script_link = script_link
        self.notice = notice
        self.name = name
        self._tool_contact_armed = False
        """Tool contact was armed: its one result is still to come."""

    # ---- RTDE inputs --------------------------------------------------------------------------------

    def set_io(self, kind: str, pin: int, value: float | bool) -> None:
        """Set an output through RTDE inputs."""
        Backend.check_io(kind, pin, value, UR_IO_SIZES)
        fields: dict[str, Any] = {}
        if kind == "analog":
            fields = {
                "standard_analog_output_mask": 1 << pin,
                "standard_analog_output_type": 1 << pin,  # voltage
                f"standard_analog_output_{pin}": float(value),
            }
        else:
            prefix = {"digital": "standard", "configurable": "configurable", "tool": "tool"}[kind]
            fields = {
                f"{prefix}_digital_output_mask": 1 << pin,
                f"{prefix}_digital_output": 0xFF if value else 0x00,
            }
        self._send_inputs(fields)

    def set_speed_slider(self, fraction: float) -> None:
        """Set the speed slider through RTDE inputs."""
        if not 0.0 <= fraction <= 1.0:
            raise BackendError(f"speed slider must be within 0..1, got {fraction!r}")
        self._send_inputs({"speed_slider_mask": 1, "speed_slider_fraction": float(fraction)})

    def _send_inputs(self, fields: dict[str, Any]) -> None:
        """One RTDE input package: ``fields`` set, every other input of the recipe 0."""
        self.links.check_commanding()
        self.links.send_inputs(fields)

    # ---- script commands ------------------------------------------------------------------------------

    def set_payload(self, mass: float, cog: tuple[float, float, float]) -> None:
        """Set the payload through the script command socket (or a secondary program without one)."""
        self.links.check_commanding()
        if not all(math.isfinite(v) for v in (mass, *cog)):
            raise BackendError(f"payload mass and centre of gravity must be finite, got {mass!r}, {cog!r}")
        if self.script_link.connected:
            self.script_command(script_command.SetPayload(mass, cog), "the payload")
            return
        x, y, z = cog
        self.links.send_script(prim.sec_program("setup", f"set_payload({mass!r}, [{x!r}, {y!r}, {z!r}])"))

    def set_tcp(self, pose: tuple[float, ...]) -> None:
        """Make ``pose`` the TCP offset: sent now (script command) if the control program is connected,
        else when it connects (``send_tcp``, given the offset the backend kept); refused (BackendError)
        on a read-only robot or if it cannot be sent, and then the backend keeps its old one."""
        self.links.check_commanding()
        if self.script_link.connected:
            self.script_command(script_command.SetTcpOffset(pose), "the TCP offset")

    def send_tcp(self, pose: tuple[float, ...]) -> None:
        """Send the kept TCP offset ``pose``: the control program's script command link just came up (a
        program started anew runs with the installation's TCP until told, e.g. a URCap's pendant program)."""
        if self.links.read_only:
            return
        try:
            self.script_command(script_command.SetTcpOffset(pose), "the TCP offset")
        except (BackendError, ConnectionLostError) as err:  # gone again at once: sent at its next connection
            log.warning("[%s] the TCP offset was not sent to the new control program: %s", self.name, err)

    def set_tool_voltage(self, volts: int) -> None:
        """Set the tool voltage (script command)."""
        if volts not in TOOL_VOLTAGES:
            raise BackendError(f"tool voltage must be {_VOLTAGES_TEXT} V, got {volts!r}")
        self.script_command(script_command.SetToolVoltage(volts), "the tool voltage")

    def tool_contact(self, start: bool) -> None:
        """Arm tool-contact detection, or end it; the result comes back as a ``tool_contact`` notice."""
        message = script_command.StartToolContact() if start else script_command.EndToolContact()
        self.script_command(message, "tool contact")
        if start:  # ending it leaves it armed: the robot answers CANCELED (or a contact crossed the end)
            self._tool_contact_armed = True

    def script_link_lost(self) -> None:
        """The script command link dropped: an armed tool contact's result can no longer come."""
        self._tool_contact_armed = False

    def tool_contact_result(self, event: script_command.ToolContactResult) -> None:
        """The robot's answer to tool contact: a ``tool_contact`` notice (contact or canceled)."""
        if not self._tool_contact_armed:  # nobody asked: not a tool-contact event
            log.warning("[%s] ignored a tool-contact result nobody armed: %s", self.name, event)
            return
        self._tool_contact_armed = False
        outcome = "contact" if event.code == script_command.ToolContactResultCode.SUCCESS else "canceled"
        self.notice("tool_contact", outcome)

    def script_command(self, message: Any, what: str) -> None:
        """Send a script command; BackendError (never a traceback) if it cannot be sent or encoded."""
        try:
            sent = self.script_link.send(message)
        except LocalProtocolError as err:  # e.g. a value beyond what the wire's int32 can carry
            raise BackendError(f"cannot send {what} to the robot: {err}") from None
        if not sent:
            raise BackendError("the control program is not connected (no script command link)")

    # ---- the dashboard --------------------------------------------------------------------------------

    async def dashboard(self, line: str) -> tuple[bool, str]:
        """Send a dashboard command line; (success, the robot's reply)."""
        reply = await self.links.dashboard_command(dash.parse_command(line) or dash.Raw(line))
        text = str(getattr(reply, "text", ""))
        success = getattr(reply, "success", None)
        if isinstance(reply, dash.RawReply):  # a line the codec does not type: the robot's words decide
            success = not dash.is_refusal(text)
        elif success is None:  # a query: it succeeded if it could be read
            success = all(getattr(reply, f, "") is not None for f in ("mode", "state", "running", "remote"))
        return bool(success), text
