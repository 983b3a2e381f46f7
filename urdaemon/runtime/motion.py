"""One robot's motion, owned once: whether motion may start, what ends it, and goals planned in slices.

``RobotMotion`` is the only writer of the facts the rules read (shutting down, tool contact, the goal
being planned, "from rest", the generation) and the only caller of what ends motion: refusing the
goal being planned, cancelling the trajectory the robot runs itself, the controller's stop, abort or
cancel, publishing goal events and the status. It has two verbs:

- ``end(reason, how)``: every stop of the daemon (the stop service, a cancel, a lease that ends, a
  backend that fails or shuts down, a tool contact and its end, hand_back_control, freedrive) is one
  row of ``ENDINGS``, the steps below done in this order, each only where its row says:

  ======================  =========  =======  ===========  ==========  ==============  =======
  how                     planned    contact  passthrough  controller  program ended   publish
  ======================  =========  =======  ===========  ==========  ==============  =======
  stop                    refused    -        cancelled    stop        -               yes
  cancel                  refused    -        -            cancel      -               yes
  abort                   -          cleared  -            abort       yes             yes
  contact                 refused    set      -            abort       -               yes
  hand_back               refused    -        -            -           -               -
  ======================  =========  =======  ===========  ==========  ==============  =======

  The arguments narrow a row: ``goal_id`` ends that goal only (the goal being planned is not
  refused, unless ``or_planned`` and no goal of that id ran: a goal being planned has no id yet);
  ``end_freedrive`` ends freedrive too (a lease that ends); ``closing`` shuts down first; ``touched``
  False is a contact's end (``end_tool_contact``: cleared, and the controller aborts only if the
  robot rested in a contact). The trajectory the robot runs itself stops with its goal: the events
  step cancels it for a result of the goal it runs (a goal the daemon ended, in ``end`` or a cycle).
- ``plan(ticket, steps)``: stepped work (the one shape: a generator whose every ``next`` is one
  bounded step, such as a point decoded or checked, a segment planned or an IK's Newton evaluation,
  whose return value is the result and whose ``close`` abandons it; nothing inside reads a clock) run
  in slices between robot cycles under a
  ``Ticket`` (``claim``: the goal being planned, with its description; "from rest" for a linear
  goal), refused at the next slice once something ended motion (the generation) or the daemon shuts
  down. The ticket's ``with`` block clears it, once.
"""

from __future__ import annotations

import enum
import logging
import time
from collections.abc import Callable, Generator, Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Protocol, TypeVar

from urdaemon.backends.base import Backend
from urdaemon.control import GoalFeedback, GoalResult, MotionController
from urdaemon.errors import BackendError, GoalRejected
from urdaemon.runtime import slicing
from urdaemon.runtime.queries import SHUTTING_DOWN
from urdaemon.runtime.status import StatusPublisher

__all__ = [
    "ENDINGS",
    "STOPPED_WHILE_PLANNING",
    "TOOL_CONTACT_BUSY",
    "TOOL_CONTACT_REASON",
    "Ended",
    "Ending",
    "GoalEventSink",
    "How",
    "RobotMotion",
    "Ticket",
]

T = TypeVar("T")

STOPPED_WHILE_PLANNING = "stopped while it was being planned (stop, cancel, hand_back_control or freedrive)"
"""The reason a goal is refused when something ended motion while it was being planned."""
TOOL_CONTACT_REASON = "tool contact: the tool touched something; the robot stopped and went back to it"
"""The reason a goal or stream ends when the robot reports a tool contact."""
TOOL_CONTACT_BUSY = "busy: tool contact: the robot rests where its tool touched; call end_tool_contact first"
"""The reason motion is refused between a tool contact and ``end_tool_contact``."""


class How(enum.Enum):
    """How motion ends (``ENDINGS`` says what each does)."""

    STOP = "stop"
    """Whatever moves the robot stops (ramped): the stop service, a lease that ends, a cell goal's
    ``stop_all``."""
    CANCEL = "cancel"
    """A goal ends canceled: a cancel query, a cell goal's cancel."""
    ABORT = "abort"
    """The control script is gone: the backend failed, restarts or shuts down."""
    CONTACT = "contact"
    """The robot reported a tool contact (or, ``touched`` False, the contact ended)."""
    HAND_BACK = "hand_back"
    """Someone else moves the robot now (hand_back_control, freedrive): only the plan is refused."""


@dataclass(frozen=True, slots=True)
class Ending:
    """What an end does, step by step in this order (``RobotMotion.end``)."""

    refuse_planned: bool
    """The goal being planned is refused (the generation moves on)."""
    contact: bool | None
    """What ``in_contact`` becomes (None: unchanged)."""
    passthrough: bool
    """The trajectory the robot runs itself is cancelled, whatever goal it is."""
    controller: str | None
    """The controller's ``stop``, ``cancel`` or ``abort`` (None: not told)."""
    program_ended: bool
    """The robot's program no longer runs (a restarted control script starts anew)."""
    publish: bool
    """Goal events and the status are published."""


ENDINGS: Mapping[How, Ending] = MappingProxyType(
    {
        How.STOP: Ending(True, None, True, "stop", False, True),
        How.CANCEL: Ending(True, None, False, "cancel", False, True),
        How.ABORT: Ending(False, False, False, "abort", True, True),
        How.CONTACT: Ending(True, True, False, "abort", False, True),
        How.HAND_BACK: Ending(True, None, False, None, False, False),
    }
)
"""Each way motion ends, as data: the module docstring's table."""


@dataclass(frozen=True, slots=True)
class Ended:
    """What an end ended."""

    ended: bool
    """A goal (or, for a whole-robot end, whatever ran) ended; False: nothing of ``goal_id`` ran."""
    planned: str | None = None
    """The goal being planned that was refused (for a reply), None if none was."""


class GoalEventSink(Protocol):
    """Publishes one goal event (runtime/goal_events.py)."""

    def publish(self, event: GoalFeedback | GoalResult) -> None:
        """Publish ``event`` (signed with its goal's key)."""


class Ticket:
    """A goal's hold on the gate while it is planned: taken at once (``RobotMotion.claim``) and let go
    once, when its ``with`` block ends (the planning description and "from rest" are cleared)."""

    __slots__ = ("_release", "generation")

    def __init__(self, generation: int, release: Callable[[], None]) -> None:
        self.generation = generation
        """The generation the goal was asked in: anything that ends motion since refuses it."""
        self._release = release

    def __enter__(self) -> Ticket:
        return self

    def __exit__(self, *_: object) -> None:
        self._release()


class RobotMotion:
    """One robot's motion facts, the rules that read them, and the two verbs that change them."""

    def __init__(
        self,
        *,
        backend: Backend,
        controller: MotionController,
        status: StatusPublisher,
        events: GoalEventSink,
        log: logging.LoggerAdapter[logging.Logger],
    ) -> None:
        self._backend = backend
        self._controller = controller
        self._status = status
        self._events = events
        self._log = log
        self._closing = False
        self._in_contact = False
        self._planning: str | None = None
        self._from_rest = False
        self._generation = 0

    # ---- the facts (read-only outside) -----------------------------------------------------------

    @property
    def closing(self) -> bool:
        """Set first when the runtime shuts down: every new request is answered ``SHUTTING_DOWN``."""
        return self._closing

    @property
    def in_contact(self) -> bool:
        """The robot reported a tool contact and rests where it touched until ``end_tool_contact``."""
        return self._in_contact

    @property
    def planning(self) -> str | None:
        """What goal is being decoded or planned, kind first (for replies), None when none is."""
        return self._planning

    @property
    def from_rest(self) -> bool:
        """The goal being planned starts where the robot rests now (a linear goal's plan is the joints
        of every cycle from there): until it is answered nothing else may move the robot."""
        return self._from_rest

    @property
    def generation(self) -> int:
        """Counts what refuses the goal being planned (stop, cancel, contact, hand_back_control,
        freedrive on): a goal is started only if it is still the one it was asked in."""
        return self._generation

    # ---- the rules -------------------------------------------------------------------------------

    def check_accepting(self) -> None:
        """Refuse a streaming command while shutting down, in freedrive, resting after a contact, or
        while a goal is planned from where the robot rests."""
        if self._closing:
            raise GoalRejected(SHUTTING_DOWN)
        self.check_free_to_move()
        self.check_not_planning_from_rest()

    def check_not_planning_from_rest(self) -> None:
        """Refuse motion while a goal is planned from where the robot rests (``from_rest``): moved
        meanwhile, the robot would no longer be where that plan starts."""
        if self._from_rest:
            raise GoalRejected(
                f"busy: a linear goal is being planned from where the robot rests ({self._planning}); "
                "wait for its answer or cancel it"
            )

    def check_free_to_move(self) -> None:
        """Refuse motion while freedrive is on or the robot rests where its tool touched something."""
        if self._backend.freedrive_active:
            raise GoalRejected(
                "busy: freedrive is on (stop sending freedrive commands, or send active: false)"
            )
        if self._in_contact:
            raise GoalRejected(TOOL_CONTACT_BUSY)

    def check_still_wanted(self, generation: int) -> None:
        """Refuse a goal being planned if the daemon shuts down, or since ``generation`` something
        ended motion, or freedrive is on, or the robot rests in a contact."""
        self._check_generation(generation)
        self.check_free_to_move()

    def _check_generation(self, generation: int) -> None:
        if self._closing:
            raise GoalRejected(SHUTTING_DOWN)
        if generation != self._generation:
            raise GoalRejected(STOPPED_WHILE_PLANNING)

    # ---- plan: stepped work under the gate -------------------------------------------------------

    def claim(self, what: str, generation: int | None = None) -> Ticket:
        """Hold the gate for a goal being planned (``what``, kind first), now: refused while shutting
        down or while another goal is planned. ``generation``: the one the goal was asked in (default:
        now; what ended motion before the request counts as before it)."""
        if self._closing:
            raise GoalRejected(SHUTTING_DOWN)
        if self._planning is not None:
            raise GoalRejected(f"busy: still planning {self._planning}")
        self._planning = what
        return Ticket(self._generation if generation is None else generation, self._let_go)

    def _let_go(self) -> None:
        self._planning = None
        self._from_rest = False

    async def plan(
        self,
        ticket: Ticket,
        steps: Generator[None, None, T],
        *,
        what: str | None = None,
        from_rest: bool = False,
    ) -> T:
        """Run ``steps`` in slices between robot cycles under ``ticket``; its result. ``what``: what is
        planned now (for replies); ``from_rest``: nothing else may move the robot until the ticket is
        let go. Refused (``GoalRejected``) at the next slice once something ended motion since the
        ticket's generation or the daemon shuts down; the steps are closed either way."""
        if what is not None:
            self._planning = what
        if from_rest:
            self._from_rest = True
        try:
            return await slicing.sliced(steps, lambda: self._check_generation(ticket.generation))
        finally:
            steps.close()

    # ---- end: what ends motion -------------------------------------------------------------------

    def end(
        self,
        reason: str,
        how: How,
        goal_id: str | None = None,
        *,
        or_planned: bool = False,
        touched: bool = True,
        end_freedrive: bool = False,
        closing: bool = False,
    ) -> Ended:
        """End motion ``how`` (``ENDINGS``) for ``reason``; what it ended (the module docstring says
        what the arguments change)."""
        if closing:
            self.close()  # before anything else: no request may start motion from now on
        row = ENDINGS[how]
        if how is How.CONTACT and not touched:
            if not self._in_contact:
                return Ended(False)
            row = _CONTACT_ENDED
        ended = self._end_goal(reason, row.controller, goal_id)
        refuse = row.refuse_planned and (goal_id is None or (or_planned and not ended))
        planned = self._refuse_planned() if refuse else None
        if row.contact is not None:
            self._in_contact = row.contact
        if row.passthrough and goal_id is None:
            self._backend.cancel_passthrough()  # the trajectory the robot runs, if any, stops too
        if row.program_ended:
            self._backend.state.program_running = False
        if end_freedrive:
            self._end_freedrive()
        if row.publish and (ended or planned is not None):
            self.publish_events()
            self._status.publish()
        return Ended(ended, planned)

    def _end_goal(self, reason: str, verb: str | None, goal_id: str | None) -> bool:
        """The controller's part of an end; whether a goal (or, for a whole-robot end, anything) ended."""
        controller = self._controller
        if verb == "cancel":
            return controller.cancel(goal_id)
        if goal_id is not None and controller.active_goal_id != goal_id:
            return False
        if verb == "stop":
            controller.stop(reason, time.monotonic())
        elif verb == "abort":
            controller.abort(reason)
        return True

    def _refuse_planned(self) -> str | None:
        """Make the goal being planned (if any) be refused; what it was, for the reply."""
        self._generation += 1
        if self._planning is None:
            return None
        return f"the goal being planned ({self._planning}) is refused"

    def _end_freedrive(self) -> None:
        if self._backend.freedrive_active:
            try:
                self._backend.freedrive(False, 0.0)
            except BackendError as err:
                self._log.warning("ending freedrive as the lease ended failed: %s", err)

    def close(self) -> None:
        """The runtime shuts down: every request from now on is answered ``SHUTTING_DOWN``."""
        self._closing = True

    def publish_events(self) -> None:
        """Publish the controller's goal feedback and results; a result of the goal the robot runs
        itself (ended here: not ready, stopped, aborted) stops the robot's trajectory too, or it would
        carry on after play."""
        backend = self._backend
        for event in self._controller.drain_events():
            if isinstance(event, GoalResult) and event.goal_id == backend.passthrough_goal:
                backend.cancel_passthrough()
            self._events.publish(event)

    def report(self) -> None:
        """Publish what a goal that started or ended changed: its events, then the status."""
        self.publish_events()
        self._status.publish()


_CONTACT_ENDED = Ending(False, False, False, "abort", False, True)
"""A contact's end (``end_tool_contact``): motion starts anew from where the robot rests, never from a
setpoint of before the contact."""
