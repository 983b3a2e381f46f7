"""After hand_back_control the program leaves its loop: the backend sends it nothing more and starts
nothing on it until the program is taken back (startup, resend_program) or a new one connects.

No robot and no sockets: the callback servers hold stand-ins for the program's links.
"""

from __future__ import annotations

import pytest

from tests.ur.test_ur_passthrough_answers import StandInLink, connected_backend
from urdaemon.backends.ur.backend import UrBackend
from urdaemon.backends.ur.reverse_channel import ENDED_BY_HAND_BACK
from urdaemon.errors import BackendError
from urdaemon.model import CommandMode
from urdaemon.protocols import reverse
from urdaemon.protocols.trajectory_point import TrajectoryResultCode

PLAYING = 2
"""RTDE runtime_state of a program that plays."""


def frames(link: StandInLink) -> int:
    """Frames the link got, sent as messages or written pre-encoded."""
    return len(link.sent) + len(link.written)


def cycle(backend: UrBackend) -> None:
    """What the cycle does after the controller's tick, with the program playing."""
    backend._mapper.runtime_state = PLAYING
    backend._command_sent = False
    backend.send_command()


async def test_a_handed_back_program_gets_no_more_frames_and_no_freedrive() -> None:
    """Reproduction: hand back control, then the cycle runs and freedrive is asked for before the
    program has closed its socket. The backend kept writing idle frames after STOPPED and sent
    freedrive START to a program that had left its loop (the request was answered as if freedrive
    were on). Now nothing is sent after STOPPED and freedrive is refused, saying why."""
    backend, reverse_link = connected_backend()
    backend.command.mode = CommandMode.IDLE
    cycle(backend)
    assert frames(reverse_link) == 1, "a program that plays gets a keepalive each cycle"
    await backend.hand_back_control()
    assert isinstance(reverse_link.sent[-1], reverse.Stopped)
    count = frames(reverse_link)
    cycle(backend)
    with pytest.raises(BackendError, match="handed back"):
        backend.freedrive(True, 1.0)
    backend.freedrive(False, 1.0)  # ending a freedrive that is not on is never refused
    assert not backend.freedrive_active
    assert frames(reverse_link) == count, "nothing after STOPPED"
    assert backend.passthrough_problem() == (
        "control was handed back to the robot (resend_program takes it back)"
    )


async def test_hand_back_ends_the_passthrough_goal_the_robot_ran() -> None:
    """STOPPED ends the program's trajectory with it: the goal ends FAILURE at once (it ended when the
    program's link dropped before), and a new program that connects takes frames again. The goal's
    end names the hand back (it read "the robot reported that the trajectory failed" before)."""
    backend, reverse_link = connected_backend()
    results: list[tuple[str, int, str | None]] = []
    point = backend.encode_passthrough_point((0.0,) * 6, (0.0,) * 6, None, 1.0)
    backend.start_encoded_passthrough("g1", point, 1, lambda g, c, why: results.append((g, c, why)))
    assert backend.passthrough_problem() == "passthrough goal g1 is still running on the robot"
    await backend.hand_back_control()
    assert results == [("g1", int(TrajectoryResultCode.FAILURE), ENDED_BY_HAND_BACK)]
    assert backend.passthrough_goal is None
    backend.servers.reverse.link = None
    backend.on_link("reverse", False, "reverse: connection closed by the robot")
    backend.servers.reverse.link = reverse_link  # type: ignore[assignment]
    backend.on_link("reverse", True, "reverse: connected")  # played on the pendant
    count = frames(reverse_link)
    cycle(backend)
    assert frames(reverse_link) == count + 1
