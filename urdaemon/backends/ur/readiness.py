"""Why a UR robot cannot take motion now, and what to do about it: the status's ``reason``.

Pure: the robot's state and what the backend knows about its control program in, one sentence out.
The backend words it only while the robot is not ready, and only when something it depends on
changed.
"""

from __future__ import annotations

from dataclasses import dataclass

from urdaemon.model import Lifecycle, RobotMode, RobotState, SafetyMode

__all__ = ["ProgramFacts", "not_ready_reason"]


@dataclass(frozen=True, slots=True)
class ProgramFacts:
    """What the backend knows about its control program."""

    read_only: bool
    headless: bool
    handed_back: bool
    """hand_back_control ended the program's loop."""
    lost_link: str
    """The program link that dropped while the others stayed up ("" if none)."""
    missing: tuple[str, ...]
    """The program links not connected now."""
    links: int
    """How many links the program holds while it runs."""
    program_ended: str
    """What the controller said when the program last ended ("" if nothing)."""
    startup_problem: str
    """Why the last start-up failed ("" if it did not, or none ran)."""


def not_ready_reason(state: RobotState, facts: ProgramFacts) -> str:
    """The reason for a robot that is not ready (``state.lifecycle`` as RTDE last reported it)."""
    lifecycle = state.lifecycle
    problem = f"; {facts.startup_problem}" if facts.startup_problem else ""
    if lifecycle is Lifecycle.EMERGENCY_STOP:
        return f"emergency stop ({state.safety_mode.name}): release it, then start up again{problem}"
    if lifecycle is Lifecycle.PROTECTIVE_STOP:
        if state.safety_mode is SafetyMode.PROTECTIVE_STOP:
            return (
                "protective stop: unlock it (dashboard 'unlock protective stop' or the pendant), "
                f"then {_restart(facts)}{problem}"
            )
        return f"safety mode {state.safety_mode.name}: clear its cause on the robot's safety system{problem}"
    if lifecycle is Lifecycle.IDLE:
        mode = state.robot_mode
        if mode is RobotMode.POWER_OFF:
            return f"the robot is powered off: call startup, or power it on on the pendant{problem}"
        if mode is RobotMode.IDLE:
            return f"the brakes are engaged: call startup, or release them on the pendant{problem}"
        return f"robot mode {mode.name}{problem}"
    if lifecycle is Lifecycle.PAUSED:
        return f"the program is paused on the controller: {_restart(facts)}"
    if lifecycle is not Lifecycle.RUNNING:
        return state.lifecycle_reason  # connecting, recovering: the backend's own words stand
    return _program_reason(facts, problem)


def _restart(facts: ProgramFacts) -> str:
    """The action that starts the control program again after a pause or a protective stop: a headless
    program is no program the controller can resume (its play plays the loaded .urp), so only the
    daemon sending it again works; an External Control program resumes with play."""
    if facts.headless:
        return "call resend_program (a headless program cannot be resumed with play)"
    return "resume it (play, on the pendant or the dashboard) or call resend_program"


def _program_reason(facts: ProgramFacts, problem: str) -> str:
    """The robot runs (powered, brakes off, no stop) but the control program does not hold its links."""
    if facts.read_only:
        return "read-only (ur.read_only: true): watching, not commanding"
    if facts.handed_back:
        return "control handed back to the robot"  # (resend_program takes it back)
    if facts.lost_link:
        return f"the control program lost its {facts.lost_link} link: " + (
            "restarting the program" if facts.headless else "restart it (resend_program or play)"
        )
    if facts.missing and len(facts.missing) < facts.links:
        return f"the control program is connecting back (waiting for: {', '.join(facts.missing)})"
    if facts.program_ended:
        return f"the control program ended: {facts.program_ended}{problem}"
    if problem:
        return problem[2:]
    if not facts.headless:
        return "waiting for the control program: play it on the pendant or call resend_program"
    return "waiting for the control program to connect"
