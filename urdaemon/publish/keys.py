"""Key expressions: everything of a robot lives under ``<cell>/<robot>/``; see docs/keys.md."""

from __future__ import annotations

from dataclasses import dataclass

from urdaemon.model import CELL_LEVEL_KEYS

__all__ = ["ALIVE_ANYWHERE", "CellKeys", "RobotKeys"]

ALIVE_ANYWHERE = "*/*/alive"
"""Every robot's liveliness token in every cell: what a client asks to find the robots served
(``CellKeys.of_alive`` reads each answer)."""


@dataclass(frozen=True, slots=True)
class CellKeys:
    """Keys of the cell as a whole."""

    cell: str

    @property
    def tf(self) -> str:
        """Every link pose of the cell in the ``world`` frame."""
        return f"{self.cell}/tf"

    @property
    def robot_description(self) -> str:
        """The cell URDF (queryable)."""
        return f"{self.cell}/robot_description"

    @property
    def daemon(self) -> str:
        """Queryable: the daemon serving the cell describes itself and its robots (what ``urdaemon
        list`` and ``info`` show; runtime/daemon_info.py)."""
        return f"{self.cell}/daemon"

    @property
    def any_robot(self) -> str:
        """Every key under any robot's name (the daemon answers queries on robots it does not serve)."""
        return f"{self.cell}/*/**"

    @property
    def cell_level(self) -> frozenset[str]:
        """The chunks after ``<cell>/`` that name a key of the cell, not a robot."""
        return CELL_LEVEL_KEYS

    @property
    def audit(self) -> str:
        """The audit log's entries (runtime/audit.py): each commanding request and session."""
        return f"{self.cell}/audit"

    @property
    def stop(self) -> str:
        """The cell's stop: every robot of the cell stops (the queryable answers once, for all)."""
        return f"{self.cell}/service/stop"

    @property
    def flight_record(self) -> str:
        """Queryable: write the flight recorder's last seconds to a file now (answered with its path);
        served only with the cell file's ``record`` section."""
        return f"{self.cell}/service/flight_record"

    @property
    def goal_trajectory(self) -> str:
        """Queryable: a cell goal, trajectories that start together on several robots."""
        return f"{self.cell}/goal/trajectory"

    @property
    def goal_cancel(self) -> str:
        """Queryable: cancel a cell goal (every robot's part of it stops)."""
        return f"{self.cell}/goal/cancel"

    def goal_feedback(self, goal_id: str) -> str:
        """Feedback of one cell goal while it runs."""
        return f"{self.cell}/goal/{goal_id}/feedback"

    def goal_result(self, goal_id: str) -> str:
        """The one result of a cell goal (published, and answered to queries afterwards)."""
        return f"{self.cell}/goal/{goal_id}/result"

    @property
    def goal_results(self) -> str:
        """Every cell goal's result (wildcard)."""
        return f"{self.cell}/goal/*/result"

    def goal_of_result(self, key: str) -> str | None:
        """The goal id a cell goal's result key names (``goal_result``'s inverse); None for another key."""
        return _goal_of_result(key, self.cell)

    @property
    def goal_messages(self) -> str:
        """Every cell goal's feedback and result (wildcard: what a client follows)."""
        return f"{self.cell}/goal/*/*"

    @property
    def lease_holders(self) -> str:
        """Every robot's lease holders' liveliness tokens (wildcard: what the daemon watches)."""
        return f"{self.cell}/*/lease/*"

    def robot(self, name: str) -> RobotKeys:
        """The keys of one robot."""
        return RobotKeys(self.cell, name)

    def parse(self, key: str) -> tuple[str, tuple[str, ...]] | None:
        """The robot a concrete key of this cell is under and the chunks after its name
        (``<cell>/alice/service/stop`` → ``("alice", ("service", "stop"))``); ``None`` for a key
        with a wildcard, a key outside the cell, or a key of the cell itself (``tf``, ...)."""
        prefix = f"{self.cell}/"
        if "*" in key or not key.startswith(prefix):
            return None
        robot, *rest = key[len(prefix) :].split("/")
        if not robot or robot in self.cell_level:
            return None
        return robot, tuple(rest)

    @staticmethod
    def of_alive(key: str) -> tuple[str, str] | None:
        """The cell and robot a robot's liveliness token names (``RobotKeys.alive``'s inverse,
        ``<cell>/alice/alive`` → ``("<cell>", "alice")``); None for any other key."""
        chunks = key.split("/")
        if len(chunks) != 3 or chunks[2] != "alive" or not all(chunks[:2]) or "*" in key:
            return None
        return chunks[0], chunks[1]

    @staticmethod
    def goal_message(rest: tuple[str, ...]) -> tuple[str, str] | None:
        """The goal id and message kind (``feedback``, ``result``) a robot's goal message key names,
        from the chunks :meth:`parse` returns after the robot's name (``("goal", "g1", "result")``
        → ``("g1", "result")``); None for any other key."""
        if len(rest) == 3 and rest[0] == "goal" and rest[1] and rest[2] in ("feedback", "result"):
            return rest[1], rest[2]
        return None

    @staticmethod
    def service_name(rest: tuple[str, ...]) -> str | None:
        """The service a robot's key names, from the chunks :meth:`parse` returns after the robot's
        name (``("service", "stop")`` → ``"stop"``); ``None`` for any other key."""
        return rest[1] if len(rest) == 2 and rest[0] == "service" else None


@dataclass(frozen=True, slots=True)
class RobotKeys:
    """Keys of one robot."""

    cell: str
    robot: str

    @property
    def base(self) -> str:
        """``<cell>/<robot>``."""
        return f"{self.cell}/{self.robot}"

    @property
    def joint_states(self) -> str:
        """Joint positions, velocities and efforts at the robot rate."""
        return f"{self.base}/joint_states"

    @property
    def tcp_pose(self) -> str:
        """The TCP pose (tool0 with the robot's TCP offset) in the robot's base frame at the robot rate."""
        return f"{self.base}/tcp_pose"

    @property
    def status(self) -> str:
        """Backend, lifecycle, modes, speed scaling; on change and periodically."""
        return f"{self.base}/status"

    @property
    def io(self) -> str:
        """Digital/analog inputs and outputs, tool voltage, payload."""
        return f"{self.base}/io"

    @property
    def alive(self) -> str:
        """Liveliness token, present while the daemon serves the robot."""
        return f"{self.base}/alive"

    @property
    def events(self) -> str:
        """Rejected streaming commands and other notices."""
        return f"{self.base}/events"

    @property
    def servo_command(self) -> str:
        """PCA9685 channel values of a servo robot."""
        return f"{self.base}/servo_command"

    @property
    def goal_trajectory(self) -> str:
        """Queryable: send a joint trajectory goal."""
        return f"{self.base}/goal/trajectory"

    @property
    def goal_move(self) -> str:
        """Queryable: send a point-to-point move goal."""
        return f"{self.base}/goal/move"

    @property
    def goal_linear(self) -> str:
        """Queryable: send a linear goal (straight TCP lines through a list of poses)."""
        return f"{self.base}/goal/linear"

    @property
    def goal_cancel(self) -> str:
        """Queryable: cancel a goal."""
        return f"{self.base}/goal/cancel"

    def goal_feedback(self, goal_id: str) -> str:
        """Feedback of one goal while it runs."""
        return f"{self.base}/goal/{goal_id}/feedback"

    def goal_result(self, goal_id: str) -> str:
        """The one result of a goal (published, and answered to queries afterwards)."""
        return f"{self.base}/goal/{goal_id}/result"

    @property
    def goal_results(self) -> str:
        """Every goal's result (wildcard)."""
        return f"{self.base}/goal/*/result"

    def goal_of_result(self, key: str) -> str | None:
        """The goal id a result key of this robot names (``goal_result``'s inverse); None for another key."""
        return _goal_of_result(key, self.base)

    @property
    def command_joint_position(self) -> str:
        """Streaming joint position commands (deadman)."""
        return f"{self.base}/command/joint_position"

    @property
    def command_joint_velocity(self) -> str:
        """Streaming joint velocity commands (deadman)."""
        return f"{self.base}/command/joint_velocity"

    @property
    def command_twist(self) -> str:
        """Streaming TCP twist commands (deadman)."""
        return f"{self.base}/command/twist"

    @property
    def command_freedrive(self) -> str:
        """Freedrive (hand guiding) commands (deadman)."""
        return f"{self.base}/command/freedrive"

    @property
    def goal_messages(self) -> str:
        """Every goal's feedback and result (wildcard: what a client follows)."""
        return f"{self.base}/goal/*/*"

    @property
    def lease(self) -> str:
        """Queryable: acquire, release, take over or show the robot's command lease."""
        return f"{self.base}/lease"

    def lease_holder(self, session: str) -> str:
        """The liveliness token a lease holder declares, binding the lease to its Zenoh session."""
        return f"{self.base}/lease/{session}"

    def service(self, name: str) -> str:
        """Queryable service ``name`` (publish/services.py lists them)."""
        return f"{self.base}/service/{name}"


def _goal_of_result(key: str, base: str) -> str | None:
    """The goal id in ``<base>/goal/<id>/result``; None for any other key (a wildcard included)."""
    head, tail = f"{base}/goal/", "/result"
    if not (key.startswith(head) and key.endswith(tail)):
        return None
    goal_id = key[len(head) : -len(tail)]
    return goal_id if goal_id and "/" not in goal_id and "*" not in goal_id else None
