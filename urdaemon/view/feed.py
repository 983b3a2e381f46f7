"""The newest messages of one robot, kept as Zenoh's threads deliver them and read by the view's loops.

A robot publishes ``joint_states`` at up to 500 Hz; the view draws at ~30 Hz. It follows no
``tcp_pose``: the daemon would compute, encode and put it every cycle for the view, which draws the
TCP from the joints and the status's ``tcp`` (scene.py). So a callback only
keeps the newest payload (bytes, no decoding on Zenoh's thread) and counts it; the display task
decodes the newest one when it draws. Events are kept as the last few; a ``command_rejected`` one
is also handed to the loop (``on_rejected``), where the robot's control decides what it means.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

__all__ = ["EVENTS_KEPT", "STALE_S", "JointSample", "RobotFeed"]

EVENTS_KEPT = 6
"""The events a robot's panel shows (the newest last)."""
STALE_S = 1.0
"""A robot whose newest ``joint_states`` is older than this is shown as disconnected."""


@dataclass(frozen=True, slots=True)
class JointSample:
    """One decoded ``joint_states`` message."""

    names: tuple[str, ...]
    positions: tuple[float, ...]
    velocities: tuple[float, ...]
    received: float
    """``time.monotonic()`` when it arrived."""


class RobotFeed:
    """The newest ``joint_states`` and ``status`` of one robot, and its last events."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.joint_states_count = 0
        """``joint_states`` messages received (a test waits on it)."""
        self._joints: tuple[bytes, float] | None = None
        self._decoded: tuple[bytes, JointSample] | None = None
        self._status: bytes | None = None
        self.events: deque[str] = deque(maxlen=EVENTS_KEPT)
        self.replaced = 0
        """Stream samples the daemon replaced by a newer one before reading them (counted, not listed:
        on a busy machine they come often and would push every other event out)."""
        self.on_rejected: Callable[[str, str], None] | None = None
        """Called on the loop with (key, reason) for each ``command_rejected`` event."""
        self._loop: asyncio.AbstractEventLoop | None = None
        self._subs: list[Any] = []
        self.first_joint_states = asyncio.Event()
        """Set (on the loop) once the first ``joint_states`` came."""

    def subscribe(self, session: Any, keys: Any, loop: asyncio.AbstractEventLoop) -> None:
        """Follow the robot of ``keys`` (``RobotKeys``) on ``session``; ``close`` ends it."""
        self._loop = loop
        for key, callback in (
            (keys.joint_states, self._on_joint_states),
            (keys.status, self._on_status),
            (keys.events, self._on_event),
        ):
            self._subs.append(session.declare_subscriber(key, callback))

    def close(self) -> None:
        """Stop following the robot."""
        for sub in self._subs:
            with contextlib.suppress(Exception):
                sub.undeclare()
        self._subs.clear()

    # ------------------------------------------------------------------ on Zenoh's threads

    def _on_joint_states(self, sample: Any) -> None:
        self._joints = (sample.payload.to_bytes(), time.monotonic())
        self.joint_states_count += 1
        if self.joint_states_count == 1 and self._loop is not None:
            with contextlib.suppress(RuntimeError):  # the loop has closed
                self._loop.call_soon_threadsafe(self.first_joint_states.set)

    def _on_status(self, sample: Any) -> None:
        self._status = sample.payload.to_bytes()

    def _on_event(self, sample: Any) -> None:
        event = _json_object(sample.payload.to_bytes())
        if event is None:
            return
        if event.get("kind") == "command_rejected" and str(event.get("reason", "")).startswith("busy:"):
            self.replaced += 1
        else:
            self.events.append(event_text(event))
        loop, handler = self._loop, self.on_rejected
        if event.get("kind") == "command_rejected" and loop is not None and handler is not None:
            with contextlib.suppress(RuntimeError):  # the loop has closed
                loop.call_soon_threadsafe(handler, str(event.get("key", "")), str(event.get("reason", "")))

    # ------------------------------------------------------------------ readers

    def joints(self) -> JointSample | None:
        """The newest ``joint_states``, decoded (once per message), or None before the first."""
        newest = self._joints
        if newest is None:
            return None
        payload, received = newest
        decoded = self._decoded
        if decoded is not None and decoded[0] is payload:
            return decoded[1]
        data = _json_object(payload)
        if data is None:
            return None
        try:
            sample = JointSample(
                tuple(str(n) for n in data["names"]),
                tuple(_number(p) for p in data["position"]),
                tuple(_number(v) for v in data.get("velocity") or [0.0] * len(data["position"])),
                received,
            )
        except (KeyError, TypeError, ValueError):
            return None
        self._decoded = (payload, sample)
        return sample

    def stale(self, now: float) -> bool:
        """Whether no ``joint_states`` came within ``STALE_S`` of ``now`` (``time.monotonic()``)."""
        newest = self._joints
        return newest is None or now - newest[1] > STALE_S

    def last_events(self) -> list[str]:
        """The last events, oldest first (a copy: Zenoh's threads append meanwhile)."""
        return list(self.events)  # one C call under the GIL: never sees the deque half changed

    def status(self) -> dict[str, Any] | None:
        """The newest ``status`` message."""
        return None if self._status is None else _json_object(self._status)


def event_text(event: dict[str, Any]) -> str:
    """One short line about an event (its kind, then what it says)."""
    kind = str(event.get("kind", "event"))
    detail = event.get("reason") or event.get("text") or event.get("action") or ""
    if kind == "lease":
        detail = f"{event.get('action', '')} {event.get('holder', '')}".strip()
    return f"{kind}: {str(detail)[:160]}" if detail else kind


def _json_object(payload: bytes) -> dict[str, Any] | None:
    try:
        data = json.loads(payload)
    except ValueError:
        return None
    return data if isinstance(data, dict) else None


def _number(value: object) -> float:
    """A published number (``null`` stands for NaN, which is never published)."""
    return float("nan") if value is None else float(value)  # type: ignore[arg-type]
