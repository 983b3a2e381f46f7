"""Trajectory goals the robot interpolates itself (passthrough): encoded before they are accepted,
sent in one write, ended by the robot's result or by the daemon.

Which goal the robot runs is the backend's to say (``Backend.passthrough_goal``, the UR backend's
reverse channel): a goal ended by the daemon (stopped, aborted, not ready) that is the one the robot
runs also stops the robot's trajectory (runtime/motion.py ``publish_events``).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Generator

from urdaemon.backends.base import Backend, PassthroughResult
from urdaemon.control import GoalStatus, MotionController, Tolerances
from urdaemon.control.trajectory import TrajectoryPlanner
from urdaemon.errors import BackendError, GoalRejected
from urdaemon.runtime.queries import internal_error

__all__ = ["ROBOT_RESULTS", "Passthrough"]

ROBOT_RESULTS = {
    0: (GoalStatus.SUCCEEDED, "the robot finished the trajectory"),
    1: (GoalStatus.CANCELED, "canceled on the robot"),
}
"""The robot's trajectory result code → the goal's status and reason (any other code: aborted)."""


class Passthrough:
    """One robot's passthrough goals: the one the robot runs, if any."""

    def __init__(
        self,
        backend: Backend,
        controller: MotionController,
        log: logging.LoggerAdapter[logging.Logger],
    ) -> None:
        self._backend = backend
        self._controller = controller
        self._log = log

    def check_available(self) -> None:
        """Refuse a passthrough goal the backend cannot run now."""
        problem = self._backend.passthrough_problem()
        if problem is not None:
            raise GoalRejected(f"passthrough: {problem}")

    def encode_steps(self, planner: TrajectoryPlanner) -> Generator[None, None, tuple[bytes, int]]:
        """Every point as the robot receives it, a point a step, before the goal is accepted (the
        runtime runs them in slices): a value the robot cannot carry (a segment over 2147 s) refuses the
        goal, nothing is in limbo. Returns the frames and how many."""
        points, velocities = planner.points, planner.velocities
        encode = self._backend.encode_passthrough_point
        frames: list[bytes] = []
        for i, point in enumerate(points):
            segment = point.time_from_start - (points[i - 1].time_from_start if i else 0.0)
            try:
                frames.append(encode(point.positions, velocities[i], point.accelerations, segment))
            except BackendError as err:
                raise GoalRejected(f"passthrough: point {i}: {err}") from None
            if i + 1 < len(points):
                yield
        return b"".join(frames), len(frames)

    def start(
        self,
        goal_id: str,
        planner: TrajectoryPlanner,
        tolerances: Tolerances | None,
        frames: tuple[bytes, int],
        on_result: PassthroughResult,
    ) -> float:
        """Accept a goal the robot interpolates itself and send it its pre-encoded points (one write,
        no await in between). Everything that can refuse it ran before: accepting is the last step."""
        self.check_available()
        state = self._backend.state
        duration = self._controller.accept_external(
            goal_id, planner, state, time.monotonic(), tolerances=tolerances
        )
        try:
            self._backend.start_encoded_passthrough(goal_id, *frames, on_result)
        except Exception as err:  # a bug: the goal was accepted, so it ends with its one result now
            self._log.exception("passthrough goal %s could not be sent", goal_id)
            self._controller.finish_external(goal_id, GoalStatus.ABORTED, internal_error(err), state)
            return duration
        return duration

    def finish(self, goal_id: str, code: int, why: str | None = None) -> bool:
        """The result of ``goal_id``: the robot's code, or (``why``) the daemon's side ended it; True
        when it ended the goal (its result is an event)."""
        if why is not None:
            status, reason = GoalStatus.ABORTED, why
        else:
            status, reason = ROBOT_RESULTS.get(
                code, (GoalStatus.ABORTED, "the robot reported that the trajectory failed")
            )
        return self._controller.finish_external(goal_id, status, reason, self._backend.state)
