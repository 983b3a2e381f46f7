"""One robot's status, IO and events messages: published on change and on slow timers.

The status goes out at once when what users act on changes (lifecycle, modes, a percent of speed
scaling, the program, the active goal, the TCP offset) and every status period; the IO when it
changes (looked at every IO period) and at least once a second. Events are notices, rejected
commands and the command lease's changes; the status names the lease's holder and the robot's TCP
(``tcp``: its tool link, and the offset in that link's frame), so a viewer draws the TCP from
``joint_states`` without following ``tcp_pose``. Status and IO carry the time of the state they
report, events the time they happened (docs/keys.md, "Time fields").
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Mapping
from typing import Any

from urdaemon.backends.base import Backend
from urdaemon.cell.config import PublishOptions
from urdaemon.cell.robot_options import Robot
from urdaemon.control import MotionController
from urdaemon.publish import envelope
from urdaemon.publish.endpoints import ROBOT, Endpoint

__all__ = ["StatusPublisher", "io_signature", "tool_link"]


def tool_link(robot: Robot) -> str:
    """The robot's tool link, prefixed: ``<robot>_tool0`` (UR), a custom robot's own ``tool_link``;
    the TCP offset (``set_tcp``, the cell file's ``tcp``) is in its frame."""
    custom = robot.description
    return f"{robot.prefix}tool0" if custom is None else f"{robot.prefix}{custom.tool_link}"


class StatusPublisher:
    """Publishes one robot's status, IO and events; counts what the status reports."""

    def __init__(
        self,
        robot: Robot,
        backend: Backend,
        controller: MotionController,
        publish: PublishOptions,
        log: logging.LoggerAdapter[logging.Logger],
    ) -> None:
        self._robot = robot
        self._backend = backend
        self._controller = controller
        self._tool_link = tool_link(robot)
        self._log = log
        self._status_period = 1.0 / publish.status_rate_hz
        self._io_period = 1.0 / publish.io_rate_hz
        self._signature: tuple[Any, ...] = ()
        self._io_signature: tuple[Any, ...] = ()
        self._pub_status: Any = None
        self._pub_io: Any = None
        self._pub_events: Any = None
        self.restarts = 0
        """Backend restarts since start."""
        self.rejected_commands = 0
        """Streaming and freedrive commands rejected since start."""
        self.lease: dict[str, Any] | None = None
        """Who holds the command lease (``holder``, ``fingerprint``, ``since``; never its session id),
        None: nobody (runtime/lease_keeper.py)."""

    ENDPOINTS = (ROBOT.status, ROBOT.io, ROBOT.events)
    """The rows of the endpoint table this part publishes on."""

    def take_publishers(self, declared: Mapping[Endpoint, Any]) -> None:
        """Publish on the status, IO and events publishers the table declared (robot.py)."""
        self._pub_status = declared[ROBOT.status]
        self._pub_io = declared[ROBOT.io]
        self._pub_events = declared[ROBOT.events]

    def message(self) -> dict[str, Any]:
        """The status message body."""
        backend = self._backend
        state = backend.state
        stats = backend.statistics()
        return {
            "robot": self._robot.name,
            # the state it reports: the modes, scaling and program are that state's
            **envelope.state_time(state, time.time_ns()),
            "backend": backend.kind,
            "model": self._robot.model,
            "lifecycle": state.lifecycle.value,
            # never an empty reason while not ready, even before the backend worded its own
            "reason": state.lifecycle_reason or state.not_ready_reason(),
            "robot_mode": state.robot_mode.name,
            "safety_mode": state.safety_mode.name,
            "speed_slider": state.speed_slider,
            "speed_scaling": state.speed_scaling,
            "program_running": state.program_running,
            "ready": state.ready_for_motion,
            "active_goal": self._controller.active_goal_id,
            "rate_hz": backend.rate_hz,
            "cycles": stats.cycles,
            "missed_cycles": stats.missed_cycles,
            "late_cycles": stats.late_cycles,
            "restarts": self.restarts,
            "rejected_stream_commands": self.rejected_commands,
            # UR robots: does the robot's kinematics hash match the configured calibration (None: not checked)
            "calibration_ok": getattr(backend, "calibration_ok", None),
            "lease": self.lease,
            # servo arms: each board or serial port's condition and counters (backends/servo/writer.py)
            "outputs": backend.output_reports(),
            # the TCP offset in the tool link's frame: the TCP's pose is the link's composed with it
            "tcp": {"link": self._tool_link, "pose": list(self._controller.tcp)},
        }

    def io_message(self) -> dict[str, Any]:
        """The IO message body."""
        s = self._backend.state
        return {
            "robot": self._robot.name,
            **envelope.state_time(s, time.time_ns()),
            "digital_out": list(s.digital_out),
            "configurable_out": list(s.configurable_out),
            "tool_out": list(s.tool_out),
            "analog_out": list(s.analog_out),
            "digital_in": list(s.digital_in),
            "configurable_in": list(s.configurable_in),
            "tool_in": list(s.tool_in),
            "analog_in": list(s.analog_in),
            "tool_voltage": s.tool_voltage,
            "payload": {"mass": s.payload_mass, "cog": list(s.payload_cog)},
        }

    def _key(self) -> tuple[Any, ...]:
        """What, when it changes, makes the status go out at once."""
        state = self._backend.state
        return (
            state.lifecycle,
            state.lifecycle_reason,
            state.robot_mode,
            state.safety_mode,
            # a real controller's scaling moves continuously: only a change of a percent is news
            round(state.speed_scaling, 2),
            state.program_running,
            self._controller.active_goal_id,
            self._controller.tcp,  # set_tcp: a viewer's TCP frame moves at once
        )

    def publish_if_changed(self) -> None:
        """Publish the status if what users act on changed (once per cycle)."""
        if self._key() != self._signature:
            self.publish()

    def publish(self) -> None:
        """Publish the status now."""
        self._signature = self._key()
        if self._pub_status is not None:
            self._pub_status.put(envelope.encode(self.message()))

    def publish_io(self) -> None:
        """Publish the IO message now."""
        message = self.io_message()
        self._io_signature = io_signature(message)
        if self._pub_io is not None:
            self._pub_io.put(envelope.encode(message))

    def event(self, body: dict[str, Any]) -> None:
        """Publish an event (``kind`` and what it says) of this robot."""
        if self._pub_events is not None:
            # when it happened: now (a notice, a refusal, a lease's change is news as it is published)
            stamped = {"robot": self._robot.name, "host_time_ns": time.time_ns(), **body}
            self._pub_events.put(envelope.encode(stamped))

    async def run(self) -> None:
        """Publish the status every status period and the IO when it changed (or each second)."""
        last_status = last_io = 0.0
        while True:
            await asyncio.sleep(min(self._status_period, self._io_period))
            now = time.monotonic()
            try:
                if now - last_status >= self._status_period:
                    self.publish()
                    last_status = now
                signature = io_signature(self.io_message())
                if signature != self._io_signature or now - last_io >= 1.0:
                    self.publish_io()
                    last_io = now
            except Exception:  # a publishing error must not end this robot's (or the cell's) tasks
                self._log.exception("publishing status/IO failed")


_TIME_FIELDS = ("host_time_ns", "controller_time")


def io_signature(message: dict[str, Any]) -> tuple[str, ...]:
    """What, when it changes, makes the IO go out at once: its values, not the time they were read."""
    return tuple(str(v) for k, v in message.items() if k not in _TIME_FIELDS)
