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

__all__ = ["PACE_AFTER_S", "PaceWatch", "ServoBackend", "output_condition"]

PACE_AFTER_S = 5
"""Seconds without a skipped frame before a slow output is said to keep pace again (one skipped
frame now and then on a busy machine must not make the events flap)."""


def output_condition(reports: Sequence[OutputReport]) -> tuple[Lifecycle, str]:
    """The robot's lifecycle and its reason, from its device outputs' reports: running only while
    every output works. An output that failed is named before one that has not opened yet."""
    for report in reports:
        if report.state == "lost":
            return Lifecycle.DISCONNECTED, (
                f"servo output {report.label} failed: {report.error}; "
                f"opening it again in {report.retry_in_s:.1f} s"
            )
    for report in reports:
        if report.state == "stopped":
            return Lifecycle.DISCONNECTED, f"servo output {report.label} stopped"
    for report in reports:
        if report.state == "connecting":
            why = f": {report.error}; trying again in {report.retry_in_s:.1f} s" if report.error else ""
            return Lifecycle.CONNECTING, f"opening servo output {report.label}{why}"
    return Lifecycle.RUNNING, ""


class PaceWatch:
    """Decides, once a second, whether the outputs keep pace: an output that had to skip frames makes
    them slow at once; they keep pace again after ``PACE_AFTER_S`` seconds without a skipped frame."""

    def __init__(self) -> None:
        self.text = ""
        """While slow: which outputs skipped how many frames (the status reason); else empty."""
        self._clean_s = 0

    def second(self, skipped: Sequence[tuple[str, int]]) -> tuple[str, str] | None:
        """Take one second's (output, frames skipped); the (event kind, text) to tell users, if any."""
        slow = [f"{label} skipped {count} frame(s) in the last second" for label, count in skipped if count]
        if slow:
            was = self.text
            self.text, self._clean_s = (
                f"servo output slow: {'; '.join(slow)} (only the newest frame is written)",
                0,
            )
            return None if was else ("servo_output_slow", self.text)
        if not self.text:
            return None
        self._clean_s += 1
        if self._clean_s < PACE_AFTER_S:
            return None
        self.text = ""
        return ("servo_output_pace", "the servo outputs keep pace again")


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
        self._states: list[str] = []
        self._pace = PaceWatch()
        self._superseded: list[int] = []
        self._sent: list[float] = []
        """The pulses last handed to the writers (compared each cycle; copied only when they change)."""
        self._publish = publish
        prescale = pca9685.prescale_for(options.pwm_frequency_hz)
        self._prescale = prescale
        width = pca9685.CHANNELS * (max(j.channel for j in options.joints) // pca9685.CHANNELS + 1)
        self._counts = [0] * width
        self._pulses = [0.0] * width
        self._head = f'{{"v":1,"robot":{json.dumps(name)},"pwm_frequency_hz":{options.pwm_frequency_hz!r},'

    async def run(self, on_cycle: Callable[[], None]) -> None:
        """Start the device outputs' writers, then cycle at ``rate_hz`` until cancelled; at the end the
        outputs go to the safe state (``off``: no pulses; ``hold``: the last ones) and close."""
        self._writers = [OutputWriter(link) for link in self._links]
        self._seen = [-1] * len(self._writers)
        self._states = ["connecting"] * len(self._writers)
        self._superseded = [0] * len(self._writers)
        self._sent = []
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
        if pulses != self._sent:  # at rest nothing is copied and no writer is woken
            self._sent = list(pulses)
            frame = tuple(pulses)
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
        prescale = self._prescale
        for channel, pulse in zip(self.mapping.channels, pulses, strict=True):
            counts[channel] = pca9685.count_for(pulse, prescale)
            widths[channel] = round(pulse, 1)
        state = self.state  # stamped as joint_states: the state the pulses were computed from
        assert self._publish is not None
        stamp = f'"host_time_ns":{state.host_time_ns},"controller_time":{state.controller_time!r}'
        values = f'"channels":[{",".join(map(str, counts))}],"pulses_us":[{",".join(map(repr, widths))}]'
        self._publish(f"{self._head}{stamp},{values}}}".encode())

    def _apply_condition(self) -> None:
        """Set the lifecycle from the outputs' reports, and tell users which output failed or is back."""
        reports = []
        for i, writer in enumerate(self._writers):
            self._seen[i] = writer.changes
            report = writer.report()
            reports.append(report)
            was = self._states[i]
            if report.state == "lost" and was != "lost":
                self.notice("servo_output_lost", f"servo output {report.label} failed: {report.error}")
            elif report.state == "ok" and was == "lost":
                self.notice("servo_output_back", f"servo output {report.label} works again")
            self._states[i] = report.state
        state = self.state
        lifecycle, reason = output_condition(reports)
        state.lifecycle = lifecycle
        state.lifecycle_reason = reason or self._pace.text
        state.program_running = lifecycle is Lifecycle.RUNNING

    def _check_pace(self) -> None:
        """Once a second: which outputs had to skip frames, and what users should hear of it."""
        skipped = []
        for i, writer in enumerate(self._writers):
            report = writer.report()
            skipped.append((report.label, report.superseded - self._superseded[i]))
            self._superseded[i] = report.superseded
        said = self._pace.second(skipped)
        if said is not None:
            self.notice(*said)
        if self.state.lifecycle is Lifecycle.RUNNING:
            self.state.lifecycle_reason = self._pace.text

    async def set_io(self, kind: str, pin: int, value: float | bool) -> None:
        """Servo arms have no IO."""
        raise BackendError("servo backend has no IO outputs")

    async def set_payload(self, mass: float, cog: tuple[float, float, float]) -> None:
        """Servo arms take no payload."""
        raise BackendError("servo backend has no payload setting")


def _stop_all(writers: Sequence[OutputWriter], off: bool) -> None:
    for writer in writers:
        writer.stop(off)
