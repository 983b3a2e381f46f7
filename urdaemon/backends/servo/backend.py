"""The ``servo`` backend: a hobby-servo arm with no feedback (docs/servo.md).

Each cycle the command becomes the state (the servos report nothing back, as in the mock), the joint
positions become pulses (``ServoMapping``), and the pulses go to every output: published on
``<cell>/<robot>/servo_command`` (``zenoh``), and handed to a writer thread per device output
(``i2c``, ``serial``) that puts them on the bus without the cycle ever waiting for it. While a device
output is not working the robot is not ready, so its goals end; it is opened again with a backoff.
"""

from __future__ import annotations

import asyncio
import json
from collections.abc import Callable, Sequence
from typing import Any

from urdaemon.backends.mock import MockBackend
from urdaemon.backends.servo.link import BoardLink
from urdaemon.backends.servo.mapping import ServoMapping
from urdaemon.backends.servo.writer import OutputReport, OutputWriter
from urdaemon.boards import pca9685
from urdaemon.cell.servo import ServoOptions
from urdaemon.errors import BackendError
from urdaemon.model import Lifecycle, RobotMode, SafetyMode

__all__ = ["ServoBackend", "output_condition"]


def output_condition(reports: Sequence[OutputReport]) -> tuple[Lifecycle, str]:
    """The robot's lifecycle and its reason, from its device outputs' reports: running only while
    every output works."""
    for report in reports:
        if report.state == "connecting":
            why = f": {report.error}; trying again in {report.retry_in_s:.1f} s" if report.error else ""
            return Lifecycle.CONNECTING, f"opening servo output {report.label}{why}"
    for report in reports:
        if report.state in ("lost", "stopped"):
            return Lifecycle.DISCONNECTED, (
                f"servo output {report.label} failed: {report.error}; "
                f"opening it again in {report.retry_in_s:.1f} s"
            )
    return Lifecycle.RUNNING, ""


class ServoBackend(MockBackend):
    """A servo arm: the command is mirrored into state and sent to the arm's outputs as pulses."""

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
        links: Sequence[BoardLink] = (),
    ) -> None:
        super().__init__(name, joint_names, options.rate_hz, initial_positions=initial_positions)
        self.mapping = ServoMapping(tuple(joint_names), prefix, options)
        self.mapping.update(self.state.positions)
        self._off_at_stop = options.safe_state == "off"
        self._links = tuple(links)
        self._writers: list[OutputWriter] = []
        self._seen: list[int] = []
        self._superseded: list[int] = []
        self._sent: tuple[float, ...] | None = None
        self._slow = ""
        self._publish = publish
        prescale = pca9685.prescale_for(options.pwm_frequency_hz)
        self._to_count = [(j.channel, prescale) for j in options.joints]
        width = pca9685.CHANNELS * (max(j.channel for j in options.joints) // pca9685.CHANNELS + 1)
        self._counts = [0] * width
        self._pulses = [0.0] * width
        self._head = f'{{"v":1,"robot":{json.dumps(name)},"pwm_frequency_hz":{options.pwm_frequency_hz!r},'

    async def run(self, on_cycle: Callable[[], None]) -> None:
        """Start the device outputs' writers, then cycle at ``rate_hz`` until cancelled; at the end the
        outputs go to the safe state (``off``: no pulses; ``hold``: the last ones) and close."""
        self._writers = [OutputWriter(link) for link in self._links]
        self._seen = [-1] * len(self._writers)
        self._superseded = [0] * len(self._writers)
        self._sent = None
        state = self.state
        state.robot_mode = RobotMode.RUNNING
        state.safety_mode = SafetyMode.NORMAL
        self._apply_condition()
        for writer in self._writers:
            writer.start()
        self._clock.start()
        try:
            while True:
                await self._clock.wait()
                self.step()
                on_cycle()
        finally:
            writers, off = self._writers, self._off_at_stop
            await asyncio.shield(asyncio.to_thread(_stop_all, writers, off))

    def step(self) -> None:
        """Mirror the command into state, then send the pulses of the new positions."""
        super().step()
        pulses = self.mapping.update(self.state.positions)
        if self._publish is not None:
            self._publish_pulses(pulses)
        frame = tuple(pulses)
        if frame != self._sent:
            self._sent = frame
            for writer in self._writers:
                writer.submit(frame)
        seen = self._seen
        for i, writer in enumerate(self._writers):
            if writer.changes != seen[i]:
                self._apply_condition()
                break
        if self.state.cycle % max(1, round(self.rate_hz)) == 0:
            self._check_pace()

    def output_reports(self) -> list[dict[str, Any]] | None:
        """Each device output's condition and counters (status ``outputs``)."""
        return [writer.report().as_dict() for writer in self._writers]

    def _publish_pulses(self, pulses: Sequence[float]) -> None:
        counts, widths = self._counts, self._pulses
        for (channel, prescale), pulse in zip(self._to_count, pulses, strict=True):
            counts[channel] = pca9685.count_for(pulse, prescale)
            widths[channel] = round(pulse, 1)
        state = self.state  # stamped as joint_states: the state the pulses were computed from
        assert self._publish is not None
        stamp = f'"host_time_ns":{state.host_time_ns},"controller_time":{state.controller_time!r}'
        values = f'"channels":[{",".join(map(str, counts))}],"pulses_us":[{",".join(map(repr, widths))}]'
        self._publish(f"{self._head}{stamp},{values}}}".encode())

    def _apply_condition(self) -> None:
        """Set the lifecycle from the outputs' reports, and tell users what changed."""
        reports = []
        for i, writer in enumerate(self._writers):
            self._seen[i] = writer.changes
            reports.append(writer.report())
        state = self.state
        before = state.lifecycle
        lifecycle, reason = output_condition(reports)
        state.lifecycle = lifecycle
        state.lifecycle_reason = reason or self._slow
        state.program_running = lifecycle is Lifecycle.RUNNING
        if lifecycle is Lifecycle.DISCONNECTED and before is not Lifecycle.DISCONNECTED:
            self.notice("servo_output_lost", reason)
        elif lifecycle is Lifecycle.RUNNING and before is Lifecycle.DISCONNECTED:
            self.notice("servo_output_back", ", ".join(r.label for r in reports) + " working again")

    def _check_pace(self) -> None:
        """Once a second: outputs that had to skip frames are slow; say so once, and when it ends."""
        slow = []
        for i, writer in enumerate(self._writers):
            report = writer.report()
            skipped = report.superseded - self._superseded[i]
            self._superseded[i] = report.superseded
            if skipped:
                slow.append(f"{report.label} skipped {skipped} frame(s) in the last second")
        text = f"servo output slow: {'; '.join(slow)} (only the newest frame is written)" if slow else ""
        if bool(text) != bool(self._slow):
            self.notice(
                "servo_output_slow" if text else "servo_output_pace", text or "outputs keep pace again"
            )
        self._slow = text
        if self.state.lifecycle is Lifecycle.RUNNING:
            self.state.lifecycle_reason = text

    async def set_io(self, kind: str, pin: int, value: float | bool) -> None:
        """Servo arms have no IO."""
        raise BackendError("servo backend has no IO outputs")

    async def set_payload(self, mass: float, cog: tuple[float, float, float]) -> None:
        """Servo arms take no payload."""
        raise BackendError("servo backend has no payload setting")


def _stop_all(writers: Sequence[OutputWriter], off: bool) -> None:
    for writer in writers:
        writer.stop(off)
