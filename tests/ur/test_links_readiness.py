"""The status reason of a UR robot that is not ready: what it says for each state (pure)."""

from __future__ import annotations

import dataclasses

import pytest

from urdaemon.backends.ur.readiness import ProgramFacts, not_ready_reason
from urdaemon.model import UR_JOINTS, Lifecycle, RobotMode, RobotState, SafetyMode

FACTS = ProgramFacts(
    read_only=False,
    headless=True,
    handed_back=False,
    lost_link="",
    missing=("reverse", "trajectory", "script_command"),
    links=3,
    program_ended="",
    startup_problem="",
)


def _state(lifecycle: Lifecycle, mode: RobotMode, safety: SafetyMode = SafetyMode.NORMAL) -> RobotState:
    state = RobotState.zeros(UR_JOINTS)
    state.lifecycle = lifecycle
    state.robot_mode = mode
    state.safety_mode = safety
    return state


@pytest.mark.parametrize(
    ("state", "changes", "expected"),
    [
        (_state(Lifecycle.IDLE, RobotMode.POWER_OFF), {}, "the robot is powered off: call startup"),
        (_state(Lifecycle.IDLE, RobotMode.IDLE), {}, "the brakes are engaged"),
        (
            _state(Lifecycle.PROTECTIVE_STOP, RobotMode.RUNNING, SafetyMode.PROTECTIVE_STOP),
            {},
            "protective stop: unlock it",
        ),
        (
            _state(Lifecycle.PROTECTIVE_STOP, RobotMode.RUNNING, SafetyMode.SAFEGUARD_STOP),
            {},
            "safety mode SAFEGUARD_STOP: clear its cause",
        ),
        (
            _state(Lifecycle.EMERGENCY_STOP, RobotMode.POWER_OFF, SafetyMode.ROBOT_EMERGENCY_STOP),
            {"startup_problem": "start-up failed: power on refused: Failed to execute: power on"},
            "emergency stop (ROBOT_EMERGENCY_STOP): release it, then start up again; "
            "start-up failed: power on",
        ),
        (_state(Lifecycle.PAUSED, RobotMode.RUNNING), {}, "the program is paused"),
        (_state(Lifecycle.RUNNING, RobotMode.RUNNING), {"handed_back": True}, "control handed back"),
        (
            _state(Lifecycle.RUNNING, RobotMode.RUNNING),
            {"lost_link": "trajectory", "missing": ("trajectory",)},
            "the control program lost its trajectory link: restarting the program",
        ),
        (
            _state(Lifecycle.RUNNING, RobotMode.RUNNING),
            {"lost_link": "script_command", "missing": ("script_command",), "headless": False},
            "the control program lost its script_command link: restart it (resend_program or play)",
        ),
        (
            _state(Lifecycle.RUNNING, RobotMode.RUNNING),
            {"missing": ("reverse",)},
            "the control program is connecting back (waiting for: reverse)",
        ),
        (
            _state(Lifecycle.RUNNING, RobotMode.RUNNING),
            {"program_ended": "runtime exception at 3:1: boom"},
            "the control program ended: runtime exception at 3:1: boom",
        ),
        (
            _state(Lifecycle.RUNNING, RobotMode.RUNNING),
            {"headless": False},
            "waiting for the control program: play it on the pendant",
        ),
        (_state(Lifecycle.RUNNING, RobotMode.RUNNING), {"read_only": True}, "read-only"),
    ],
)
def test_the_reason_says_why_and_what_to_do(
    state: RobotState, changes: dict[str, object], expected: str
) -> None:
    """Each not-ready state has its own words (before issue 13 an idle robot's reason was empty)."""
    assert not_ready_reason(state, dataclasses.replace(FACTS, **changes)).startswith(expected)  # type: ignore[arg-type]
