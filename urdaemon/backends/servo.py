"""The ``servo`` backend: a hobby-servo arm driven by a PCA9685 board, with no feedback.

Each cycle the joint command is mapped, per configured joint, to a PWM pulse and then to the
PCA9685's 12-bit "off" count at the board's PWM frequency; the 16 channel values are published
on the robot's ``servo_command`` key for whatever drives the board. The measured state simply
follows the command (fake execution), because the servos report nothing back.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Sequence

from urdaemon.backends.mock import MockBackend
from urdaemon.cell.config import ServoOptions
from urdaemon.errors import BackendError, ConfigError

__all__ = ["PCA9685_CHANNELS", "PCA9685_RESOLUTION", "ServoBackend", "ServoMapping"]

PCA9685_CHANNELS = 16
PCA9685_RESOLUTION = 4096
"""Counts per PWM period (12-bit), PCA9685 datasheet §7.3.3."""


class ServoMapping:
    """Joint angle → pulse width (µs) → PCA9685 count, for every configured joint."""

    def __init__(self, joint_names: Sequence[str], prefix: str, options: ServoOptions) -> None:
        by_name = {f"{prefix}{j.name}": j for j in options.joints}
        unknown = sorted(set(by_name) - set(joint_names))
        if unknown:
            raise ConfigError(f"servo joints not in the robot description: {', '.join(unknown)}")
        unmapped = [name for name in joint_names if name not in by_name]
        if unmapped:
            raise ConfigError(f"joints of the description without a servo channel: {', '.join(unmapped)}")
        period_us = 1e6 / options.pwm_frequency_hz
        for j in options.joints:
            if j.pulse_max_us >= period_us:
                raise ConfigError(
                    f"servo joint {j.name}: pulse_max_us {j.pulse_max_us} does not fit the PWM period of "
                    f"{period_us:.0f} µs at {options.pwm_frequency_hz} Hz"
                )
        self.frequency = options.pwm_frequency_hz
        # (joint index, channel, angle_min, angle span, pulse_min, pulse span, offset, direction)
        self._joints = [
            (
                joint_names.index(name),
                j.channel,
                j.angle_min,
                j.angle_max - j.angle_min,
                j.pulse_min_us,
                j.pulse_max_us - j.pulse_min_us,
                j.offset,
                float(j.direction),
            )
            for name, j in by_name.items()
        ]
        self._counts_per_us = self.frequency * PCA9685_RESOLUTION / 1e6
        self.channels = [0] * PCA9685_CHANNELS

    def pulse_us(self, index: int, position: float) -> float:
        """Pulse width (µs) for joint ``index`` of the configured joints at ``position``."""
        _, _, angle_min, angle_span, pulse_min, pulse_span, offset, direction = self._joints[index]
        fraction = (direction * position + offset - angle_min) / angle_span
        fraction = 0.0 if fraction < 0.0 else 1.0 if fraction > 1.0 else fraction
        return pulse_min + fraction * pulse_span

    def update(self, positions: Sequence[float]) -> list[int]:
        """Recompute ``channels`` (PCA9685 off-counts, 0 for unused channels) from joint positions."""
        channels, scale = self.channels, self._counts_per_us
        for k, (joint, channel, *_rest) in enumerate(self._joints):
            position = positions[joint]
            if not math.isfinite(position):
                continue  # keep the last count: a servo must never be sent garbage
            count = round(self.pulse_us(k, position) * scale)
            channels[channel] = min(max(count, 0), PCA9685_RESOLUTION - 1)
        return channels


class ServoBackend(MockBackend):
    """A servo arm: the command is published as PCA9685 channel values and mirrored into state."""

    kind = "servo"

    def __init__(
        self,
        name: str,
        joint_names: Sequence[str],
        prefix: str,
        options: ServoOptions,
        *,
        initial_positions: Sequence[float] | None = None,
        publish: Callable[[bytes], None] | None = None,
    ) -> None:
        super().__init__(name, joint_names, options.rate_hz, initial_positions=initial_positions)
        self.mapping = ServoMapping(tuple(joint_names), prefix, options)
        self._publish = publish
        self._head = f'{{"v":1,"robot":{json.dumps(name)},"pwm_frequency_hz":{options.pwm_frequency_hz!r},'

    def step(self) -> None:
        """Mirror the command into state, then publish the channel values of the new positions."""
        super().step()
        channels = self.mapping.update(self.state.positions)
        if self._publish is not None:
            state = self.state  # stamped as joint_states: the state the channels were computed from
            stamp = f'"host_time_ns":{state.host_time_ns},"controller_time":{state.controller_time!r}'
            self._publish(f'{self._head}{stamp},"channels":[{",".join(map(str, channels))}]}}'.encode())

    async def set_io(self, kind: str, pin: int, value: float | bool) -> None:
        """Servo arms have no IO."""
        raise BackendError("servo backend has no IO outputs")

    async def set_payload(self, mass: float, cog: tuple[float, float, float]) -> None:
        """Servo arms take no payload."""
        raise BackendError("servo backend has no payload setting")
