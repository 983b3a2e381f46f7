"""Zenoh: key layout, message encoding, the daemon's session."""

from __future__ import annotations

from urdaemon.publish.keys import CellKeys, RobotKeys

__all__ = ["CellKeys", "RobotKeys"]
