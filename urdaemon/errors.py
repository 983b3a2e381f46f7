"""The one exception tree of urdaemon.

::

    UrDaemonError
    ├── ConfigError(ValueError)          a cell file or calibration file is wrong; names file and key path
    ├── DescriptionError                 the robot description (xacro/URDF/model data) cannot be built
    ├── ProtocolError                    a wire format was violated
    │   ├── LocalProtocolError           we tried to send something illegal
    │   └── RemoteProtocolError          the peer sent something illegal
    ├── ConnectionLostError(ConnectionError)
    ├── UrTimeoutError(TimeoutError)
    ├── BackendError                     a backend refused or failed a request
    ├── RobotFaultError                  protective stop, emergency stop, program stopped
    ├── ControlError                     ruckig failure, limit violation
    ├── GoalRejected                     a goal or command was refused before any motion; carries the reason
    └── MessageError(ValueError)         a message from a client could not be decoded or validated
"""

from __future__ import annotations

__all__ = [
    "BackendError",
    "ConfigError",
    "ConnectionLostError",
    "ControlError",
    "DescriptionError",
    "GoalRejected",
    "LocalProtocolError",
    "MessageError",
    "ProtocolError",
    "RemoteProtocolError",
    "RobotFaultError",
    "UrDaemonError",
    "UrTimeoutError",
]


class UrDaemonError(Exception):
    """Root of every error urdaemon raises on purpose."""


class ConfigError(UrDaemonError, ValueError):
    """A configuration file is invalid; the message names the file, the key path and the reason."""

    def __init__(self, message: str, *, errors: list[str] | None = None) -> None:
        super().__init__(message)
        self.errors: list[str] = errors if errors is not None else [message]


class DescriptionError(UrDaemonError):
    """The cell description (model data, xacro, URDF) could not be built or read."""


class ProtocolError(UrDaemonError):
    """A wire protocol was violated; never raised directly."""

    def __init__(self, message: str, *, protocol: str = "", offset: int | None = None) -> None:
        if type(self) is ProtocolError:
            raise TypeError("ProtocolError is abstract; raise LocalProtocolError or RemoteProtocolError")
        super().__init__(message)
        self.protocol = protocol
        self.offset = offset


class LocalProtocolError(ProtocolError):
    """We tried to send something the protocol does not allow."""


class RemoteProtocolError(ProtocolError):
    """The peer sent something the protocol does not allow."""


class ConnectionLostError(UrDaemonError, ConnectionError):
    """A link to a robot or a client dropped."""


class UrTimeoutError(UrDaemonError, TimeoutError):
    """Something expected did not happen in time."""


class BackendError(UrDaemonError):
    """A backend refused or failed a request (set IO, payload, ...)."""


class RobotFaultError(UrDaemonError):
    """The robot is in a state that forbids motion (protective stop, emergency stop, program stopped)."""


class ControlError(UrDaemonError):
    """Motion planning or tracking failed (ruckig error, limit violation)."""


class GoalRejected(UrDaemonError):
    """A goal or command was refused before any motion; ``reason`` says why."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


class MessageError(UrDaemonError, ValueError):
    """A message from a client could not be decoded or is not valid."""
