"""One robot served by the daemon: backend + motion controller + its Zenoh keys, supervised.

``RobotRuntime`` keeps the supervision of the backend (restarts with backoff) and the cycle, and
composes the rest (urdaemon/runtime/): the status, goals, commands, services and the command lease.
The backend clocks ``_on_cycle`` (the robot is the clock). That path only ticks the controller,
encodes the joint state and TCP pose and publishes them; everything else happens on requests or on
slow timers.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Sequence
from typing import Any

from urdaemon.backends.base import Backend
from urdaemon.cell.config import PublishOptions
from urdaemon.cell.robot_options import Robot
from urdaemon.control import MotionController
from urdaemon.description.arm import ArmKinematics
from urdaemon.description.frames import frame_of_pose
from urdaemon.description.kinematics import DhKinematics, ToolOffset, quaternion_of
from urdaemon.errors import UrDaemonError
from urdaemon.model import Lifecycle, RobotState
from urdaemon.publish import state_encoder
from urdaemon.publish.endpoints import ROBOT, Endpoint, declare_endpoints, read_only_reason
from urdaemon.publish.keys import RobotKeys
from urdaemon.publish.node import ZenohNode
from urdaemon.publish.tap import Matching
from urdaemon.runtime.audit import AuditLog, RobotAudit
from urdaemon.runtime.goal_events import GoalEvents
from urdaemon.runtime.goals import Goals
from urdaemon.runtime.lease import LeaseBook
from urdaemon.runtime.lease_keeper import LeaseKeeper
from urdaemon.runtime.motion import TOOL_CONTACT_REASON, How, RobotMotion
from urdaemon.runtime.pose_goals import Cartesian
from urdaemon.runtime.queries import SHUTTING_DOWN, Requests
from urdaemon.runtime.service_runner import ServiceRunner
from urdaemon.runtime.status import StatusPublisher, tool_link
from urdaemon.runtime.streaming import Commands

__all__ = ["RESTART_BACKOFF_S", "RobotRuntime"]

RESTART_BACKOFF_S = (0.1, 0.5, 1.0, 2.0, 5.0)
"""Delays before restarting a failed backend; the last one repeats."""
HEALTHY_CYCLES_S = 1.0
"""A backend that ran this many seconds' worth of cycles (at its rate) before failing restarts with
the first, shortest delay again: it was healthy, so this is a new fault, not the same one again."""


class _RobotLog(logging.LoggerAdapter[logging.Logger]):
    def process(self, msg: Any, kwargs: Any) -> tuple[Any, Any]:
        return f"[{self.extra['robot'] if self.extra else '?'}] {msg}", kwargs


class TcpPoses:
    """tcp_pose's pose and frames: the TCP in the robot's base frame, with its current TCP offset.

    A UR robot's tool0 comes from its DH (``DhKinematics``, cheapest), a custom robot's from its arm
    kinematics (``ArmKinematics.forward``); the offset is the cell file's ``tcp`` until ``set_tcp``.
    """

    __slots__ = ("_arm", "_kinematics", "_tcp", "_tcp_child", "_tool", "_tool_link", "child", "frame")

    def __init__(self, robot: Robot, kinematics: DhKinematics | None, arm: ArmKinematics | None) -> None:
        self._kinematics = kinematics
        self._arm = arm if kinematics is None else None
        custom = robot.description
        self.frame = f"{robot.prefix}base" if custom is None else f"{robot.prefix}{custom.base_link}"
        """The frame of tcp_pose: UR ``<robot>_base``, custom robots their base link."""
        self._tool_link = tool_link(robot)
        self._tcp_child = f"{robot.prefix}tcp"
        self._tcp: tuple[float, ...] = ()
        self._tool: ToolOffset | None = None
        """The TCP offset composed with a UR robot's tool0 pose (None: the TCP is tool0)."""
        self.child = self._tool_link
        self.use(robot.tcp)

    @property
    def available(self) -> bool:
        """Whether the robot has kinematics to publish tcp_pose with."""
        return self._kinematics is not None or self._arm is not None

    def use(self, tcp: Sequence[float]) -> None:
        """Compose tcp_pose with the TCP offset ``tcp`` from now on: child ``<robot>_tcp``, or the
        tool link for a zero offset."""
        self._tcp = tuple(tcp)
        self._tool = ToolOffset(tcp) if any(tcp) else None
        self.child = self._tcp_child if self._tool is not None else self._tool_link

    def pose(self, positions: Sequence[float]) -> tuple[float, ...]:
        """(x, y, z, qx, qy, qz, qw) of the TCP in ``frame``."""
        if self._kinematics is not None:
            pose = self._kinematics.tool_pose(positions)
            return pose if self._tool is None else self._tool.apply(pose)
        assert self._arm is not None, "no tcp_pose without kinematics (available)"
        r00, r01, r02, r10, r11, r12, r20, r21, r22, x, y, z = frame_of_pose(
            self._arm.forward(positions, self._tcp)
        )
        return (x, y, z, *quaternion_of(r00, r01, r02, r10, r11, r12, r20, r21, r22))


class RobotRuntime:
    """Serves one robot until cancelled; restarts its backend after failures without touching others."""

    def __init__(
        self,
        cell: str,
        robot: Robot,
        backend: Backend,
        controller: MotionController,
        node: ZenohNode,
        publish: PublishOptions,
        *,
        kinematics: DhKinematics | None = None,
        arm: ArmKinematics | None = None,
        audit: AuditLog | None = None,
    ) -> None:
        self.robot = robot
        self._audit = audit
        self.backend = backend
        self.controller = controller
        self.node = node
        self.keys = RobotKeys(cell, robot.name)
        self.log = _RobotLog(logging.getLogger("urdaemon.robot"), {"robot": robot.name})
        log = self.log
        self.requests = Requests()
        self.status = status = StatusPublisher(robot, backend, controller, publish, log)
        events = GoalEvents(robot=robot, backend=backend, node=node, keys=self.keys, log=log)
        self.motion = RobotMotion(
            backend=backend, controller=controller, status=status, events=events, log=log
        )
        self._compose(robot, events, arm)
        self.service_names: frozenset[str] = frozenset()
        """The services this robot answers (once declared)."""
        self.tcp_poses = TcpPoses(robot, kinematics, arm)
        self._decimation = publish.joint_states_decimation
        self._encoder = state_encoder.JointStateEncoder(robot.name, backend.state.joint_names)
        self._pub_joints: Any = None
        self._pub_pose: Any = None
        self._joints_wanted = Matching(False)
        self._pose_wanted = Matching(False)

    def _compose(self, robot: Robot, events: GoalEvents, arm: ArmKinematics | None) -> None:
        """The runtime's parts, each given the collaborators it uses by name."""
        backend, controller, node, log = self.backend, self.controller, self.node, self.log
        motion, status = self.motion, self.status
        cartesian = (
            None
            if arm is None
            else Cartesian(robot=robot, backend=backend, controller=controller, kinematics=arm, log=log)
        )
        self.goals = Goals(
            robot=robot,
            backend=backend,
            controller=controller,
            node=node,
            keys=self.keys,
            motion=motion,
            events=events,
            requests=self.requests,
            cartesian=cartesian,
            log=log,
        )
        self.commands = Commands(
            robot=robot,
            backend=backend,
            controller=controller,
            motion=motion,
            status=status,
            joint_names=self.goals.joint_names,
            log=log,
        )
        self.services = ServiceRunner(
            backend=backend,
            controller=controller,
            motion=motion,
            requests=self.requests,
            status=status,
            log=log,
            on_tcp=self._use_tcp,
        )
        self.lease = LeaseKeeper(
            keys=self.keys,
            book=LeaseBook(robot.name, self.keys.lease),  # checked unless the cell says not (daemon.py)
            motion=motion,
            requests=self.requests,
            status=status,
            log=log,
        )

    # ---- lifecycle -----------------------------------------------------------------------------

    def declare(self) -> None:
        """Declare this robot's endpoints by walking the table (publish/endpoints.py): every row its
        parts serve, each with its row's key, size limit, reply field and checks (the command lease on
        a leased row; on a read-only robot, the refusal of every row that would command it); the
        liveliness token last. Its servo_command publisher is the backend's (daemon.py)."""
        served: dict[Endpoint, Any] = dict.fromkeys((ROBOT.joint_states, *self.status.ENDPOINTS, ROBOT.alive))
        if self.tcp_poses.available:
            served[ROBOT.tcp_pose] = None
        for part in (self.goals, self.services, self.lease):
            served.update(part.endpoints())
        served.update(self.commands.endpoints())
        self.backend.on_notice = self._publish_notice
        self.backend.on_change = self.status.publish
        declared = declare_endpoints(
            self.node,
            self.keys,
            served,
            guard=self.lease.book,
            read_only=read_only_reason(self.robot),
            refused=self.commands.on_refused,
            audit=None if self._audit is None else RobotAudit(self._audit, self.robot.name, self.lease.book),
        )
        self._pub_joints = declared[ROBOT.joint_states]
        self._joints_wanted = self.node.matching(self._pub_joints)  # with the flight recorder: always on
        self._pub_pose = declared.get(ROBOT.tcp_pose)
        self._pose_wanted = Matching(False) if self._pub_pose is None else self.node.matching(self._pub_pose)
        self.status.take_publishers(declared)
        self.service_names = frozenset(row.service.name for row in declared if row.service is not None)

    async def run(self) -> None:
        """Run the backend, restarting it with backoff after any failure; also the status/IO timers."""
        try:
            async with asyncio.TaskGroup() as group:
                group.create_task(self.status.run())
                group.create_task(self._supervise())
        finally:
            # from now on every request answers "shutting down" (the daemon closes the backends after
            # this: nothing may be accepted that no cycle would end); requests in progress answer it too
            self.motion.close()
            await self.requests.cancel_all()

    async def _supervise(self) -> None:
        attempt = 0
        while True:
            cycles_before = self.backend.statistics().cycles
            try:
                await self.backend.run(self._on_cycle)
                reason = "backend stopped"
            except asyncio.CancelledError:
                # shutting down first: no request may start motion from now on
                self.motion.end(SHUTTING_DOWN, How.ABORT, closing=True)
                raise
            except Exception as err:  # any failure of one robot is contained here
                reason = f"backend failed: {type(err).__name__}: {err}"
                self.log.error("%s", reason, exc_info=not isinstance(err, UrDaemonError))
            self.status.restarts += 1
            self.motion.end(reason, How.ABORT)  # a restarted control script has no contact to rest in
            state = self.backend.state
            state.lifecycle = Lifecycle.DISCONNECTED
            state.lifecycle_reason = reason
            self.status.publish()
            if self.backend.statistics().cycles - cycles_before >= HEALTHY_CYCLES_S * self.backend.rate_hz:
                attempt = 0  # a healthy run earns a fresh, short backoff: this is a new fault
            delay = RESTART_BACKOFF_S[min(attempt, len(RESTART_BACKOFF_S) - 1)]
            attempt += 1
            self.log.info("restarting backend in %.1f s", delay)
            await asyncio.sleep(delay)

    # ---- the cycle (hot path) --------------------------------------------------------------------

    def _on_cycle(self) -> None:
        backend = self.backend
        state = backend.state
        self.controller.tick(state, backend.command, state.monotonic_ns * 1e-9)
        if backend.catching_up:  # a newer package follows at once: it sends and publishes
            return
        backend.send_command()  # the robot's frame first, then everything users see
        if state.cycle % self._decimation == 0:
            # nothing is computed or encoded for a stream nobody wants (a subscriber; for joint_states
            # also the flight recorder's ring, publish/tap.py)
            if self._joints_wanted.active:
                self._pub_joints.put(self._encoder.encode(state))
            if self._pose_wanted.active:
                poses = self.tcp_poses
                pose = poses.pose(state.positions)
                self._pub_pose.put(self._encoder.encode_pose(state, poses.frame, poses.child, pose))
        if self.controller.has_events:
            self.motion.publish_events()
        self.status.publish_if_changed()

    def _use_tcp(self, tcp: Sequence[float]) -> None:
        """set_tcp took ``tcp``: tcp_pose follows."""
        self.tcp_poses.use(tcp)

    # ---- what the robot tells ------------------------------------------------------------------------

    def _publish_notice(self, kind: str, text: str) -> None:
        if kind == "tool_contact" and text == "contact":
            # the robot stopped on its own and goes back to where the tool touched: what we were sending
            # is over now, not when the goal's time runs out, and nothing moves it until end_tool_contact
            self.motion.end(TOOL_CONTACT_REASON, How.CONTACT)
        self.status.event({"kind": kind, "text": text})

    def status_message(self) -> dict[str, Any]:
        """The status message body."""
        return self.status.message()

    @property
    def state(self) -> RobotState:
        """The robot's latest state."""
        return self.backend.state
