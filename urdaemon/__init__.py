"""urdaemon: drive a cell of Universal Robots arms (and generic servo arms) over Zenoh, without ROS."""

from __future__ import annotations

from urdaemon.errors import (
    BackendError,
    ConfigError,
    ControlError,
    DescriptionError,
    GoalRejected,
    MessageError,
    UrDaemonError,
    UrTimeoutError,
)

__version__ = "0.1.0"

__all__ = [
    "BackendError",
    "ConfigError",
    "ControlError",
    "DescriptionError",
    "GoalRejected",
    "MessageError",
    "UrDaemonError",
    "UrTimeoutError",
    "__version__",
]
