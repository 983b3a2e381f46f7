"""The UR backend's services over the robot's links: outputs and the speed slider as RTDE inputs,
the payload, the TCP offset (kept, and sent again whenever the control program connects), the
force/torque sensor, the tool voltage, force mode and tool contact as script
commands, and dashboard command lines.

Each refuses (``BackendError``, one line naming what is wrong) a value the robot cannot take, a
read-only robot, or a link that is not there; the backend's ``Backend`` methods call these.
"""

from __future__ import annotations

import asyncio
import logging
import math
from typing import TYPE_CHECKING, Any

from urdaemon.errors import BackendError, ConnectionLostError, LocalProtocolError, UrTimeoutError
from urdaemon.model import IO_SIZES, TOOL_VOLTAGES
from urdaemon.protocols import dashboard as dash
from urdaemon.protocols import primary as prim
from urdaemon.protocols import script_command
from urdaemon.protocols.rtde_variables import DOUBLE, INPUT_VARIABLES

if TYPE_CHECKING:
    from urdaemon.backends.ur.backend import UrBackend

__all__ = ["UR_IO_SIZES", "UrServices"]

log = logging.getLogger("urdaemon.ur")

UR_IO_SIZES = IO_SIZES
"""A UR controller's IO (model.py's ``IO_SIZES``; the name stays for the backend's users)."""
_DOUBLE_INPUTS = frozenset(name for name, kind in INPUT_VARIABLES.items() if kind == DOUBLE)
"""The RTDE inputs sent as doubles (the rest of an input package are integers)."""
_VOLTAGES_TEXT = ", ".join(str(v) for v in TOOL_VOLTAGES[:-1]) + f" or {TOOL_VOLTAGES[-1]}"


class UrServices:
    """The services of one UR backend (``ur``: the backend whose links they use)."""

    def __init__(self, ur: UrBackend) -> None:
        self.ur = ur
        self.tool_contact_armed = False
        """Tool contact was armed: its one result is still to come."""
        ur.tcp = ur.check_tcp(ur.robot.tcp)  # the cell file's until set_tcp; sent as the program connects

    def check_commanding(self) -> None:
        """Refuse a read-only robot."""
        if self.ur.options.read_only:
            raise BackendError("read-only robot (ur.read_only: true): it is watched, not commanded")

    # ---- RTDE inputs --------------------------------------------------------------------------------

    def set_io(self, kind: str, pin: int, value: float | bool) -> None:
        """Set an output through RTDE inputs."""
        self.ur.check_io(kind, pin, value, UR_IO_SIZES)
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
        self.send_inputs(fields)

    def set_speed_slider(self, fraction: float) -> None:
        """Set the speed slider through RTDE inputs."""
        if not 0.0 <= fraction <= 1.0:
            raise BackendError(f"speed slider must be within 0..1, got {fraction!r}")
        self.send_inputs({"speed_slider_mask": 1, "speed_slider_fraction": float(fraction)})

    def send_inputs(self, fields: dict[str, Any]) -> None:
        """One RTDE input package: ``fields`` set, every other input of the recipe 0."""
        self.check_commanding()
        rtde = self.ur._rtde
        if rtde is None:
            raise BackendError("not connected to the robot")
        values = []
        for name in self.ur._inputs:
            value = fields.get(name, 0)
            values.append(float(value) if name in _DOUBLE_INPUTS else int(value))
        rtde.send_inputs(values)

    # ---- script commands ------------------------------------------------------------------------------

    def set_payload(self, mass: float, cog: tuple[float, float, float]) -> None:
        """Set the payload through the script command socket (or a secondary program without one)."""
        self.check_commanding()
        if not all(math.isfinite(v) for v in (mass, *cog)):
            raise BackendError(f"payload mass and centre of gravity must be finite, got {mass!r}, {cog!r}")
        if self.ur.servers.script_command.connected:
            self.script_command(script_command.SetPayload(mass, cog), "the payload")
            return
        primary = self.ur._primary
        if primary is None:
            raise BackendError("not connected to the robot")
        x, y, z = cog
        primary.send_script(prim.sec_program("setup", f"set_payload({mass!r}, [{x!r}, {y!r}, {z!r}])"))

    def set_tcp(self, pose: tuple[float, ...]) -> None:
        """Make ``pose`` the TCP offset: sent now (script command) if the control program is connected,
        else when it connects (``send_tcp``); kept either way, so the controller's TCP is the daemon's."""
        self.check_commanding()
        if self.ur.servers.script_command.connected:
            self.script_command(script_command.SetTcpOffset(pose), "the TCP offset")
        self.ur.tcp = pose

    def send_tcp(self) -> None:
        """Send the kept TCP offset: the control program's script command link just came up (a program
        started anew runs with the installation's TCP until told, e.g. a URCap's pendant program)."""
        if self.ur.options.read_only:
            return
        try:
            self.script_command(script_command.SetTcpOffset(self.ur.tcp), "the TCP offset")
        except (BackendError, ConnectionLostError) as err:  # gone again at once: sent at its next connection
            log.warning("[%s] the TCP offset was not sent to the new control program: %s", self.ur.name, err)

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
            self.tool_contact_armed = True

    def tool_contact_result(self, event: script_command.ToolContactResult) -> None:
        """The robot's answer to tool contact: a ``tool_contact`` notice (contact or canceled)."""
        if not self.tool_contact_armed:  # nobody asked: not a tool-contact event
            log.warning("[%s] ignored a tool-contact result nobody armed: %s", self.ur.name, event)
            return
        self.tool_contact_armed = False
        outcome = "contact" if event.code == script_command.ToolContactResultCode.SUCCESS else "canceled"
        self.ur.notice("tool_contact", outcome)

    def script_command(self, message: Any, what: str) -> None:
        """Send a script command; BackendError (never a traceback) if it cannot be sent or encoded."""
        try:
            sent = self.ur.servers.script_command.send(message)
        except LocalProtocolError as err:  # e.g. a value beyond what the wire's int32 can carry
            raise BackendError(f"cannot send {what} to the robot: {err}") from None
        if not sent:
            raise BackendError("the control program is not connected (no script command link)")

    # ---- the dashboard --------------------------------------------------------------------------------

    async def query(self, line: str, timeout: float) -> str:
        """Send a dashboard line and return the reply's text within ``timeout`` s (``UrTimeoutError``
        after it; the link is dropped then, as its late reply would answer the next command)."""
        command = dash.parse_command(line) or dash.Raw(line)
        ur = self.ur
        timeout = max(timeout, 0.001)
        try:  # a connection that does not come is given up within the time too (nothing sent yet)
            link = await asyncio.wait_for(ur._dashboard_link(), timeout)
        except TimeoutError:
            raise UrTimeoutError(f"dashboard: not connected within {timeout:.1f} s") from None
        try:
            reply = await link.command(command, timeout=timeout)
        except (ConnectionLostError, UrTimeoutError):
            ur._drop_dashboard()
            raise
        return str(getattr(reply, "text", ""))

    async def dashboard(self, line: str) -> tuple[bool, str]:
        """Send a dashboard command line; (success, the robot's reply)."""
        command = dash.parse_command(line) or dash.Raw(line)
        ur = self.ur
        try:
            reply = await (await ur._dashboard_link()).command(command)
        except ConnectionLostError:
            ur._drop_dashboard()  # the dashboard dropped: connect once more
            reply = await (await ur._dashboard_link()).command(command)
        except UrTimeoutError:
            ur._drop_dashboard()  # its late reply would be read as the next command's answer
            raise
        text = str(getattr(reply, "text", ""))
        success = getattr(reply, "success", None)
        if isinstance(reply, dash.RawReply):  # a line the codec does not type: the robot's words decide
            success = not dash.is_refusal(text)
        elif success is None:  # a query: it succeeded if it could be read
            success = all(getattr(reply, f, "") is not None for f in ("mode", "state", "running", "remote"))
        return bool(success), text
