"""The asyncio Python API for programs that talk to a running urdaemon over Zenoh.

::

    async with await Client.connect("tcp/127.0.0.1:7447") as client:
        alice = await client.robot("alice")
        goal = await alice.move([0, -1.57, 1.57, -1.57, -1.57, 0], duration=3.0)
        async for feedback in goal.feedback():
            print(feedback["progress"])
        result = await goal.result()
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import re
from collections.abc import AsyncIterator, Callable, Sequence
from typing import Any

import zenoh

from urdaemon.cell import config as cell_config
from urdaemon.errors import ConnectionLostError, GoalRejected, UrDaemonError, UrTimeoutError
from urdaemon.model import (
    FORCE_MODE_DAMPING,
    FORCE_MODE_GAIN_SCALING,
    FORCE_MODE_TYPE,
    CycleStatsRequest,
    DashboardRequest,
    ForceModeRequest,
    SetIoRequest,
    SetPayloadRequest,
    SpeedSliderRequest,
    ToolVoltageRequest,
)
from urdaemon.publish import codec, services
from urdaemon.publish.codec import SCHEMA_VERSION
from urdaemon.publish.keys import CellKeys, RobotKeys
from urdaemon.publish.node import zenoh_config

__all__ = [
    "DEFAULT_ENDPOINT",
    "Client",
    "GoalHandle",
    "NoSuchRobot",
    "NoSuchService",
    "RobotClient",
    "Subscription",
    "zenoh_message",
]

DEFAULT_ENDPOINT = cell_config.DEFAULT_ENDPOINT
QUERY_TIMEOUT_S = services.CLIENT_TIMEOUT_S
"""How long a query waits for its answer unless told (a service's own wait is in its table entry)."""
RESULT_POLL_S = 0.5
"""While waiting for a result, ask the daemon for it this often (covers a missed publication)."""
LOST_GRACE_S = 1.0
"""When a robot's liveliness token disappears, how long a waiting goal still listens and asks for its
result before it fails (the token's deletion can overtake the result's publication)."""
PEER_WAIT_S = 0.05

_RUST_LOCATION = re.compile(r"\s+at\s+\S+\.rs:\d+(:\d+)?\.?")


def zenoh_message(err: BaseException) -> str:
    """A Zenoh error's text without the Rust source location it carries (``at /root/.cargo/...rs:1``)."""
    return _RUST_LOCATION.sub("", str(err)).strip()


class NoSuchRobot(UrDaemonError):
    """No daemon reachable from this client serves a robot of that name; ``robots`` lists what is served."""

    def __init__(self, message: str, robots: Sequence[tuple[str, str]] = ()) -> None:
        super().__init__(message)
        self.robots = list(robots)


class NoSuchService(UrDaemonError):
    """Nothing answers the key: the daemon serves no such service (or goal key) for that robot."""


def _encode(body: dict[str, Any]) -> bytes:
    return json.dumps({"v": SCHEMA_VERSION, **body}, separators=(",", ":")).encode()


class Subscription:
    """Samples of a key expression, delivered to the loop; iterate with ``async for``."""

    def __init__(
        self, session: Any, key_expr: str, loop: asyncio.AbstractEventLoop, maxsize: int = 1000
    ) -> None:
        self.key_expr = key_expr
        self._queue: asyncio.Queue[tuple[str, bytes]] = asyncio.Queue(maxsize)
        self._loop = loop
        self.dropped = 0
        self._sub = session.declare_subscriber(key_expr, self._on_sample)

    def _on_sample(self, sample: Any) -> None:
        item = (str(sample.key_expr), sample.payload.to_bytes())
        with contextlib.suppress(RuntimeError):
            self._loop.call_soon_threadsafe(self._put, item)

    def _put(self, item: tuple[str, bytes]) -> None:
        try:
            self._queue.put_nowait(item)
        except asyncio.QueueFull:
            self.dropped += 1

    async def get(self, timeout: float | None = None) -> tuple[str, bytes]:
        """The next (key, payload); raises ``UrTimeoutError`` after ``timeout`` seconds."""
        try:
            return await asyncio.wait_for(self._queue.get(), timeout)
        except TimeoutError as err:
            raise UrTimeoutError(f"no sample on {self.key_expr} within {timeout} s") from err

    async def get_json(self, timeout: float | None = None) -> dict[str, Any]:
        """The next sample decoded as JSON."""
        _, payload = await self.get(timeout)
        data: dict[str, Any] = json.loads(payload)
        return data

    def __aiter__(self) -> AsyncIterator[tuple[str, bytes]]:
        return self._iterate()

    async def _iterate(self) -> AsyncIterator[tuple[str, bytes]]:
        while True:
            yield await self._queue.get()

    def close(self) -> None:
        """Stop receiving."""
        with contextlib.suppress(Exception):
            self._sub.undeclare()


class Client:
    """A Zenoh session connected to a urdaemon cell."""

    def __init__(
        self, session: Any, loop: asyncio.AbstractEventLoop, endpoint: str = DEFAULT_ENDPOINT
    ) -> None:
        self.session = session
        self.endpoint = endpoint
        """Where this client connected (named in error messages)."""
        self._loop = loop
        self._subscriptions: list[Subscription] = []
        self._tasks: list[asyncio.Task[None]] = []
        self._closers: list[Callable[[], object]] = []

    @classmethod
    async def connect(
        cls, endpoint: str = DEFAULT_ENDPOINT, *, timeout: float = 5.0, low_latency: bool = False
    ) -> Client:
        """Open a Zenoh session connected to ``endpoint`` (no multicast scouting); ``low_latency``
        to match a daemon whose cell sets ``zenoh: {low_latency: true}`` (half the CPU per sample
        for both; without it the client still works).

        Raises ``UrDaemonError`` naming ``endpoint`` when nothing answers there within ``timeout`` s.
        """
        loop = asyncio.get_running_loop()
        try:
            conf = zenoh_config("peer", [], [endpoint], low_latency=low_latency)
            conf.insert_json5("connect/timeout_ms", json.dumps(int(timeout * 1000)))
            session = await loop.run_in_executor(None, zenoh.open, conf)
        except zenoh.ZError as err:
            raise UrDaemonError(f"cannot connect to {endpoint}: {zenoh_message(err)}") from err
        deadline = loop.time() + timeout
        while not _has_peer(session):  # a peer session opens even when nobody listens there
            if loop.time() >= deadline:
                await loop.run_in_executor(None, session.close)
                raise UrDaemonError(
                    f"cannot connect to {endpoint}: nothing answered within {timeout:g} s "
                    "(is the daemon running and listening there?)"
                )
            await asyncio.sleep(PEER_WAIT_S)
        return cls(session, loop, endpoint)

    async def __aenter__(self) -> Client:
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    async def close(self) -> None:
        """Stop background tasks, undeclare subscriptions and close the session."""
        for task in self._tasks:
            task.cancel()
        for task in self._tasks:
            with contextlib.suppress(asyncio.CancelledError):
                await task
        for closer in self._closers:
            with contextlib.suppress(Exception):
                closer()
        for sub in self._subscriptions:
            sub.close()
        await self._loop.run_in_executor(None, self.session.close)

    def unsubscribe(self, sub: Subscription) -> None:
        """Close ``sub`` and forget it."""
        sub.close()
        with contextlib.suppress(ValueError):
            self._subscriptions.remove(sub)

    def subscribe(self, key_expr: str, maxsize: int = 1000) -> Subscription:
        """Subscribe to ``key_expr`` (closed with the client)."""
        try:
            sub = Subscription(self.session, key_expr, self._loop, maxsize)
        except zenoh.ZError as err:
            raise UrDaemonError(f"cannot subscribe to {key_expr!r}: {zenoh_message(err)}") from err
        self._subscriptions.append(sub)
        return sub

    async def query(
        self, key: str, body: dict[str, Any] | None = None, *, timeout: float = QUERY_TIMEOUT_S
    ) -> list[bytes]:
        """Ask a queryable; every reply's payload."""
        payload = None if body is None else _encode(body)

        def ask() -> list[bytes]:
            replies = self.session.get(key, payload=payload, timeout=timeout)
            return [r.ok.payload.to_bytes() for r in replies if r.ok is not None]

        try:
            return await self._loop.run_in_executor(None, ask)
        except zenoh.ZError as err:
            raise UrDaemonError(f"cannot ask {key!r} at {self.endpoint}: {zenoh_message(err)}") from err

    async def request(
        self, key: str, body: dict[str, Any] | None = None, *, timeout: float = QUERY_TIMEOUT_S
    ) -> dict[str, Any]:
        """Ask a queryable that must answer once.

        Raises ``NoSuchService`` when the query ends at once without a reply (nobody serves ``key``),
        ``UrTimeoutError`` when nobody answers within ``timeout`` s.
        """
        start = self._loop.time()
        replies = await self.query(key, body, timeout=timeout)
        if not replies:
            if self._loop.time() - start < min(0.5 * timeout, 1.0):
                raise NoSuchService(f"nothing at {self.endpoint} serves {key}")
            raise UrTimeoutError(f"no answer on {key} from {self.endpoint} within {timeout:g} s")
        try:
            data = json.loads(replies[0])
        except ValueError as err:
            raise UrDaemonError(f"the answer on {key} is not JSON: {err}") from err
        if not isinstance(data, dict):
            raise UrDaemonError(f"the answer on {key} is not a JSON object")
        return data

    async def robots(self, *, timeout: float = 2.0) -> list[tuple[str, str]]:
        """(cell, robot) of every robot served, from their liveliness tokens."""

        def ask() -> list[str]:
            return [
                str(r.ok.key_expr)
                for r in self.session.liveliness().get("*/*/alive", timeout=timeout)
                if r.ok
            ]

        try:
            keys = await self._loop.run_in_executor(None, ask)
        except zenoh.ZError as err:
            raise UrDaemonError(f"cannot list robots at {self.endpoint}: {zenoh_message(err)}") from err
        found = []
        for key in keys:
            parts = key.split("/")
            if len(parts) == 3:
                found.append((parts[0], parts[1]))
        return sorted(found)

    async def robot(self, name: str, *, cell: str | None = None, timeout: float = 5.0) -> RobotClient:
        """A handle on robot ``name``; finds its cell from the liveliness tokens unless given.

        Raises ``NoSuchRobot`` (listing the robots served) when robots are served but none is
        ``name`` (in ``cell``); waits up to ``timeout`` s only while no robot at all is served (a
        daemon starting up).
        """
        deadline = self._loop.time() + timeout
        misses = 0
        while True:
            served = await self.robots()
            cells = sorted({c for c, r in served if r == name and cell in (None, c)})
            if len(cells) == 1:
                return RobotClient(self, RobotKeys(cells[0], name))
            if len(cells) > 1:
                raise UrDaemonError(
                    f"robot {name!r} is served in several cells ({', '.join(cells)}); name one"
                )
            if served:
                misses += 1  # tokens of one daemon arrive together; allow one late arrival
                if misses >= 3:
                    raise NoSuchRobot(_no_such_robot(name, cell, served, self.endpoint), served)
            if self._loop.time() > deadline:
                if served:
                    raise NoSuchRobot(_no_such_robot(name, cell, served, self.endpoint), served)
                raise UrTimeoutError(
                    f"no robot is served at {self.endpoint} (waited {timeout:g} s for {name!r})"
                )
            await asyncio.sleep(0.1)

    async def stop_cell(self, cell: str | None = None, *, timeout: float = QUERY_TIMEOUT_S) -> dict[str, Any]:
        """Stop every robot of ``cell`` at once (default: the one cell served); the reply names each
        robot's outcome (``{"ok": true, "robots": {"alice": {"ok": true}, ...}}``)."""
        if cell is None:
            cells = sorted({c for c, _ in await self.robots()})
            if len(cells) != 1:
                raise UrDaemonError(
                    f"{'no cell is' if not cells else 'several cells are'} served at {self.endpoint}"
                    + (f" ({', '.join(cells)}); name one" if cells else "")
                )
            cell = cells[0]
        return await self.request(CellKeys(cell).stop, timeout=timeout)

    async def robot_description(self, cell: str, *, timeout: float = QUERY_TIMEOUT_S) -> str:
        """The cell URDF."""
        replies = await self.query(CellKeys(cell).robot_description, timeout=timeout)
        if not replies:
            raise UrTimeoutError(f"no robot_description from cell {cell!r} at {self.endpoint}")
        return replies[0].decode()


def _has_peer(session: Any) -> bool:
    info = session.info
    return bool(list(info.peers_zid()) or list(info.routers_zid()))


def _no_such_robot(name: str, cell: str | None, served: Sequence[tuple[str, str]], endpoint: str) -> str:
    where = f"{cell}/{name}" if cell is not None else repr(name)
    listed = ", ".join(f"{c}/{r}" for c, r in served)
    return f"no robot {where} at {endpoint}; served: {listed}"


class GoalHandle:
    """An accepted goal: its feedback and its one result."""

    MAX_QUEUED_FEEDBACK = 1000
    """Feedback kept for a reader that falls behind; older messages are dropped first."""

    def __init__(self, robot: RobotClient, goal_id: str, duration: float) -> None:
        self.robot = robot
        self.goal_id = goal_id
        self.duration = duration
        self._feedback: asyncio.Queue[dict[str, Any]] = asyncio.Queue(self.MAX_QUEUED_FEEDBACK)
        self._result: asyncio.Future[dict[str, Any]] = asyncio.get_running_loop().create_future()

    def _deliver(self, kind: str, data: dict[str, Any]) -> None:
        if kind == "result":
            if not self._result.done():
                self._result.set_result(data)
        else:
            if self._feedback.full():
                self._feedback.get_nowait()
            self._feedback.put_nowait(data)

    def _fail(self, error: Exception) -> None:
        if not self._result.done():
            self._result.set_exception(error)

    async def feedback(self) -> AsyncIterator[dict[str, Any]]:
        """Feedback messages until the goal has ended; raises what ``result()`` would if it ended unknown."""
        while not self._result.done():
            getter = asyncio.ensure_future(self._feedback.get())
            done, _ = await asyncio.wait(
                {getter, self._result}, timeout=RESULT_POLL_S, return_when=asyncio.FIRST_COMPLETED
            )
            if getter in done:
                yield getter.result()
                continue
            getter.cancel()
            if not done:  # nothing for a while: the result may have been published while we missed it
                await self._poll_result()
        while not self._feedback.empty():
            yield self._feedback.get_nowait()
        error = self._result.exception()
        if error is not None:  # the goal's end is unknown (e.g. the daemon died): say so, do not just stop
            raise error

    async def result(self, timeout: float | None = None) -> dict[str, Any]:
        """Wait for the result (asking the daemon too, in case a publication was missed).

        Raises ``ConnectionLostError`` when the daemon stops serving the robot before the goal ended,
        ``UrTimeoutError`` after ``timeout`` seconds.
        """
        loop = asyncio.get_running_loop()
        deadline = None if timeout is None else loop.time() + timeout
        while not self._result.done():
            wait = RESULT_POLL_S if deadline is None else min(RESULT_POLL_S, deadline - loop.time())
            if wait <= 0:
                raise UrTimeoutError(f"goal {self.goal_id}: no result within {timeout} s")
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(asyncio.shield(self._result), wait)
            if not self._result.done():
                await self._poll_result()
        return self._result.result()

    async def _poll_result(self, timeout: float = 1.0) -> None:
        try:
            replies = await self.robot.client.query(
                self.robot.keys.goal_result(self.goal_id), timeout=timeout
            )
        except UrDaemonError:
            return
        for payload in replies:
            data = _result_message(payload, self.goal_id)
            if data is not None:
                self._deliver("result", data)
                self.robot._forget(self.goal_id)
                return


def _three(values: Sequence[float]) -> tuple[float, float, float]:
    """A centre of gravity as sent: the daemon refuses one that is not three numbers, naming it."""
    return tuple(values)  # type: ignore[return-value]


def _result_message(payload: bytes, goal_id: str) -> dict[str, Any] | None:
    """``payload`` decoded if it is a message of goal ``goal_id``, else None (garbage is ignored)."""
    try:
        data = json.loads(payload)
    except ValueError:
        return None
    if isinstance(data, dict) and data.get("goal_id") == goal_id:
        return data
    return None


class RobotClient:
    """Commands and state of one robot."""

    def __init__(self, client: Client, keys: RobotKeys) -> None:
        self.client = client
        self.keys = keys
        self._goals: dict[str, GoalHandle] = {}
        self._early: dict[str, list[tuple[str, dict[str, Any]]]] = {}
        self._goal_sub: Subscription | None = None
        self._pump: asyncio.Task[None] | None = None
        self._alive_sub: Any = None
        self._lost: asyncio.Task[None] | None = None

    @property
    def name(self) -> str:
        """The robot's name."""
        return self.keys.robot

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
        body: dict[str, Any] = {"points": list(points), "preempt": preempt}
        if passthrough:
            body["passthrough"] = True
        if joint_names is not None:
            body["joint_names"] = list(joint_names)
        if tolerances is not None:
            body["tolerances"] = tolerances
        return await self._send_goal(self.keys.goal_trajectory, body)

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
        body: dict[str, Any] = {
            "positions": list(positions),
            "velocity_scale": velocity_scale,
            "acceleration_scale": acceleration_scale,
            "preempt": preempt,
        }
        if duration is not None:
            body["duration"] = duration
        if joint_names is not None:
            body["joint_names"] = list(joint_names)
        return await self._send_goal(self.keys.goal_move, body)

    async def call(
        self, service: str, body: dict[str, Any] | None = None, *, timeout: float = 60.0
    ) -> dict[str, Any]:
        """Call service ``service``; the reply (``ok``, and a ``reason`` when not: an unknown service's
        reason lists the robot's services).

        Raises ``NoSuchService`` when nothing answers at all (no daemon serves this robot's cell).
        """
        return await self.client.request(self.keys.service(service), body or {}, timeout=timeout)

    async def service(
        self, name: str, request: object | None = None, *, timeout: float | None = None
    ) -> dict[str, Any]:
        """Call service ``name`` of the table (publish/services.py) with its request (a request type of
        model.py; None for a service without arguments), waiting the table's time unless ``timeout``."""
        entry = services.spec(name)
        wait = entry.timeout if timeout is None else timeout
        return await self.client.request(self.keys.service(name), codec.request_body(request), timeout=wait)

    async def cancel(self, goal_id: str | None = None) -> dict[str, Any]:
        """Cancel a goal (default: the active one)."""
        return await self.client.request(
            self.keys.goal_cancel, {} if goal_id is None else {"goal_id": goal_id}
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

    async def zero_ft_sensor(self) -> dict[str, Any]:
        """Zero the force/torque sensor."""
        return await self.service("zero_ft_sensor")

    async def set_tool_voltage(self, volts: int) -> dict[str, Any]:
        """Set the tool voltage (0, 12 or 24 V)."""
        return await self.service("set_tool_voltage", ToolVoltageRequest(volts))

    async def stop(self) -> dict[str, Any]:
        """Stop whatever moves the robot."""
        return await self.service("stop")

    def stream_positions(self, positions: Sequence[float], velocities: Sequence[float] | None = None) -> None:
        """Publish one streaming position command (repeat faster than the deadman timeout)."""
        body: dict[str, Any] = {"positions": list(positions)}
        if velocities is not None:
            body["velocities"] = list(velocities)
        self.client.session.put(self.keys.command_joint_position, _encode(body))

    def freedrive(self, active: bool = True) -> None:
        """Keep freedrive (hand guiding) on for one deadman period, or end it; repeat while it should last."""
        self.client.session.put(self.keys.command_freedrive, _encode({"active": active}))

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
        """Publish one streaming velocity command (repeat faster than the deadman timeout)."""
        self.client.session.put(self.keys.command_joint_velocity, _encode({"velocities": list(velocities)}))

    async def _send_goal(self, key: str, body: dict[str, Any]) -> GoalHandle:
        self._ensure_goal_subscription()
        reply = await self.client.request(key, body)
        if not reply.get("accepted"):
            raise GoalRejected(str(reply.get("reason", "rejected without a reason")))
        handle = GoalHandle(self, str(reply["goal_id"]), float(reply.get("duration", 0.0)))
        self._goals[handle.goal_id] = handle
        for kind, data in self._early.pop(handle.goal_id, []):
            handle._deliver(kind, data)
        return handle

    def _ensure_goal_subscription(self) -> None:
        if self._goal_sub is None:
            self._goal_sub = self.client.subscribe(self.keys.goal_messages, maxsize=10000)
            self._pump = asyncio.get_running_loop().create_task(self._pump_goals(self._goal_sub))
            self.client._tasks.append(self._pump)
            self._watch_liveliness()

    def _forget(self, goal_id: str) -> None:
        self._goals.pop(goal_id, None)

    def _watch_liveliness(self) -> None:
        """Fail every waiting goal when the daemon stops serving this robot (its token disappears)."""
        loop = asyncio.get_running_loop()

        def on_token(sample: Any) -> None:
            if sample.kind == zenoh.SampleKind.DELETE:
                with contextlib.suppress(RuntimeError):
                    loop.call_soon_threadsafe(self._on_lost)

        self._alive_sub = self.client.session.liveliness().declare_subscriber(self.keys.alive, on_token)
        self.client._closers.append(self._alive_sub.undeclare)

    def _on_lost(self) -> None:
        if self._goals and (self._lost is None or self._lost.done()):
            self._lost = asyncio.get_running_loop().create_task(self._settle_lost())
            self.client._tasks.append(self._lost)

    async def _settle_lost(self) -> None:
        """The token is gone: a result published just before may still be on its way (or only be
        answerable), so take what was received, ask for each waiting goal's result, and fail only
        the goals whose result is still unknown after ``LOST_GRACE_S``."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + LOST_GRACE_S
        waiting = list(self._goals.values())
        await asyncio.gather(*(handle._poll_result(timeout=LOST_GRACE_S) for handle in waiting))
        pending = [handle._result for handle in waiting if not handle._result.done()]
        if pending:
            await asyncio.wait(pending, timeout=max(0.0, deadline - loop.time()))
        error = ConnectionLostError(
            f"the daemon at {self.client.endpoint} stopped serving robot {self.name!r} before the goal ended"
        )
        for handle in waiting:
            if not handle._result.done():
                handle._fail(error)
                self._forget(handle.goal_id)

    async def _pump_goals(self, sub: Subscription) -> None:
        async for key, payload in sub:
            parts = key.split("/")
            if len(parts) < 2 or parts[-1] not in ("feedback", "result"):
                continue
            goal_id, kind = parts[-2], parts[-1]
            data = _result_message(payload, goal_id)
            if data is None:  # not JSON, not an object, or about another goal: someone else's garbage
                continue
            handle = self._goals.get(goal_id)
            if handle is not None:
                handle._deliver(kind, data)
                if kind == "result":  # the handle keeps its result; the robot need not track it further
                    self._forget(goal_id)
            else:
                early = self._early.setdefault(goal_id, [])
                if len(early) < 100:
                    early.append((kind, data))
                if len(self._early) > 100:
                    self._early.pop(next(iter(self._early)))
