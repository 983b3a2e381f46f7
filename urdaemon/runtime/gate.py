"""Whether motion may start now: the rules every goal, stream and freedrive command passes.

Motion is refused once the daemon shuts down, while freedrive is on, and while the robot rests where
its tool touched something (until ``end_tool_contact``). A trajectory goal is planned over many turns
of the event loop: it is accepted only if nothing ended motion meanwhile (``generation``).
"""

from __future__ import annotations

from urdaemon.backends.base import Backend
from urdaemon.errors import GoalRejected
from urdaemon.runtime.queries import SHUTTING_DOWN

__all__ = ["STOPPED_WHILE_PLANNING", "TOOL_CONTACT_BUSY", "TOOL_CONTACT_REASON", "MotionGate"]

STOPPED_WHILE_PLANNING = "stopped while it was being planned (stop, cancel, hand_back_control or freedrive)"
"""The reason a trajectory goal is refused when something ended motion while it was being planned."""
TOOL_CONTACT_REASON = "tool contact: the tool touched something; the robot stopped and went back to it"
"""The reason a goal or stream ends when the robot reports a tool contact."""
TOOL_CONTACT_BUSY = "busy: tool contact: the robot rests where its tool touched; call end_tool_contact first"
"""The reason motion is refused between a tool contact and ``end_tool_contact``."""


class MotionGate:
    """One robot's rules for starting motion, and the facts they read."""

    def __init__(self, backend: Backend) -> None:
        self._backend = backend
        self.closing = False
        """Set first when the runtime shuts down: every new request is answered ``SHUTTING_DOWN``."""
        self.in_contact = False
        """The robot reported a tool contact and rests where it touched until ``end_tool_contact``."""
        self.planning: str | None = None
        """What goal is being decoded or planned, kind first (for replies), None when none is."""
        self.from_rest = False
        """The goal being planned starts where the robot rests now (a linear goal's plan is the joints of
        every cycle from there): until it is answered nothing else may move the robot."""
        self.generation = 0
        """Counts what ends motion (stop, cancel, hand_back_control, freedrive on): a trajectory being
        planned is accepted only if it is still the same as when its planning began."""

    def check_accepting(self) -> None:
        """Refuse a streaming command while shutting down, in freedrive, resting after a contact, or
        while a goal is planned from where the robot rests."""
        if self.closing:
            raise GoalRejected(SHUTTING_DOWN)
        self.check_free_to_move()
        self.check_not_planning_from_rest()

    def check_not_planning_from_rest(self) -> None:
        """Refuse motion while a goal is planned from where the robot rests (``from_rest``): moved
        meanwhile, the robot would no longer be where that plan starts."""
        if self.from_rest:
            raise GoalRejected(
                f"busy: a linear goal is being planned from where the robot rests ({self.planning}); "
                "wait for its answer or cancel it"
            )

    def check_free_to_move(self) -> None:
        """Refuse motion while freedrive is on or the robot rests where its tool touched something."""
        if self._backend.freedrive_active:
            raise GoalRejected(
                "busy: freedrive is on (stop sending freedrive commands, or send active: false)"
            )
        if self.in_contact:
            raise GoalRejected(TOOL_CONTACT_BUSY)

    def check_still_wanted(self, generation: int) -> None:
        """Refuse a goal being planned if the daemon shuts down, or since ``generation`` something
        ended motion (stop, cancel, hand_back_control, freedrive), or freedrive is on."""
        if self.closing:
            raise GoalRejected(SHUTTING_DOWN)
        if generation != self.generation:
            raise GoalRejected(STOPPED_WHILE_PLANNING)
        self.check_free_to_move()

    def interrupt_planning(self) -> str | None:
        """Make the goal being planned (if any) be refused; what it was, for the reply."""
        self.generation += 1
        if self.planning is None:
            return None
        return f"the goal being planned ({self.planning}) is refused"
