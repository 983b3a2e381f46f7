"""Joint angle → servo pulse width, the one mapping every output of a servo arm shares."""

from __future__ import annotations

import math
from collections.abc import Sequence

from urdaemon.cell.servo import ServoOptions
from urdaemon.errors import ConfigError

__all__ = ["ServoMapping"]


class ServoMapping:
    """The pulse (µs) of each configured joint, in the order of the cell file's ``joints``."""

    def __init__(self, joint_names: Sequence[str], prefix: str, options: ServoOptions) -> None:
        by_name = {f"{prefix}{j.name}": j for j in options.joints}
        unknown = sorted(name.removeprefix(prefix) for name in set(by_name) - set(joint_names))
        own = ", ".join(name.removeprefix(prefix) for name in joint_names)
        if unknown:
            raise ConfigError(
                f"servo.joints: {', '.join(unknown)} not in the robot's description (its joints: {own})"
            )
        unmapped = [name.removeprefix(prefix) for name in joint_names if name not in by_name]
        if unmapped:
            raise ConfigError(
                f"servo.joints: the description's joint(s) {', '.join(unmapped)} have no servo channel; "
                "list each joint with its channel"
            )
        self._names = tuple(j.name for j in options.joints)
        self.channels = tuple(j.channel for j in options.joints)
        """Each configured joint's output channel."""
        # (joint index, angle_min, angle span, pulse_min, pulse span, offset, direction)
        self._joints = [
            (
                joint_names.index(name),
                j.angle_min,
                j.angle_max - j.angle_min,
                j.pulse_min_us,
                j.pulse_max_us - j.pulse_min_us,
                j.offset,
                float(j.direction),
            )
            for name, j in by_name.items()
        ]
        self.pulses = [self.pulse_us(k, 0.0) for k in range(len(self._joints))]
        """The pulses of the last ``update`` (µs), one per configured joint."""

    def uncovered(self, lows: Sequence[float], highs: Sequence[float]) -> list[str]:
        """The joints whose position limits (description order) reach past the servo's angle range:
        there the pulse stops at its end while the state would report the commanded angle."""
        problems = []
        for (joint, angle_min, span, _, _, offset, direction), name in zip(
            self._joints, self._names, strict=True
        ):
            ends = sorted((direction * lows[joint] + offset, direction * highs[joint] + offset))
            if ends[0] < angle_min - 1e-9 or ends[1] > angle_min + span + 1e-9:
                problems.append(
                    f"servo.joints ({name}): the joint's limits [{lows[joint]:g}, {highs[joint]:g}] rad "
                    f"take the servo to [{ends[0]:g}, {ends[1]:g}] rad, past angle_min {angle_min:g} / "
                    f"angle_max {angle_min + span:g}: narrow the limits (joint_limits.{name}) or widen "
                    "the servo's angle range"
                )
        return problems

    def pulse_us(self, index: int, position: float) -> float:
        """Pulse width (µs) for configured joint ``index`` at ``position``, within its pulse range."""
        _, angle_min, angle_span, pulse_min, pulse_span, offset, direction = self._joints[index]
        fraction = (direction * position + offset - angle_min) / angle_span
        fraction = 0.0 if fraction < 0.0 else 1.0 if fraction > 1.0 else fraction
        return pulse_min + fraction * pulse_span

    def update(self, positions: Sequence[float]) -> list[float]:
        """Recompute ``pulses`` from the robot's joint positions (in description order)."""
        pulses = self.pulses
        for k, (joint, *_rest) in enumerate(self._joints):
            position = positions[joint]
            if math.isfinite(position):  # else keep the last pulse: a servo must never be sent garbage
                pulses[k] = self.pulse_us(k, position)
        return pulses
