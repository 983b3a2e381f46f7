"""Keyboard teleop's pure part: keys and the time in, the twist to send out (no terminal, no clock).

The keys (the generic-robot template's keyboard teleop, plus a frame key):

    q w e r t y   +x +y +z +rx +ry +rz        i / k   faster / slower (x SPEED_STEP)
    a s d f g h   -x -y -z -rx -ry -rz        l       stop (zero twist at once)
    b             toggle the frame: base <-> tool
    x, Esc, Ctrl-C, Ctrl-D                    quit

A terminal reports no key releases, only characters: while a key is held its auto-repeat sends it
again and again. So a motion key holds its axis for ``release_s`` (``RELEASE_S``) after its last
character; when no motion key came within that window the twist is zero (the robot decelerates,
and the daemon's deadman stops it anyway once twists stop coming). One axis moves at a time: the
last motion key's (a terminal repeats only the last key held). The TCP point moves at ``speed``
(m/s) along a linear axis; a rotation key turns the TCP frame at ``ANGULAR_PER_LINEAR`` x ``speed``
(rad/s).

``TeleopKeys`` is the state machine (``feed(key, now)``, ``twist(now)``); ``keys_of`` splits what the
terminal sent into keys; ``status_line`` is the one live line the teleop shell rewrites.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import NamedTuple, TypeGuard

from urdaemon.publish.state_encoder import rotation_vector_of_quaternion

__all__ = [
    "ANGULAR_PER_LINEAR",
    "DEFAULT_SPEED",
    "FRAMES",
    "HELP",
    "MAX_SPEED",
    "MIN_SPEED",
    "MOTION_KEYS",
    "QUIT",
    "RELEASE_S",
    "SPEED_STEP",
    "TeleopKeys",
    "Twist",
    "keys_of",
    "rotation_vector",
    "status_line",
]

MOTION_KEYS: dict[str, tuple[int, int]] = {
    "q": (0, 1),
    "w": (1, 1),
    "e": (2, 1),
    "r": (3, 1),
    "t": (4, 1),
    "y": (5, 1),
    "a": (0, -1),
    "s": (1, -1),
    "d": (2, -1),
    "f": (3, -1),
    "g": (4, -1),
    "h": (5, -1),
}
"""Motion key -> (twist axis 0..5 = vx vy vz wx wy wz, sign)."""
AXIS_NAMES = ("x", "y", "z", "rx", "ry", "rz")
FASTER, SLOWER, STOP, FRAME_KEY = "i", "k", "l", "b"
ESC = "esc"
"""The token ``keys_of`` gives for a lone Escape (an escape sequence, e.g. an arrow key, is dropped)."""
QUIT = frozenset({"x", ESC, "\x03", "\x04"})
"""Keys that end teleop: x, Esc, Ctrl-C (a raw terminal delivers it as a character), Ctrl-D."""
FRAMES = ("base", "tool")

RELEASE_S = 0.15
"""A motion key holds its axis this long after its last character (a held key's auto-repeat comes
every ~30-50 ms once it started); no motion key within it: zero twist."""
DEFAULT_SPEED = 0.1
"""m/s of the TCP point at start (``urdaemon teleop --speed``)."""
MIN_SPEED = 0.005
MAX_SPEED = 0.5
"""The range i/k and --speed keep to, m/s (the daemon caps twists at the cell's max_speed too)."""
SPEED_STEP = 1.25
"""i multiplies the speed by this, k divides by it."""
ANGULAR_PER_LINEAR = 3.0
"""A rotation key turns at this many rad/s per m/s of ``speed`` (0.1 m/s -> 0.3 rad/s): the ratio
of the cell file's default caps (max_angular_speed 3.0 rad/s, max_speed 1.0 m/s)."""


HELP = (
    "q w e r t y: +x +y +z +rx +ry +rz   a s d f g h: -x -y -z -rx -ry -rz   "
    "i/k: faster/slower   l: stop   b: base/tool frame   x, Esc, Ctrl-C: quit"
)
"""The keys, as the teleop shell shows them when it starts."""


class Twist(NamedTuple):
    """A twist as ``RobotClient.twist`` sends it: the TCP point's velocity and the angular velocity."""

    linear: tuple[float, float, float]
    angular: tuple[float, float, float]

    @property
    def zero(self) -> bool:
        """Whether nothing moves."""
        return not any(self.linear) and not any(self.angular)


ZERO = Twist((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))


class TeleopKeys:
    """The teleop state machine: speed, frame, the held axis and whether to quit; time passed in."""

    def __init__(
        self, speed: float = DEFAULT_SPEED, frame: str = "base", release_s: float = RELEASE_S
    ) -> None:
        if frame not in FRAMES:
            raise ValueError(f"frame must be one of {', '.join(FRAMES)}, got {frame!r}")
        if not (math.isfinite(speed) and MIN_SPEED <= speed <= MAX_SPEED):
            raise ValueError(f"speed must be within {MIN_SPEED}..{MAX_SPEED} m/s, got {speed}")
        self.speed = speed
        self.frame = frame
        self.release_s = release_s
        self.done = False
        """Set by a quit key: the shell ends."""
        self._held: tuple[int, int] | None = None
        self._last = -math.inf

    @property
    def angular_speed(self) -> float:
        """rad/s of a rotation key at the current speed."""
        return ANGULAR_PER_LINEAR * self.speed

    def feed(self, key: str, now: float) -> str | None:
        """Take one key at time ``now`` (s, any monotonic clock); what it did: ``"move"``, ``"speed"``,
        ``"frame"``, ``"stop"``, ``"quit"``, or None for a key with no meaning (ignored)."""
        if key in QUIT:
            self.done = True
            self._held = None
            return "quit"
        key = key.lower()
        motion = MOTION_KEYS.get(key)
        if motion is not None:
            self._held, self._last = motion, now
            return "move"
        if key in (FASTER, SLOWER):
            factor = SPEED_STEP if key == FASTER else 1.0 / SPEED_STEP
            self.speed = min(MAX_SPEED, max(MIN_SPEED, self.speed * factor))
            return "speed"
        if key == STOP:
            self._held = None
            return "stop"
        if key == FRAME_KEY:
            self.frame = FRAMES[(FRAMES.index(self.frame) + 1) % len(FRAMES)]
            return "frame"
        return None

    def moving(self, now: float) -> str | None:
        """The held axis as shown (``"+y"``, ``"-rz"``), None when no motion key holds one at ``now``."""
        if self._held is None or now - self._last > self.release_s:
            return None
        axis, sign = self._held
        return f"{'+' if sign > 0 else '-'}{AXIS_NAMES[axis]}"

    def twist(self, now: float) -> Twist:
        """The twist to send at ``now``: the held axis at the current speed, zero when none is held."""
        if self._held is None or now - self._last > self.release_s:
            return ZERO
        axis, sign = self._held
        values = [0.0] * 6
        values[axis] = sign * (self.speed if axis < 3 else self.angular_speed)
        return Twist((values[0], values[1], values[2]), (values[3], values[4], values[5]))


def keys_of(chunk: str) -> list[str]:
    """The keys in what a raw terminal delivered at once: one per character, a lone Escape as
    ``ESC``; an escape sequence (Esc followed by ``[`` or ``O`` and its characters, e.g. an arrow
    key) is no key at all and is dropped."""
    keys: list[str] = []
    i = 0
    while i < len(chunk):
        char = chunk[i]
        if char != "\x1b":
            keys.append(char)
            i += 1
            continue
        if i + 1 < len(chunk) and chunk[i + 1] in "[O":
            i += 2
            while i < len(chunk) and not ("@" <= chunk[i] <= "~"):  # parameters up to the final byte
                i += 1
            i += 1
            continue
        keys.append(ESC)
        i += 1
    return keys


def rotation_vector(quaternion: Sequence[float]) -> tuple[float, float, float]:
    """The rotation vector (rx, ry, rz; angle in [0, pi]) of a unit quaternion (x, y, z, w), as the
    daemon's ``tcp_pose`` gives it in ``pose``."""
    x, y, z, w = (float(v) for v in quaternion)
    return rotation_vector_of_quaternion(x, y, z, w)


def status_line(robot: str, pose: Mapping[str, object] | None, keys: TeleopKeys, now: float) -> str:
    """The live line: the TCP pose from the last ``tcp_pose`` message (None: none yet), the speed,
    the frame and what moves."""
    shown = "waiting for tcp_pose"
    if pose is not None:
        position, orientation = pose.get("position"), pose.get("orientation")
        if _numbers(position, 3) and _numbers(orientation, 4):
            rx, ry, rz = rotation_vector(orientation)
            x, y, z = position
            shown = f"x {x:+.4f} y {y:+.4f} z {z:+.4f} m  rx {rx:+.3f} ry {ry:+.3f} rz {rz:+.3f} rad"
    moving = keys.moving(now) or "stopped"
    return (
        f"{robot}: {shown} | {keys.speed:.3f} m/s {keys.angular_speed:.2f} rad/s | "
        f"frame {keys.frame} | {moving}"
    )


def _numbers(value: object, count: int) -> TypeGuard[list[float]]:
    return (
        isinstance(value, list)
        and len(value) == count
        and all(isinstance(v, int | float) and math.isfinite(v) for v in value)
    )
