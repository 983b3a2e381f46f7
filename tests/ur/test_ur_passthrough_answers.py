"""The UR backend's passthrough goals end with their own trajectory result, never a canceled one's.

No robot and no sockets: the callback servers hold stand-ins for the program's links, and the
robot's answers arrive as the servers would hand them over (``on_event``).
"""

from __future__ import annotations

import time
from typing import Any

from tests.helpers import fake_address
from tests.ur.test_links_harness import HOME, JOINTS, robot_config
from urdaemon.backends.ur.backend import UrBackend
from urdaemon.protocols import reverse
from urdaemon.protocols.trajectory_point import TrajectoryResult, TrajectoryResultCode


class StandInLink:
    """What a callback server's link is to the backend: it sends and writes."""

    def __init__(self) -> None:
        self.sent: list[Any] = []
        self.written: list[bytes] = []

    def send(self, message: Any) -> None:
        self.sent.append(message)

    def write(self, data: bytes) -> None:
        self.written.append(data)

    def close(self) -> None:
        return


def connected_backend() -> tuple[UrBackend, StandInLink]:
    """A backend whose control program holds all its links (the reverse one last, as it dials)."""
    backend = UrBackend(robot_config(fake_address()), JOINTS, expected_hash=None)
    reverse_link = StandInLink()
    for server in (backend.servers.trajectory, backend.servers.script_command, backend.servers.reverse):
        server.link = reverse_link if server is backend.servers.reverse else StandInLink()  # type: ignore[assignment]
        server.connected_at = time.monotonic()
        backend.on_link(server.name, True, f"{server.name}: connected")
    return backend, reverse_link


async def test_two_canceled_goals_answers_do_not_end_the_goal_after_them() -> None:
    """Reproduction: start passthrough g1, cancel it, start g2, cancel it, start g3; the robot answers
    CANCELED for g1, then for g2. The backend kept one "swallow the next result" flag: g1's answer
    cleared it and g2's ended g3 as canceled on the robot, while the robot still ran g3. Now each
    canceled trajectory's answer is owed and dropped, and g3 ends with its own result."""
    backend, reverse_link = connected_backend()
    results: list[tuple[str, int]] = []
    point = backend.encode_passthrough_point(HOME, (0.0,) * 6, None, 1.0)
    for goal in ("g1", "g2"):
        backend.start_encoded_passthrough(goal, point, 1, lambda g, c, _why: results.append((g, c)))
        backend.cancel_passthrough()
    backend.start_encoded_passthrough("g3", point, 1, lambda g, c, _why: results.append((g, c)))
    cancels = [
        m
        for m in reverse_link.sent
        if isinstance(m, reverse.TrajectoryControl) and m.action is reverse.TrajectoryAction.CANCEL
    ]
    assert len(cancels) == 2
    for _ in range(2):
        backend.on_event("trajectory", TrajectoryResult(TrajectoryResultCode.CANCELED))
    assert results == [], "a canceled goal's answer ended a goal"
    assert backend.passthrough_problem() == "passthrough goal g3 is still running on the robot"
    backend.on_event("trajectory", TrajectoryResult(TrajectoryResultCode.SUCCESS))
    assert results == [("g3", int(TrajectoryResultCode.SUCCESS))]
    assert backend.passthrough_problem() is None
