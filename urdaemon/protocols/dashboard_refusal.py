"""How a controller's dashboard answer reads when it refuses a line (wire facts of
docs/protocols.md §3.2), apart from the dashboard codec so that what only needs to name them (the
service table's help text) does not load the codec.
"""

from __future__ import annotations

from typing import Final

__all__ = ["REFUSAL_PREFIXES", "is_refusal"]

REFUSAL_PREFIXES: Final = ("could not understand", "failed to execute", "error")
"""How a controller's answer starts, lower-cased, when it refuses a line: what the daemon reads as a
refusal of a line the codec does not type (§3.2 does not enumerate failure texts; these are the
ones it quotes, and ``error`` for the rest)."""


def is_refusal(text: str) -> bool:
    """Whether an answer to a line the codec does not type says it was refused (an empty one does)."""
    lowered = text.strip().lower()
    return not lowered or lowered.startswith(REFUSAL_PREFIXES)
