"""Scripted misbehaviour of the fake controller, for tests: refuse or drop links, stall, mangle bytes.

Each fault names the service it applies to (``rtde``, ``primary``, ``secondary``, ``realtime``,
``dashboard``) or ``*`` for all. Outgoing bytes pass through :meth:`FaultInjector.mangle`, which may
split a write into pieces, garble bytes, or ask the writer to wait before sending.
"""

from __future__ import annotations

import itertools
import random
from dataclasses import dataclass, field

__all__ = ["SERVICES", "FaultInjector", "Mangled"]

SERVICES = ("rtde", "primary", "secondary", "realtime", "dashboard")


@dataclass(frozen=True, slots=True)
class Mangled:
    """What to write instead of one chunk: pieces to write one by one, after ``delay_s``."""

    pieces: tuple[bytes, ...]
    delay_s: float = 0.0


@dataclass
class FaultInjector:
    """The faults in force; change them at any time (the controller reads them on every write)."""

    refused: set[str] = field(default_factory=set)
    """Services whose new connections are closed at once."""
    split: set[str] = field(default_factory=set)
    """Services whose writes are split into random pieces (a peer must reassemble frames)."""
    garble: dict[str, int] = field(default_factory=dict)
    """Service → number of upcoming writes in which one byte is flipped."""
    delay_s: dict[str, float] = field(default_factory=dict)
    """Service → extra delay before every write."""
    stalled_until: float = 0.0
    """Controller time until which nothing is sent on any stream (RTDE data, robot state)."""
    seed: int = 0
    _rng: random.Random = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self._rng = random.Random(self.seed)

    def applies(self, faults: set[str] | dict[str, object], service: str) -> bool:
        """True if ``faults`` names ``service`` or ``*``."""
        return service in faults or "*" in faults

    def is_refused(self, service: str) -> bool:
        """True if new connections to ``service`` must be closed at once."""
        return self.applies(self.refused, service)

    def mangle(self, service: str, data: bytes) -> Mangled:
        """How to send ``data`` on ``service`` under the faults in force."""
        key = service if service in self.garble else "*" if "*" in self.garble else None
        if key is not None and self.garble[key] > 0 and data:
            self.garble[key] -= 1
            at = self._rng.randrange(len(data))
            data = data[:at] + bytes([data[at] ^ 0xFF]) + data[at + 1 :]
        pieces: tuple[bytes, ...] = (data,)
        if self.applies(self.split, service) and len(data) > 1:
            cuts = sorted(self._rng.sample(range(1, len(data)), k=min(3, len(data) - 1)))
            bounds = [0, *cuts, len(data)]
            pieces = tuple(data[a:b] for a, b in itertools.pairwise(bounds))
        delay = self.delay_s.get(service, self.delay_s.get("*", 0.0))
        return Mangled(pieces, delay)
