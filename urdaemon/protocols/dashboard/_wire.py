"""The dashboard's wire: its port, the banner, the line rules, and the words its lines carry (§3.1, §3.2)."""

from __future__ import annotations

import enum
from typing import Final

__all__ = [
    "ASCII_LOWER",
    "ASCII_UPPER",
    "DASHBOARD_BANNER",
    "DASHBOARD_PORT",
    "MAX_LINE_BYTES",
    "PROTOCOL",
    "TRAILING_WHITESPACE",
    "TRAILING_WHITESPACE_BYTES",
    "OperationalMode",
    "ProgramState",
    "UserRole",
]

PROTOCOL: Final = "dashboard"
DASHBOARD_PORT: Final = 29999
"""TCP port of the dashboard server on the robot (§0)."""
DASHBOARD_BANNER: Final = "Connected: Universal Robots Dashboard Server"
"""The first line a G5 server sends after connect (§3.1)."""
MAX_LINE_BYTES: Final = 4096
"""Longest line accepted or sent, in bytes without the ``\\n``; our own cap (urcl reads unbounded)."""

TRAILING_WHITESPACE: Final = " \t\n\v\f\r"  # what urcl's rtrim removes (§3.1)
TRAILING_WHITESPACE_BYTES: Final = TRAILING_WHITESPACE.encode("ascii")
# Case folding of keywords and mode words is ASCII-only, so it never changes a line's length and
# never maps a non-ASCII letter (KELVIN SIGN, dotless i) onto a keyword.
ASCII_LOWER: Final = str.maketrans("ABCDEFGHIJKLMNOPQRSTUVWXYZ", "abcdefghijklmnopqrstuvwxyz")
ASCII_UPPER: Final = str.maketrans("abcdefghijklmnopqrstuvwxyz", "ABCDEFGHIJKLMNOPQRSTUVWXYZ")


class ProgramState(enum.StrEnum):
    """The state word of a ``programState`` reply (§3.2)."""

    STOPPED = "STOPPED"
    PLAYING = "PLAYING"
    PAUSED = "PAUSED"


class OperationalMode(enum.StrEnum):
    """Operational mode words of ``get``/``set operational mode`` (§3.2, e-Series)."""

    NONE = "NONE"
    MANUAL = "MANUAL"
    AUTOMATIC = "AUTOMATIC"


class UserRole(enum.StrEnum):
    """User role words of ``setUserRole``/``getUserRole`` (§3.2, CB3 only)."""

    PROGRAMMER = "PROGRAMMER"
    OPERATOR = "OPERATOR"
    NONE = "NONE"
    LOCKED = "LOCKED"
    RESTRICTED = "RESTRICTED"
