"""Backends: the hardware interface per robot (mock, servo; the UR backend arrives later)."""

from __future__ import annotations

from urdaemon.backends.base import Backend, BackendStatistics
from urdaemon.backends.mock import MockBackend
from urdaemon.backends.servo import ServoBackend, ServoMapping

__all__ = ["Backend", "BackendStatistics", "MockBackend", "ServoBackend", "ServoMapping"]
