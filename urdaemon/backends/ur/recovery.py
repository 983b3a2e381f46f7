"""Bounded auto-recovery of a UR robot after a protective stop (``ur.auto_recover``, opt-in).

``RecoveryPolicy`` decides, pure (the controller's time passed in): a protective stop seen first at
``t`` may be unlocked from ``t + UNLOCK_WAIT_S`` on (the controller refuses earlier), at most
``max_attempts`` times within ``within_s``; past that budget it gives up and says so once. An
emergency stop is never recovered: a person pressed it, and a person releases it. ``AutoRecovery``
does what the policy decides, through the dashboard and the backend's own ``resend_program`` (sent
again headless, played with the External Control URCap), and reports every step as a notice (the
robot's ``events``).
"""

from __future__ import annotations

import asyncio
import collections
import enum
import logging
from collections.abc import Awaitable, Callable

from urdaemon.cell.robot_options import UrAutoRecover, UrOptions
from urdaemon.errors import UrDaemonError
from urdaemon.model import RobotState, SafetyMode

__all__ = ["NOTICE", "UNLOCK_WAIT_S", "AutoRecovery", "Decision", "RecoveryPolicy", "auto_recovery"]

log = logging.getLogger("urdaemon.ur")

UNLOCK_WAIT_S = 5.0
"""The controller refuses to unlock a protective stop sooner than this after it (UR's rule)."""
NOTICE = "auto_recover"
"""The kind of every notice this module publishes (``<cell>/<robot>/events``)."""
SETTLE_S = 5.0
"""How long the safety mode may take to become normal after the unlock was accepted."""
_POLL_S = 0.05
_EMERGENCY = frozenset((SafetyMode.ROBOT_EMERGENCY_STOP, SafetyMode.SYSTEM_EMERGENCY_STOP))


class Decision(enum.Enum):
    """What the policy says to do now."""

    NOTHING = "nothing"
    WAIT = "a protective stop: wait the controller's 5 s, then unlock"
    RECOVER = "unlock the protective stop and start the program again"
    GIVE_UP = "the budget is spent: leave the robot as it is"
    EMERGENCY = "an emergency stop: never recovered automatically"


class RecoveryPolicy:
    """When to recover (see the module's docstring); ``decide`` once per look at the robot."""

    def __init__(self, options: UrAutoRecover) -> None:
        self.options = options
        self._stopped_at: float | None = None
        self._attempts: collections.deque[float] = collections.deque()
        self._said: Decision | None = None
        """The decision last reported for this stop (each is reported once per stop)."""

    def decide(self, safety: SafetyMode, now: float) -> Decision:
        """What to do about the robot's ``safety`` mode at controller time ``now``."""
        if safety in _EMERGENCY:
            self._stopped_at = None
            return self._once(Decision.EMERGENCY)
        if safety is not SafetyMode.PROTECTIVE_STOP or not self.options.protective_stop:
            self._stopped_at = None
            self._said = None
            return Decision.NOTHING
        if self._stopped_at is None:
            self._stopped_at = now
            self._said = None
        window = self.options.within_s
        attempts = self._attempts
        while attempts and now - attempts[0] > window:
            attempts.popleft()
        if len(attempts) >= self.options.max_attempts:
            return self._once(Decision.GIVE_UP)
        if now - self._stopped_at < UNLOCK_WAIT_S:
            return self._once(Decision.WAIT)
        attempts.append(now)
        self._stopped_at = None  # a stop that remains after this attempt counts as a new one
        self._said = None
        return Decision.RECOVER

    @property
    def attempts(self) -> int:
        """Attempts within the last ``within_s`` (as of the last ``decide``)."""
        return len(self._attempts)

    def _once(self, decision: Decision) -> Decision:
        if self._said is decision:
            return Decision.NOTHING
        self._said = decision
        return decision


def auto_recovery(
    name: str,
    options: UrOptions,
    state: RobotState,
    dashboard: Callable[[str], Awaitable[tuple[bool, str]]],
    restart: Callable[[], Awaitable[None]],
    notice: Callable[[str, str], None],
) -> AutoRecovery:
    """The robot's ``AutoRecovery`` under ``options.auto_recover`` (one that does nothing without it)."""
    policy = options.auto_recover or UrAutoRecover()
    return AutoRecovery(name, policy, state=state, dashboard=dashboard, restart=restart, notice=notice)


class AutoRecovery:
    """Carries out ``RecoveryPolicy``'s decisions for one robot."""

    def __init__(
        self,
        name: str,
        options: UrAutoRecover,
        *,
        state: RobotState,
        dashboard: Callable[[str], Awaitable[tuple[bool, str]]],
        restart: Callable[[], Awaitable[None]],
        notice: Callable[[str, str], None],
    ) -> None:
        self.name = name
        self.policy = RecoveryPolicy(options)
        self.state = state
        self._dashboard = dashboard
        self._restart = restart
        self._notice = notice
        self._task: asyncio.Task[None] | None = None

    def look(self) -> None:
        """Look at the robot now (the backend's link watch, a few times a second)."""
        if not self.policy.options.protective_stop or (self._task is not None and not self._task.done()):
            return
        state = self.state
        decision = self.policy.decide(state.safety_mode, state.controller_time)
        options = self.policy.options
        if decision is Decision.WAIT:
            self._say(f"protective stop: unlocking it in {UNLOCK_WAIT_S:g} s (the controller's wait)")
        elif decision is Decision.EMERGENCY:
            self._say("emergency stop: not recovered automatically; release it, then start up")
        elif decision is Decision.GIVE_UP:
            self._say(
                f"protective stop: not recovered, {options.max_attempts} attempts within "
                f"{options.within_s:g} s already; unlock it and resend_program by hand"
            )
        elif decision is Decision.RECOVER:
            attempt = self.policy.attempts
            self._task = asyncio.get_running_loop().create_task(self._recover(attempt))

    def close(self) -> None:
        """Stop a recovery under way (the links dropped, or the daemon stops)."""
        if self._task is not None:
            self._task.cancel()
            self._task = None

    async def _recover(self, attempt: int) -> None:
        options = self.policy.options
        self._say(f"unlocking the protective stop (attempt {attempt} of {options.max_attempts})")
        ok, reply = await self._dashboard("unlock protective stop")
        if not ok:
            self._say(f"unlocking the protective stop failed: {reply}")
            return
        for _ in range(round(SETTLE_S / _POLL_S)):
            if self.state.safety_mode is not SafetyMode.PROTECTIVE_STOP:
                break
            await asyncio.sleep(_POLL_S)
        else:
            self._say(f"the protective stop was not cleared within {SETTLE_S:g} s of the unlock")
            return
        self._say("protective stop unlocked; starting the control program again (resend_program)")
        try:
            await self._restart()
        except UrDaemonError as err:
            self._say(f"starting the control program again failed: {err}")
            return
        self._say("recovered from the protective stop: the control program was started again")

    def _say(self, text: str) -> None:
        log.info("[%s] auto-recover: %s", self.name, text)
        self._notice(NOTICE, text)
