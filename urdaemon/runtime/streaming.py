"""One robot's streaming commands: joint position and velocity streams, TCP twists, and freedrive.

Commands are puts, not queries: nothing answers them. A rejected one is counted in the status and
reported as a ``command_rejected`` event (the first ten, then every hundredth also in the log).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Sequence

from urdaemon.backends.base import Backend
from urdaemon.cell.robot_options import Robot
from urdaemon.control import MotionController
from urdaemon.errors import BackendError, GoalRejected, MessageError, UrDaemonError
from urdaemon.publish import stream_commands
from urdaemon.publish.endpoints import ROBOT, Endpoint
from urdaemon.runtime.motion import TOOL_CONTACT_BUSY, How, RobotMotion
from urdaemon.runtime.queries import SHUTTING_DOWN, internal_error
from urdaemon.runtime.status import StatusPublisher

__all__ = ["Commands"]


class Commands:
    """Acts on one robot's streaming and freedrive commands."""

    def __init__(
        self,
        *,
        robot: Robot,
        backend: Backend,
        controller: MotionController,
        motion: RobotMotion,
        status: StatusPublisher,
        joint_names: Callable[[Sequence[str] | None], tuple[str, ...]],
        log: logging.LoggerAdapter[logging.Logger],
    ) -> None:
        self._robot = robot
        self._backend = backend
        self._controller = controller
        self._motion = motion
        self._status = status
        self._joint_names = joint_names
        self._log = log

    def endpoints(self) -> dict[Endpoint, Callable[[str, bytes], None]]:
        """The rows of the endpoint table this part subscribes to (the command streams), and their
        handlers; a refused sample goes to ``on_refused``."""
        return {
            ROBOT.command_joint_position: self.on_stream_position,
            ROBOT.command_joint_velocity: self.on_stream_velocity,
            ROBOT.command_twist: self.on_twist,
            ROBOT.command_freedrive: self.on_freedrive,
        }

    def on_stream_position(self, key: str, payload: bytes) -> None:
        """A joint position command: the controller follows it until the deadman times out."""
        self._follow(key, payload, self._stream_position)

    def on_stream_velocity(self, key: str, payload: bytes) -> None:
        """A joint velocity command: the controller follows it until the deadman times out."""
        self._follow(key, payload, self._stream_velocity)

    def _follow(self, key: str, payload: bytes, start: Callable[[bytes], None]) -> None:
        """Run ``start(payload)``; whatever it refuses, or a bug in it, is reported as a rejection."""
        try:
            start(payload)
        except (MessageError, GoalRejected) as err:
            self.reject(key, err)
        except Exception as err:  # a bug must not kill the subscriber; the client hears of it
            self._log.exception("streaming command failed")
            self.reject(key, GoalRejected(internal_error(err)))

    def _stream_position(self, payload: bytes) -> None:
        message = stream_commands.decode_stream_position(payload)
        self._motion.check_accepting()
        assert message.positions is not None
        self._controller.stream_positions(
            self._joint_names(message.joint_names),
            message.positions,
            message.velocities,
            self._backend.state,
            time.monotonic(),
        )

    def _stream_velocity(self, payload: bytes) -> None:
        message = stream_commands.decode_stream_velocity(payload)
        self._motion.check_accepting()
        assert message.velocities is not None
        self._controller.stream_velocities(
            self._joint_names(message.joint_names), message.velocities, self._backend.state, time.monotonic()
        )

    def on_twist(self, key: str, payload: bytes) -> None:
        """A TCP twist command: the controller follows it (smoothed, slowed near singularities and
        joint limits) until the deadman times out."""
        self._follow(key, payload, self._twist)

    def _twist(self, payload: bytes) -> None:
        message = stream_commands.decode_twist(payload)
        self._motion.check_accepting()
        caps = self._robot.motion.cartesian
        for field, vector, cap, name, unit in (
            ("linear", message.linear, caps.max_speed, "max_speed", "m/s"),
            ("angular", message.angular, caps.max_angular_speed, "max_angular_speed", "rad/s"),
        ):
            size = math.hypot(*vector)
            if size > cap:
                raise GoalRejected(
                    f"twist command.{field}: |{field}| = {size:.4g} {unit} is above the cap {name} {cap:g} "
                    f"{unit} (the cell file's motion.cartesian)"
                )
        self._controller.stream_twist(
            (*message.linear, *message.angular), message.frame, self._backend.state, time.monotonic()
        )

    def on_refused(self, key: str, reason: str) -> None:
        """A command put on a wildcard key expression, too large to read, or not the lease holder's:
        it did nothing."""
        self.reject(key, GoalRejected(reason))

    def reject(self, key: str, err: UrDaemonError) -> None:
        """Count, log (rate-limited) and report a rejected command."""
        status = self._status
        status.rejected_commands += 1
        count = status.rejected_commands
        reason = err.reason if isinstance(err, GoalRejected) else str(err)
        if count <= 10 or count % 100 == 0:
            self._log.warning("streaming command on %s rejected (%d so far): %s", key, count, reason)
        status.event({"kind": "command_rejected", "key": key, "reason": reason})

    def on_freedrive(self, key: str, payload: bytes) -> None:
        """Keep freedrive on for one deadman period (it starts only at rest), or end it."""
        try:
            active = stream_commands.decode_freedrive(payload)
            if active:
                self._check_freedrive_can_start()
                # a goal planned from now on was planned before freedrive
                self._motion.end("freedrive", How.HAND_BACK)
            self._backend.freedrive(active, self._robot.motion.stream_timeout)
        except (MessageError, GoalRejected) as err:
            self.reject(key, err)
        except BackendError as err:
            self.reject(key, GoalRejected(str(err)))

    def _check_freedrive_can_start(self) -> None:
        motion, controller = self._motion, self._controller
        if motion.closing:
            raise GoalRejected(SHUTTING_DOWN)
        if motion.in_contact:
            raise GoalRejected(TOOL_CONTACT_BUSY)
        controller.release_hold()
        if controller.mode != "idle":
            raise GoalRejected(
                f"busy: the robot is {controller.mode.replace('_', ' ')}; freedrive starts at rest"
            )
        if motion.planning is not None:
            raise GoalRejected(
                f"busy: trajectory goal {motion.planning} is being planned; freedrive starts at rest"
                " (cancel it first)"
            )
