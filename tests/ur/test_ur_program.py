"""The control program's bookkeeping with time passed in: when it is sent headless, when a resend is
refused, and when the cycle wants a new one (no robot, no sockets, no clock)."""

from __future__ import annotations

from typing import Any

import pytest

from tests.helpers import fake_address
from tests.ur.test_links_harness import JOINTS, robot_config
from urdaemon.backends.ur.program import PROGRAM_RESEND_S, ControlProgram
from urdaemon.backends.ur.reverse_channel import RUNTIME_PLAYING, ReverseChannel
from urdaemon.backends.ur.rtde_link import RUNTIME_PAUSED
from urdaemon.backends.ur.servers import CallbackServers
from urdaemon.cell.robot_options import UrOptions
from urdaemon.model import Lifecycle, RobotMode, RobotState


class NoHooks:
    def on_link(self, name: str, connected: bool, reason: str) -> None:
        return

    def on_event(self, name: str, event: Any) -> None:
        return


def program(*, headless: bool = True, read_only: bool = False) -> ControlProgram:
    robot = robot_config(fake_address(), headless=headless)
    options = (robot.ur or UrOptions()).model_copy(update={"read_only": read_only})
    servers = CallbackServers(robot.address, robot.ports.as_dict(), NoHooks())
    return ControlProgram(robot, options, robot.ports.as_dict(), servers, lambda ip, o, p: f"# for {ip}")


def test_sent_headless_at_most_every_resend_interval_unless_forced() -> None:
    p = program()
    assert p.due(100.0, force=False)
    assert p.sent_at == p.started_at == 100.0
    assert not p.due(100.0 + PROGRAM_RESEND_S - 0.01, force=False)
    assert p.due(100.5, force=True)
    assert p.due(100.5 + PROGRAM_RESEND_S, force=False)


def test_a_resend_is_refused_while_the_program_sent_last_connects_back() -> None:
    p = program()
    p.due(100.0, force=False)
    assert p.still_connecting(100.5) == (
        "the control program sent 0.50 s ago is still connecting back: not sending another"
    )
    assert p.still_connecting(100.0 + PROGRAM_RESEND_S) is None
    p.links_up_at = 100.2  # it connected back
    assert p.still_connecting(100.5) is None


def running() -> RobotState:
    state = RobotState.zeros(JOINTS)
    state.robot_mode = RobotMode.RUNNING
    state.lifecycle = Lifecycle.RUNNING
    return state


WANTED: list[tuple[str, dict[str, Any], bool]] = [
    # (case, what differs from a headless robot that runs with no program, wanted)
    ("no program", {}, True),
    ("handed back", {"handed_back": True}, False),
    ("read-only", {"read_only": True}, False),
    ("URCap", {"headless": False}, False),
    ("brakes engaged", {"mode": RobotMode.IDLE}, False),
    ("protective stop", {"lifecycle": Lifecycle.PROTECTIVE_STOP}, False),
    ("a program is connecting", {"links": ("trajectory",)}, False),
    ("a program plays without its script command link", {"links": ("reverse", "trajectory")}, False),
    ("the program lost a link", {"links": ("reverse", "trajectory"), "lost_link": "script_command"}, True),
    ("a paused program holds only the reverse link", {"links": ("reverse",), "playing": False}, True),
]


@pytest.mark.parametrize(("case", "given", "wanted"), WANTED, ids=[row[0] for row in WANTED])
def test_when_the_cycle_sends_a_program(case: str, given: dict[str, Any], wanted: bool) -> None:
    p = program(headless=given.get("headless", True), read_only=given.get("read_only", False))
    state = running()
    state.robot_mode = given.get("mode", RobotMode.RUNNING)
    state.lifecycle = given.get("lifecycle", Lifecycle.RUNNING)
    for name in given.get("links", ()):
        getattr(p.servers, name).link = object()
    p.lost_link = given.get("lost_link", "")
    runtime_state = RUNTIME_PLAYING if given.get("playing", True) else RUNTIME_PAUSED
    channel = ReverseChannel()
    if given.get("links", ()) and "reverse" in given["links"]:
        channel.program_connected()
    if given.get("handed_back", False):
        channel.program_connected()
        channel.hand_back()
    assert p.wanted(state, runtime_state, channel) is wanted, case
