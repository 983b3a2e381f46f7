"""A robot's API for programs: ``RobotClient`` (its goals, services, streams and lease) and the
``GoalHandle`` of each goal it sends.

A ``RobotClient`` works through the client's session (client/session.py), its command lease
(client/command_lease.py: acquired before a command, its token attached) and its goals' messages
(client/goal_messages.py: each goal's signed feedback and result). Each body it sends is built from
the message's type next to its decoder in publish/ (``MoveGoalRequest`` and ``move_goal_body`` in
publish/move_goal.py, and so on), so one module knows each message's fields. Cartesian poses are
(x, y, z, rx, ry, rz): metres and a rotation vector (rad), of the TCP (the robot's current TCP
offset applied), in the robot's base frame (``frame="base"``, the frame of ``tcp_pose``) or the
cell's world frame (``frame="world"``, for a robot mounted on ``world``).
"""

from __future__ import annotations

import asyncio
import contextlib
import numbers
from collections.abc import AsyncIterator, Iterable, Sequence
from typing import Any

from urdaemon.client.command_lease import Lease, LeaseHeld
from urdaemon.client.goal_messages import (
    MAX_QUEUED_FEEDBACK,
    RESULT_POLL_S,
    GoalInbox,
    RobotGoals,
    accepted_result_key,
)
from urdaemon.client.session import QUERY_TIMEOUT_S, ClientSession, Subscription, encode_body
from urdaemon.errors import GoalRejected, UrDaemonError, UrTimeoutError
from urdaemon.model import (
    FORCE_MODE_DAMPING,
    FORCE_MODE_GAIN_SCALING,
    FORCE_MODE_TYPE,
    CycleStatsRequest,
    DashboardRequest,
    ForceModeRequest,
    SetIoRequest,
    SetPayloadRequest,
    SetTcpRequest,
    SpeedSliderRequest,
    ToolVoltageRequest,
)
from urdaemon.publish import service_requests, services
from urdaemon.publish.envelope import message_body
from urdaemon.publish.goal_cancel import cancel_body
from urdaemon.publish.keys import RobotKeys
from urdaemon.publish.linear_goal import LinearGoalRequest, linear_goal_body
from urdaemon.publish.move_goal import MoveGoalRequest, move_goal_body
from urdaemon.publish.stream_commands import StreamMessage, TwistMessage, freedrive_body
from urdaemon.publish.trajectory_goal import TrajectoryGoalRequest, trajectory_goal_body

__all__ = ["GoalHandle", "RobotClient"]


class GoalHandle:
    """An accepted goal: its feedback and its one result."""

    MAX_QUEUED_FEEDBACK = MAX_QUEUED_FEEDBACK
    """Feedback kept for a reader that falls behind; older messages are dropped first."""

    def __init__(self, robot: RobotClient, inbox: GoalInbox, duration: float) -> None:
        self.robot = robot
        self.goal_id = inbox.goal_id
        self.duration = duration
        self.result_key = inbox.result_key
        """The key the accepting reply gave: only messages signed with it are taken (None: a daemon
        that signs nothing, whose messages are taken as they come)."""
        self._inbox = inbox

    @property
    def forged(self) -> int:
        """Messages on this goal's keys (or replies to its result query) that were not signed with
        its key for the key they came on, or are no message of this goal: ignored."""
        return self._inbox.forged

    async def feedback(self) -> AsyncIterator[dict[str, Any]]:
        """Feedback messages until the goal has ended; raises what ``result()`` would if it ended unknown."""
        while not self._inbox.result.done():
            getter = asyncio.ensure_future(self._inbox.feedback.get())
            done, _ = await asyncio.wait(
                {getter, self._inbox.result}, timeout=RESULT_POLL_S, return_when=asyncio.FIRST_COMPLETED
            )
            if getter in done:
                yield getter.result()
                continue
            getter.cancel()
            if not done:  # nothing for a while: the result may have been published while we missed it
                await self._inbox.poll_result()
        while not self._inbox.feedback.empty():
            yield self._inbox.feedback.get_nowait()
        error = self._inbox.result.exception()
        if error is not None:  # the goal's end is unknown (e.g. the daemon died): say so, do not just stop
            raise error

    async def result(self, timeout: float | None = None) -> dict[str, Any]:
        """Wait for the result (asking the daemon too, in case a publication was missed).

        Raises ``ConnectionLostError`` when the daemon stops serving the robot before the goal ended,
        ``UrTimeoutError`` after ``timeout`` seconds.
        """
        loop = asyncio.get_running_loop()
        deadline = None if timeout is None else loop.time() + timeout
        while not self._inbox.result.done():
            wait = RESULT_POLL_S if deadline is None else min(RESULT_POLL_S, deadline - loop.time())
            if wait <= 0:
                raise UrTimeoutError(f"goal {self.goal_id}: no result within {timeout} s")
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(asyncio.shield(self._inbox.result), wait)
            if not self._inbox.result.done():
                await self._inbox.poll_result()
        return self._inbox.result.result()


class RobotClient:
    """Commands and state of one robot."""

    def __init__(self, client: ClientSession, keys: RobotKeys, lease: Lease) -> None:
        self.client = client
        self.keys = keys
        self.lease = lease
        """This client's command lease on the robot (one per robot, whichever handle asks)."""
        self._goals = RobotGoals(client, keys)

    @property
    def name(self) -> str:
        """The robot's name."""
        return self.keys.robot

    async def ensure_lease(self) -> str:
        """Acquire the robot's command lease unless this client holds it; its token ("" when the
        daemon checks none). Raises ``LeaseHeld`` naming the holder when another client holds it.

        Goals and commanding services acquire by themselves, except after the lease was
        taken from this client (they raise ``LeaseHeld`` saying so): this acquires it again. Call it
        once before streaming.
        """
        await self.lease.acquire(again=True)
        return self.lease.token or ""

    async def release(self) -> None:
        """Give the lease back (the daemon stops whatever still moves the robot)."""
        reply = await self.lease.release()
        if reply is not None and reply.get("ok") is not True:
            raise UrDaemonError(str(reply.get("reason") or f"lease: release refused ({reply})"))

    async def take_over(self, reason: str) -> dict[str, Any]:
        """Take the lease from whoever holds it (the daemon stops the robot first, logs ``reason`` and
        publishes it as a lease event); the daemon's grant (``lease``: now this client's)."""
        if not reason.strip():
            raise UrDaemonError("taking over a lease needs a reason (it is logged and published)")
        return await self.lease.acquire(force=True, reason=reason)

    async def lease_info(self) -> dict[str, Any] | None:
        """Who holds the lease as the daemon shows it (``holder``, ``fingerprint``: sha256 of the
        holder's secret session id, cut to 16 hex characters, ``since`` as unix time), None when free.
        This client's own lease shows ``lease.fingerprint``."""
        return await self.lease.show()

    async def _command(self, key: str, body: dict[str, Any], answer: str, timeout: float) -> dict[str, Any]:
        """Send a commanding query with the lease's token (acquired first); raises ``LeaseHeld``
        when the daemon refuses it for the lease."""
        lease = self.lease
        await lease.acquire()
        reply = await self.client.request(key, body, timeout=timeout, attachment=lease.attachment())
        refusal = _lease_refusal(reply, answer)
        if refusal is not None:
            await lease.confirm_end(refusal)
            raise LeaseHeld(refusal)
        return reply

    def _stream_attachment(self) -> bytes | None:
        lease = self.lease
        known = lease.ended_reason or lease.refusal  # why it is not this client's, as last heard
        if not lease.usable and known is not None:
            raise LeaseHeld(known)
        if not lease.usable:
            raise UrDaemonError(
                f"robot {self.name!r}: stream commands need this client's command lease; "
                "call `await robot.ensure_lease()` before the first (a stream command never waits)"
            )
        return lease.attachment()

    def joint_states(self, maxsize: int = 1000) -> Subscription:
        """Subscribe to joint states."""
        return self.client.subscribe(self.keys.joint_states, maxsize)

    async def status(self, timeout: float = 5.0) -> dict[str, Any]:
        """The next status message."""
        sub = self.client.subscribe(self.keys.status, 10)
        try:
            return await sub.get_json(timeout)
        finally:
            self.client.unsubscribe(sub)

    async def send_trajectory(
        self,
        points: Sequence[dict[str, Any]],
        *,
        joint_names: Sequence[str] | None = None,
        tolerances: dict[str, Any] | None = None,
        preempt: bool = False,
        passthrough: bool = False,
    ) -> GoalHandle:
        """Send a trajectory goal; raises ``GoalRejected`` with the daemon's reason.

        ``passthrough``: the robot interpolates the points itself (UR controllers).
        """
        goal = TrajectoryGoalRequest(
            points=tuple(points),
            preempt=preempt,
            passthrough=passthrough,
            joint_names=None if joint_names is None else tuple(joint_names),
            tolerances=tolerances,
        )
        return await self._send_goal(self.keys.goal_trajectory, trajectory_goal_body(goal))

    async def move(
        self,
        positions: Sequence[float],
        *,
        duration: float | None = None,
        joint_names: Sequence[str] | None = None,
        velocity_scale: float = 1.0,
        acceleration_scale: float = 1.0,
        preempt: bool = False,
    ) -> GoalHandle:
        """Send a point-to-point move goal; raises ``GoalRejected`` with the daemon's reason."""
        goal = MoveGoalRequest(
            positions=tuple(positions),
            velocity_scale=velocity_scale,
            acceleration_scale=acceleration_scale,
            preempt=preempt,
            duration=duration,
            joint_names=None if joint_names is None else tuple(joint_names),
        )
        return await self._send_goal(self.keys.goal_move, move_goal_body(goal))

    async def move_pose(
        self,
        pose: Sequence[float],
        *,
        frame: str = "base",
        configuration: dict[str, str] | None = None,
        duration: float | None = None,
        velocity_scale: float = 1.0,
        acceleration_scale: float = 1.0,
        tolerances: dict[str, Any] | None = None,
        preempt: bool = False,
    ) -> GoalHandle:
        """Move the TCP to ``pose`` with the jerk-limited joint motion of ``move``: the daemon picks
        the inverse kinematics solution nearest the joints the goal starts from, matching
        ``configuration`` (UR models: any of ``shoulder`` "left"/"right", ``elbow`` "up"/"down",
        ``wrist`` "up"/"down"). Raises ``GoalRejected`` with the daemon's reason (out of reach, no
        solution in that configuration, a joint limit...)."""
        goal = MoveGoalRequest(
            pose=tuple(pose),
            frame=frame,
            velocity_scale=velocity_scale,
            acceleration_scale=acceleration_scale,
            preempt=preempt,
            configuration=configuration,
            duration=duration,
            tolerances=tolerances,
        )
        return await self._send_goal(self.keys.goal_move, move_goal_body(goal))

    async def move_linear(
        self,
        poses: Sequence[float] | Sequence[Sequence[float]],
        *,
        frame: str = "base",
        blend_radii: Sequence[float] | None = None,
        speed: float | None = None,
        acceleration: float | None = None,
        jerk: float | None = None,
        angular_speed: float | None = None,
        angular_acceleration: float | None = None,
        angular_jerk: float | None = None,
    ) -> GoalHandle:
        """Move the TCP on straight lines from where it is through ``poses`` (one pose, or a list),
        from rest; ``blend_radii`` (m, one per pose but the last) round the corners. Limits in m/s,
        m/s², m/s³ and rad/s, rad/s², rad/s³ (left out: the cell's defaults; at most its caps). The
        daemon checks the whole path before motion: ``GoalRejected`` says what and where (a pose out
        of reach, a singularity, a joint limit at some % of a segment)."""
        goal = LinearGoalRequest(
            poses=_pose_list(poses),
            frame=frame,
            blend_radii=None if blend_radii is None else tuple(blend_radii),
            speed=speed,
            acceleration=acceleration,
            jerk=jerk,
            angular_speed=angular_speed,
            angular_acceleration=angular_acceleration,
            angular_jerk=angular_jerk,
        )
        return await self._send_goal(self.keys.goal_linear, linear_goal_body(goal))

    def twist(self, linear: Sequence[float], angular: Sequence[float], *, frame: str = "base") -> None:
        """Publish one twist command: the TCP point's velocity (m/s) and the angular velocity (rad/s),
        in the base frame or the TCP's own (``frame="tool"``). Repeat it faster than the robot's stream
        timeout, as with joint streams: when twists stop coming the robot stops; a zero twist
        decelerates it. Needs the lease held, as ``stream_positions``; the daemon's refusals (over its
        speed caps, no kinematics) are ``command_rejected`` events on the robot's events."""
        body = message_body(TwistMessage(_three(linear), _three(angular), frame))
        attachment = self._stream_attachment()
        self.client.session.put(self.keys.command_twist, encode_body(body), attachment=attachment)

    async def set_tcp(self, pose: Sequence[float], *, timeout: float = QUERY_TIMEOUT_S) -> None:
        """Set the TCP offset (x, y, z, rx, ry, rz of the TCP in the flange frame): applied to
        ``tcp_pose``, every later Cartesian command and, on a UR robot, the controller's TCP.
        Raises ``GoalRejected`` with the daemon's reason (the robot moves, a value out of range),
        ``LeaseHeld`` when another client holds the lease."""
        reply = await self.service("set_tcp", SetTcpRequest(_six(pose)), timeout=timeout)
        if reply.get("ok") is not True:
            raise GoalRejected(str(reply.get("reason") or f"set_tcp: refused ({reply})"))

    async def call(
        self, service: str, body: dict[str, Any] | None = None, *, timeout: float = 60.0
    ) -> dict[str, Any]:
        """Call service ``service``; the reply (``ok``, and a ``reason`` when not: an unknown service's
        reason lists the robot's services).

        Raises ``NoSuchService`` when nothing answers at all (no daemon serves this robot's cell),
        ``LeaseHeld`` when the service commands the robot and another client holds its lease.
        """
        if _commanding(service):
            return await self._command(self.keys.service(service), body or {}, "ok", timeout)
        return await self.client.request(self.keys.service(service), body or {}, timeout=timeout)

    async def service(
        self, name: str, request: object | None = None, *, timeout: float | None = None
    ) -> dict[str, Any]:
        """Call service ``name`` of the table (publish/services.py) with its request (a request type of
        model.py; None for a service without arguments), waiting the table's time unless ``timeout``."""
        entry = services.spec(name)
        wait = entry.timeout if timeout is None else timeout
        body = service_requests.request_body(request)
        if _commanding(name):
            return await self._command(self.keys.service(name), body, "ok", wait)
        return await self.client.request(self.keys.service(name), body, timeout=wait)

    async def cancel(self, goal_id: str | None = None) -> dict[str, Any]:
        """Cancel a goal (default: the active one), whoever sent it: a cancel only stops the robot, so,
        like ``stop``, it needs no lease and acquires none (the lease's token goes along if held)."""
        return await self.client.request(
            self.keys.goal_cancel, cancel_body(goal_id), attachment=self.lease.attachment()
        )

    async def set_io(self, kind: str, pin: int, value: bool | float) -> dict[str, Any]:
        """Set an output; the reply says ok or the reason."""
        return await self.service("set_io", SetIoRequest(kind, pin, value))

    async def set_payload(self, mass: float, cog: Sequence[float] = (0.0, 0.0, 0.0)) -> dict[str, Any]:
        """Set the payload."""
        return await self.service("set_payload", SetPayloadRequest(mass, _three(cog)))

    async def set_speed_slider(self, fraction: float) -> dict[str, Any]:
        """Set the speed slider (0..1)."""
        return await self.service("set_speed_slider", SpeedSliderRequest(fraction))

    async def dashboard(self, command: str, *, timeout: float | None = None) -> dict[str, Any]:
        """Send a dashboard command line (``power on``, ``robotmode`` …); the reply or the reason."""
        return await self.service("dashboard", DashboardRequest(command), timeout=timeout)

    async def startup(self, *, timeout: float | None = None) -> dict[str, Any]:
        """Power on, release the brakes and start the control program."""
        return await self.service("startup", timeout=timeout)

    async def resend_program(self) -> dict[str, Any]:
        """Send the control program again (headless) or play it (URCap)."""
        return await self.service("resend_program")

    async def hand_back_control(self) -> dict[str, Any]:
        """End the control program so the pendant program continues."""
        return await self.service("hand_back_control")

    async def cycle_stats(self, *, reset: bool = False) -> dict[str, Any]:
        """Cycle counters and the turnaround (state in → command out, µs: count, p50, p99, p99.9,
        max) since the last reset; ``reset`` starts a new measuring window after this reply."""
        return await self.service("cycle_stats", CycleStatsRequest(reset))

    async def doctor(self, *, timeout: float | None = None) -> dict[str, Any]:
        """The doctor's checks of this robot and its host: each with a verdict (``ok``, ``warn``,
        ``fail``, ``unknown``, ``n/a``), what was measured and what to do (docs/doctor.md)."""
        return await self.service("doctor", timeout=timeout)

    async def zero_ft_sensor(self) -> dict[str, Any]:
        """Zero the force/torque sensor."""
        return await self.service("zero_ft_sensor")

    async def set_tool_voltage(self, volts: int) -> dict[str, Any]:
        """Set the tool voltage (0, 12 or 24 V)."""
        return await self.service("set_tool_voltage", ToolVoltageRequest(volts))

    async def stop(self) -> dict[str, Any]:
        """Stop whatever moves the robot (anyone may: no lease needed, none acquired)."""
        return await self.service("stop")

    def stream_positions(self, positions: Sequence[float], velocities: Sequence[float] | None = None) -> None:
        """Publish one streaming position command (repeat faster than the deadman timeout).

        Needs the lease held (``await ensure_lease()`` first): otherwise raises ``LeaseHeld`` with the
        reason this client last heard (who holds it, who took it over), or ``UrDaemonError`` saying to
        acquire it. A command the daemon refuses is reported as a ``command_rejected`` event on the
        robot's events.
        """
        velocities = None if velocities is None else tuple(velocities)
        body = message_body(StreamMessage(None, tuple(positions), velocities))
        attachment = self._stream_attachment()
        self.client.session.put(self.keys.command_joint_position, encode_body(body), attachment=attachment)

    def freedrive(self, active: bool = True) -> None:
        """Keep freedrive (hand guiding) on for one deadman period, or end it; repeat while it should
        last. Needs the lease held, as ``stream_positions``."""
        attachment = self._stream_attachment()
        body = encode_body(freedrive_body(active))
        self.client.session.put(self.keys.command_freedrive, body, attachment=attachment)

    async def start_force_mode(
        self,
        task_frame: Sequence[float],
        selection: Sequence[int],
        wrench: Sequence[float],
        limits: Sequence[float],
        *,
        force_type: int = FORCE_MODE_TYPE,
        damping: float = FORCE_MODE_DAMPING,
        gain_scaling: float = FORCE_MODE_GAIN_SCALING,
    ) -> dict[str, Any]:
        """Start force mode (URScript ``force_mode`` semantics)."""
        request = ForceModeRequest(
            tuple(task_frame),
            tuple(selection),
            tuple(wrench),
            tuple(limits),
            force_type,
            damping,
            gain_scaling,
        )
        return await self.service("start_force_mode", request)

    async def end_force_mode(self) -> dict[str, Any]:
        """End force mode."""
        return await self.service("end_force_mode")

    async def start_tool_contact(self) -> dict[str, Any]:
        """Arm tool-contact detection; the outcome comes as a ``tool_contact`` event."""
        return await self.service("start_tool_contact")

    async def end_tool_contact(self) -> dict[str, Any]:
        """End tool-contact detection."""
        return await self.service("end_tool_contact")

    def stream_velocities(self, velocities: Sequence[float]) -> None:
        """Publish one streaming velocity command (repeat faster than the deadman timeout). Needs
        the lease held, as ``stream_positions``."""
        attachment = self._stream_attachment()
        body = encode_body(message_body(StreamMessage(None, None, tuple(velocities))))
        self.client.session.put(self.keys.command_joint_velocity, body, attachment=attachment)

    async def _send_goal(self, key: str, body: dict[str, Any]) -> GoalHandle:
        self._goals.follow()
        reply = await self._command(key, body, "accepted", QUERY_TIMEOUT_S)
        if not reply.get("accepted"):
            raise GoalRejected(str(reply.get("reason", "rejected without a reason")))
        goal_id, duration = str(reply["goal_id"]), float(reply.get("duration", 0.0))
        result_key = accepted_result_key(reply, self.name, unsigned=self.lease.unchecked)
        return GoalHandle(self, self._goals.add(goal_id, result_key), duration)


def _six(values: Sequence[float]) -> tuple[float, float, float, float, float, float]:
    """A pose as sent: the daemon refuses one that is not six numbers, naming it."""
    return tuple(values)  # type: ignore[return-value]


def _three(values: Sequence[float]) -> tuple[float, float, float]:
    """A centre of gravity as sent: the daemon refuses one that is not three numbers, naming it."""
    return tuple(values)  # type: ignore[return-value]


def _lease_refusal(reply: dict[str, Any], answer: str) -> str | None:
    """The daemon's reason when ``reply`` refuses a command for the lease (None otherwise)."""
    reason = reply.get("reason")
    if reply.get(answer) is False and isinstance(reason, str) and reason.startswith("lease: "):
        return reason
    return None


def _commanding(service: str) -> bool:
    """Whether a service needs the lease (unknown names: no, the daemon names what it serves)."""
    try:
        entry = services.spec(service)
    except KeyError:
        return False
    return entry.commanding


def _pose_list(poses: Sequence[float] | Sequence[Sequence[float]]) -> tuple[Any, ...]:
    """``poses`` as poses: one pose (six numbers) becomes a list of one."""
    items = list(poses)
    if items and all(isinstance(v, numbers.Real) for v in items):
        return (items,)
    return tuple(list(p) if isinstance(p, Iterable) and not isinstance(p, str) else p for p in items)
