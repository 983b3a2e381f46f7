"""What the view sends one robot: enable (lease, then sliders synced to the robot), the joint stream of
the sliders, jogs, stop and disable. No GUI here: the panel calls these on the asyncio loop.

Safety, in order:

- **Enable** takes the robot's command lease (refused, with the holder named, when someone else has
  it: nothing is sent) and sets every target to the robot's current joints *before* the stream
  starts, so enabling moves nothing; without joint_states newer than ``STALE_S`` it gives the lease
  back and refuses (the robot may be elsewhere than the last sample says).
- **While enabled** ``tick`` (the view's stream loop, every ``STREAM_PERIOD_S``) sends the targets as
  one joint position command; the daemon tracks them jerk-limited (ruckig). When ticks stop (the view
  disabled, the page closed, the process died) the daemon's deadman (``motion.stream_timeout``) brings
  the robot to a smooth stop.
- **A jog** is a short twist (``JOG_S`` at the chosen speed, then ``ZERO_SENDS`` zero twists); the
  joint stream pauses meanwhile (never both at once) and its targets are synced to where the jog
  left the robot before it goes on.
- **Disable** stops sending and releases the lease (the daemon stops the robot on release);
  **stop** disables and asks the robot to stop (always, no lease needed).
- A stream command the daemon refuses (a ``command_rejected`` event, other than a sample replaced by
  a newer one) disables, keeping the reason to show.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import time
from collections.abc import Callable, Sequence
from typing import Any, Protocol

from urdaemon.errors import GoalRejected, UrDaemonError
from urdaemon.view.feed import STALE_S, JointSample

__all__ = [
    "JOG_S",
    "SETTLE_SPEED",
    "STREAM_PERIOD_S",
    "ZERO_SENDS",
    "Commandable",
    "RobotControl",
    "jog_twist",
]

STREAM_PERIOD_S = 0.02
"""Joint stream commands and jog twists go out every 20 ms (50 Hz): well within the deadman."""
JOG_S = 0.3
"""A jog click moves for this long, then decelerates (viser buttons give clicks, not presses)."""
ZERO_SENDS = 5
"""Zero twists sent after a jog (the robot decelerates) before the joint stream takes over."""
SETTLE_SPEED = 1e-3
"""rad/s: after a jog, the stream's targets are taken once every joint is slower than this..."""
SETTLE_TICKS = 50
"""...or after this many stream periods (1 s), whichever comes first."""
ANGULAR_PER_LINEAR = 5.0
"""A rotation jog turns at this many rad/s per m/s of the jog speed (0.05 m/s: 0.25 rad/s)."""
AXES = ("x", "y", "z", "rx", "ry", "rz")


class Commandable(Protocol):
    """What the control needs of a robot (``urdaemon.client.RobotClient`` has it all)."""

    @property
    def name(self) -> str: ...

    async def ensure_lease(self) -> str: ...

    async def release(self) -> None: ...

    async def stop(self) -> dict[str, Any]: ...

    def stream_positions(
        self, positions: Sequence[float], velocities: Sequence[float] | None = None
    ) -> None: ...

    def twist(self, linear: Sequence[float], angular: Sequence[float], *, frame: str = "base") -> None: ...


def jog_twist(axis: str, sign: int, speed: float) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """(linear, angular) of a jog along ``axis`` (``x`` .. ``rz``), ``sign`` ±1, at ``speed`` m/s."""
    if axis not in AXES or sign not in (-1, 1) or not (math.isfinite(speed) and speed > 0):
        raise ValueError(f"no jog along {axis!r} (sign {sign}, speed {speed})")
    index = AXES.index(axis)
    twist = [0.0] * 6
    twist[index] = sign * (speed if index < 3 else ANGULAR_PER_LINEAR * speed)
    return tuple(twist[:3]), tuple(twist[3:])


class RobotControl:
    """One robot's commands from the view; every method runs on the asyncio loop."""

    def __init__(
        self,
        robot: Commandable,
        joints: Callable[[], JointSample | None],
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.robot = robot
        self._joints = joints
        self._clock = clock
        """The clock of the samples' ``received`` (``time.monotonic``)."""
        self.enabled = False
        self.targets: list[float] | None = None
        """The joint stream's targets (the sliders' values) while enabled."""
        self.jogging = False
        self.refusal = ""
        """Why the last enable, stream or jog was refused or ended ("" when none was)."""
        self.sent = 0
        """Joint stream commands and twists sent."""
        self.on_change: Callable[[], None] | None = None
        """Called after enabled, targets or refusal changed (the panel shows them)."""
        self._holding = False
        self._pending: set[asyncio.Task[None]] = set()

    async def enable(self) -> bool:
        """Take the lease and sync the targets to the robot's joints; False (``refusal`` says why) when
        refused: then nothing was sent and the lease is not held."""
        if self.enabled:
            return True
        try:
            await self.robot.ensure_lease()
        except GoalRejected as err:  # LeaseHeld: someone else commands the robot
            return self._refused(err.reason)
        except UrDaemonError as err:
            return self._refused(f"lease: {err}")
        self._holding = True
        current = self._joints()
        if current is None or not all(math.isfinite(p) for p in current.positions):
            await self._release()
            return self._refused(f"no joint_states from {self.robot.name} yet: nothing to start from")
        age = self._clock() - current.received
        if age > STALE_S:  # the robot may be elsewhere by now: never stream towards an old pose
            await self._release()
            return self._refused(
                f"the newest joint_states from {self.robot.name} are {age:.1f} s old: nothing to start from"
            )
        self.targets = list(current.positions)
        self.enabled = True
        self.refusal = ""
        self._changed()
        return True

    async def disable(self, reason: str = "") -> None:
        """Stop sending and release the lease (the daemon stops the robot); ``reason`` is shown."""
        self.enabled = False
        self.targets = None
        if reason:
            self.refusal = reason
        self._changed()
        await self._release()

    async def _release(self) -> None:
        if self._holding:
            self._holding = False
            with contextlib.suppress(UrDaemonError):
                await self.robot.release()

    async def stop(self) -> None:
        """Stop the robot now (no lease needed) and disable."""
        self.enabled = False  # no stream command after the stop
        with contextlib.suppress(UrDaemonError):
            await self.robot.stop()
        await self.disable()

    def set_target(self, index: int, value: float) -> None:
        """A slider moved: the joint's new target (ignored unless enabled and not jogging)."""
        targets = self.targets
        usable = targets is not None and 0 <= index < len(targets) and math.isfinite(value)
        if self.enabled and not self.jogging and usable:
            assert targets is not None
            targets[index] = float(value)

    def tick(self) -> None:
        """One period of the stream loop: the targets as one joint position command, when enabled."""
        targets = self.targets
        if not self.enabled or self.jogging or targets is None:
            return
        try:
            self.robot.stream_positions(targets)
            self.sent += 1
        except UrDaemonError as err:  # the lease was lost or taken over
            self._disable_soon(str(err))

    def on_rejected(self, key: str, reason: str) -> None:
        """A ``command_rejected`` event: a refused stream command of ours disables."""
        if not self.enabled or reason.startswith("busy:"):  # a sample replaced by a newer one
            return
        if key.endswith(("command/joint_position", "command/twist")):
            self._disable_soon(f"refused: {reason}")

    async def jog(self, linear: Sequence[float], angular: Sequence[float], frame: str) -> bool:
        """Twist for ``JOG_S``, decelerate, then sync the targets to the robot; False when not enabled
        or already jogging (nothing sent)."""
        if not self.enabled or self.jogging:
            return False
        loop = asyncio.get_running_loop()
        self.jogging = True
        try:
            end = loop.time() + JOG_S
            while self._active() and loop.time() < end:
                self._twist(linear, angular, frame)
                await asyncio.sleep(STREAM_PERIOD_S)
            for _ in range(ZERO_SENDS):
                if not self._active():
                    break
                self._twist((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), frame)
                await asyncio.sleep(STREAM_PERIOD_S)
            await self._settle(frame)
        except UrDaemonError as err:
            self._disable_soon(str(err))
        finally:
            self.jogging = False
        return True

    def _active(self) -> bool:
        """Still enabled (a refusal or a disable may have come while a jog awaited)."""
        return self.enabled

    def _twist(self, linear: Sequence[float], angular: Sequence[float], frame: str) -> None:
        self.robot.twist(linear, angular, frame=frame)
        self.sent += 1

    async def _settle(self, frame: str) -> None:
        """Wait (bounded) until the robot rests, then make where it is the stream's targets."""
        for _ in range(SETTLE_TICKS):
            current = self._joints()
            if current is not None and all(abs(v) < SETTLE_SPEED for v in current.velocities):
                break
            if not self.enabled:
                return
            self._twist((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), frame)  # still decelerating: keep the stream
            await asyncio.sleep(STREAM_PERIOD_S)
        current = self._joints()
        if self.enabled and current is not None:
            self.targets = list(current.positions)
            self._changed()

    def _refused(self, reason: str) -> bool:
        self.refusal = reason
        self._changed()
        return False

    def _disable_soon(self, reason: str) -> None:
        self.enabled = False  # nothing more is sent from now
        task = asyncio.get_running_loop().create_task(self.disable(reason))
        self._pending.add(task)
        task.add_done_callback(self._pending.discard)

    def _changed(self) -> None:
        if self.on_change is not None:
            self.on_change()
