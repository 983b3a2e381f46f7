"""Zenoh: key layout, message encoding, the robot services declared once (services.py), the session."""

from __future__ import annotations

from urdaemon.publish.keys import CellKeys, RobotKeys

__all__ = ["CellKeys", "RobotKeys"]
