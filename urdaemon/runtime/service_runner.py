"""The runner of one robot's services (publish/services.py declares them, once).

Every service but ``stop`` runs through ``run``: refused once the daemon shuts down, refused while
the same service still runs (a burst never acts more than once at a time), its request decoded and
checked before anything acts, answered exactly once. ``stop`` is answered at once, never refused.
A commanding service (every one but ``stop``, ``cycle_stats`` and ``doctor``) needs the robot's
command lease.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

from urdaemon.backends.base import Backend
from urdaemon.control import MotionController
from urdaemon.errors import BackendError, GoalRejected, MessageError
from urdaemon.publish.endpoints import ROBOT, Endpoint
from urdaemon.publish.services import SERVICES, STOP, ServiceSpec
from urdaemon.runtime.motion import TOOL_CONTACT_REASON, How, RobotMotion
from urdaemon.runtime.queries import SHUTTING_DOWN, Requests, internal_error, payload, reply
from urdaemon.runtime.status import StatusPublisher

__all__ = ["ServiceRunner"]


class ServiceRunner:
    """Answers one robot's service queries; the ``ServiceHost`` the table's handlers use."""

    def __init__(
        self,
        *,
        backend: Backend,
        controller: MotionController,
        motion: RobotMotion,
        requests: Requests,
        status: StatusPublisher,
        log: logging.LoggerAdapter[logging.Logger],
        on_tcp: Callable[[tuple[float, ...]], None] | None = None,
    ) -> None:
        self._on_tcp = on_tcp
        """Told a new TCP offset once the controller and the backend took it (tcp_pose's composition)."""
        self._backend = backend
        self._controller = controller
        self._motion = motion
        self._requests = requests
        self._status = status
        self._log = log
        self._running: set[str] = set()

    @property
    def backend(self) -> Backend:
        """The robot's backend."""
        return self._backend

    def endpoints(self) -> dict[Endpoint, Callable[[Any], None]]:
        """The rows of the endpoint table this part answers, every service's, and their handlers
        (a commanding service's row needs the lease; ``stop``'s never, nor reads its payload)."""
        handlers = {ROBOT.service(spec.name): self._handler(spec) for spec in SERVICES}
        handlers[ROBOT.service(STOP.name)] = self.on_stop
        return handlers

    def _handler(self, spec: ServiceSpec) -> Callable[[Any], None]:
        def handle(query: Any) -> None:
            self.run(query, spec)

        return handle

    def on_stop(self, query: Any) -> None:
        """Stop whatever moves the robot (a trajectory being planned is refused); answered at once."""
        reply(query, self.stop("stop requested"))

    def stop(self, reason: str) -> dict[str, Any]:
        """Stop whatever moves the robot now, for ``reason``; the reply body (``planned``: the goal being
        planned that was refused, if any)."""
        planned = self._motion.end(reason, How.STOP).planned
        return {"ok": True} if planned is None else {"ok": True, "planned": planned}

    def run(self, query: Any, spec: ServiceSpec) -> None:
        """Run ``spec``'s service with the query's payload and answer once; a second call while it runs
        is refused, so a burst of requests never acts more than once at a time."""
        name = spec.name
        if self._motion.closing:
            reply(query, {"ok": False, "reason": SHUTTING_DOWN})
            return
        if name in self._running:
            reply(
                query, {"ok": False, "reason": f"busy: {name} is still running; ask again once it answered"}
            )
            return
        self._running.add(name)
        task = self._requests.spawn(
            self._serve(query, spec, payload(query)), query, {"ok": False, "reason": SHUTTING_DOWN}
        )
        task.add_done_callback(lambda _: self._running.discard(name))

    async def _serve(self, query: Any, spec: ServiceSpec, data: bytes | None) -> None:
        assert spec.handle is not None, "stop is answered by on_stop"
        try:
            extra = await spec.handle(self, spec.decode(data))
        except (MessageError, BackendError, GoalRejected) as err:
            self._log.warning("%s refused: %s", spec.name, err)
            reason = err.reason if isinstance(err, GoalRejected) else str(err)
            reply(query, {"ok": False, "reason": reason})
        except Exception as err:  # a backend bug must still answer the client
            self._log.exception("%s failed", spec.name)
            reply(query, {"ok": False, "reason": internal_error(err)})
        else:
            reply(query, {"ok": True, **(extra or {})})

    # ---- the runtime's part of the table's handlers (ServiceHost) ------------------------------------

    def publish_io(self) -> None:
        """Publish the IO message now."""
        self._status.publish_io()

    async def hand_back_control(self) -> None:
        """The pendant program continues: nothing being planned may start."""
        self._motion.end("hand_back_control", How.HAND_BACK)
        await self._backend.hand_back_control()

    def check_not_planning_from_rest(self) -> None:
        """Refuse while a linear goal is planned from where the robot rests (runtime/motion.py)."""
        self._motion.check_not_planning_from_rest()

    async def end_tool_contact(self) -> None:
        """End tool-contact detection; motion starts anew from where the robot rests, never from a
        setpoint of before the contact."""
        await self._backend.tool_contact(False)
        self._motion.end(TOOL_CONTACT_REASON, How.CONTACT, touched=False)

    async def set_tcp(self, pose: tuple[float, ...]) -> None:
        """Make ``pose`` the TCP offset: refused while anything moves or a goal is being planned (a plan
        is made for the TCP it started with); the controller's first (it refuses unless idle), then the
        backend's (the controller's is put back if the backend fails), then tcp_pose's."""
        planning = self._motion.planning
        if planning is not None:
            raise GoalRejected(f"set_tcp: the robot is busy: a goal is being planned ({planning})")
        controller = self._controller
        before = controller.tcp
        controller.set_tcp(pose)  # "set_tcp: the robot is moving" unless it rests
        try:
            await self._backend.set_tcp(pose)
        except BaseException:
            try:
                controller.set_tcp(before)
            except GoalRejected:  # a goal started meanwhile, with the new TCP: the backend's stays old
                self._log.warning("set_tcp failed on the backend while a goal started with the new TCP")
            raise
        if self._on_tcp is not None:
            self._on_tcp(pose)
