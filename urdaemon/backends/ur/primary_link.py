"""The daemon's primary-interface link (30001): version, kinematics, script upload, runtime messages."""

from __future__ import annotations

import asyncio
import logging
from collections import deque
from collections.abc import Callable
from typing import Any

from urdaemon.errors import UrTimeoutError
from urdaemon.protocols import primary as prim
from urdaemon.protocols._buffer import Side
from urdaemon.shell import Shell, connect

__all__ = ["FIRST_STATE_TIMEOUT_S", "PRIMARY_PORT", "PrimaryLink"]

PRIMARY_PORT = prim.PRIMARY_PORT
FIRST_STATE_TIMEOUT_S = 10.0
"""How long a client waits for the first state package (with the kinematics) after connecting: urcl
waits up to 10 s (docs/protocols.md §6.7)."""
KEPT_MESSAGES = 50
"""Robot messages kept for the status and for diagnosing a failed program."""

log = logging.getLogger("urdaemon.ur")


class PrimaryLink(Shell):
    """One primary-interface connection (the shell around ``PrimaryConnection``); it reads from the
    moment it connects, and ``run()`` waits until the connection ends."""

    def __init__(self, on_message: Callable[[Any], None]) -> None:
        super().__init__(prim.PrimaryConnection(Side.DAEMON), "primary", self._on_event)
        self.conn: prim.PrimaryConnection = self.codec
        self.on_message = on_message
        self.version: prim.VersionMessage | None = None
        self.kinematics: prim.KinematicsInfo | None = None
        self.configuration: prim.ConfigurationData | None = None
        self.robot_mode: prim.RobotModeData | None = None
        self.messages: deque[Any] = deque(maxlen=KEPT_MESSAGES)
        self.kinematics_seen = asyncio.Event()

    @classmethod
    async def connect(
        cls, host: str, on_message: Callable[[Any], None], *, port: int = PRIMARY_PORT, timeout: float = 5.0
    ) -> PrimaryLink:
        """Open the connection."""
        return await connect(lambda: cls(on_message), host, port, timeout=timeout, name="primary")

    async def run(self) -> None:
        """Wait until the connection ends: ConnectionLostError, or RemoteProtocolError on bad bytes."""
        raise await asyncio.shield(self.closed)

    def send_script(self, text: str) -> None:
        """Send URScript text (a program, a ``sec`` program or a controller command line)."""
        self.conn.send(prim.Script(text))
        self.flush()

    async def wait_kinematics(self, timeout: float) -> prim.KinematicsInfo:
        """The robot's KINEMATICS_INFO (UrTimeoutError if none arrives within ``timeout``)."""
        try:
            await asyncio.wait_for(self.kinematics_seen.wait(), timeout)
        except TimeoutError as err:
            raise UrTimeoutError(f"primary: no KINEMATICS_INFO within {timeout} s") from err
        assert self.kinematics is not None
        return self.kinematics

    def _on_event(self, event: Any) -> None:
        if isinstance(event, prim.RobotState):
            for sub in event.subpackages:
                if isinstance(sub, prim.KinematicsInfo):
                    self.kinematics = sub
                    self.kinematics_seen.set()
                elif isinstance(sub, prim.ConfigurationData):
                    self.configuration = sub
                elif isinstance(sub, prim.RobotModeData):
                    self.robot_mode = sub
            return
        if isinstance(event, prim.VersionMessage):
            self.version = event
        if isinstance(event, prim.OtherPackage):
            return
        self.messages.append(event)
        self.on_message(event)
