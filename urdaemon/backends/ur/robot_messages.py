"""What the UR robot tells its users on the primary interface: messages, runtime errors, and the
calibration check of its kinematics against the configured one.

Each message becomes a notice (``robot_message``) and is kept among the last ``KEPT_MESSAGES``; a
runtime exception or error code is also what the controller said when the program ended.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

from urdaemon.backends.ur.primary_link import FIRST_STATE_TIMEOUT_S, PrimaryLink
from urdaemon.backends.ur.program import ControlProgram
from urdaemon.errors import RobotFaultError
from urdaemon.protocols import primary as prim

__all__ = ["KEPT_MESSAGES", "KINEMATICS_TIMEOUT_S", "RobotMessages"]

log = logging.getLogger("urdaemon.ur")

KINEMATICS_TIMEOUT_S = FIRST_STATE_TIMEOUT_S
"""How long the calibration check waits for the kinematics (the primary link's first state package)."""
KEPT_MESSAGES = 20


class RobotMessages:
    """The robot's messages of one backend, told through ``notice(kind, text)``."""

    __slots__ = (
        "_mismatch_told",
        "calibration_ok",
        "controller_version",
        "name",
        "notice",
        "program",
        "recent",
    )

    def __init__(self, name: str, notice: Callable[[str, str], None], program: ControlProgram) -> None:
        self.name = name
        self.notice = notice
        self.program = program
        """Whose ``ended`` a runtime exception or error code sets."""
        self.recent: list[str] = []
        """The last ``KEPT_MESSAGES`` texts."""
        self.calibration_ok: bool | None = None
        """Whether the robot's kinematics hash is the configured one (None: not checked yet)."""
        self.controller_version: dict[str, Any] | None = None
        """The controller's software as its VERSION message named it (None: not said yet); kept
        after the link drops, until a new connection says it again (``urdaemon info`` shows it)."""
        self._mismatch_told: str | None = None
        """The robot's kinematics hash a mismatch was last logged for: a reconnection that finds the
        same one logs nothing again (a match in between forgets it); its event goes out every time."""

    def on_message(self, message: Any) -> None:
        """One message from the primary interface."""
        text = ""
        if isinstance(message, prim.VersionMessage):
            self.controller_version = {
                "project": message.project_name,
                "major": message.major_version,
                "minor": message.minor_version,
                "bugfix": message.bugfix_version,
                "build": message.build_number,
                "date": message.build_date,
            }
        elif isinstance(message, prim.RuntimeExceptionMessage):
            text = f"runtime exception at {message.line}:{message.column}: {message.text}"
            log.warning("[%s] %s", self.name, text)
            self.program.ended = text
        elif isinstance(message, prim.ErrorCodeMessage):
            text = f"error C{message.code}A{message.argument}: {message.text}"
            log.warning("[%s] %s", self.name, text)
            self.program.ended = text
        elif isinstance(message, prim.TextMessage | prim.KeyMessage):
            text = (
                message.text if isinstance(message, prim.TextMessage) else f"{message.title}: {message.text}"
            )
            log.info("[%s] robot: %s", self.name, text)
        if text:
            self.report("robot_message", text)

    def report(self, kind: str, text: str) -> None:
        """Keep the text among the last robot messages and publish it as a notice of this kind."""
        self.recent = [*self.recent[-(KEPT_MESSAGES - 1) :], text]
        self.notice(kind, text)

    async def check_calibration(self, primary: PrimaryLink, expected_hash: str | None, check: str) -> None:
        """Compare the robot's kinematics hash with ``expected_hash``: a mismatch is a warning and a
        ``calibration_mismatch`` notice, or RobotFaultError when ``check`` is ``"error"``."""
        kinematics = await primary.wait_kinematics(KINEMATICS_TIMEOUT_S)
        actual = kinematics.kinematics_hash()
        self.calibration_ok = expected_hash is None or actual == expected_hash
        if self.calibration_ok:
            self._mismatch_told = None
        else:
            text = (
                f"the robot's kinematics hash is {actual}, the configured calibration's is "
                f"{expected_hash}: the URDF does not match this robot "
                "(write its calibration with `urdaemon calibration`)"
            )
            if check == "error":
                raise RobotFaultError(text)
            if actual != self._mismatch_told:  # the log says it once; the event goes out on every
                self._mismatch_told = actual  # connection (events are not kept: a late subscriber
                log.warning("[%s] %s", self.name, text)  # hears it on the next reconnection)
            self.report("calibration_mismatch", text)
