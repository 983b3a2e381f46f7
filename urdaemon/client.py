"""The asyncio Python API for programs that talk to a running urdaemon over Zenoh.

::

    async with await Client.connect("tcp/127.0.0.1:7447") as client:
        alice = await client.robot("alice")
        goal = await alice.move([0, -1.57, 1.57, -1.57, -1.57, 0], duration=3.0)
        async for feedback in goal.feedback():
            print(feedback["progress"])
        result = await goal.result()

Commanding a robot needs its command lease (docs/security.md): the first goal, cancel or commanding
service call of a ``RobotClient`` acquires it transparently (``LeaseHeld`` when another client holds
it), and ``Client.close()`` releases it. Once the lease ended without this client's release (another
client took it over, or it was lost), commands raise ``LeaseHeld`` until the program calls
``ensure_lease()`` again; an event saying so ends it only once the daemon confirms it. Stream commands
(``stream_positions``, ``stream_velocities``, ``freedrive``) are plain publications that never wait:
call ``await robot.ensure_lease()`` once before the first, as a ur_rtde program opens its control
interface before ``servoJ``. ``stop`` never needs the lease.

A goal's feedback and result are taken only when they carry the signature, under the key the accepting
reply gave this client, of the message and of the key it arrived on: another session can publish on a
goal's keys (or re-publish the daemon's signed feedback as a result), but what it publishes is dropped
and counted (``GoalHandle.forged``).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import numbers
import os
import re
import secrets
import socket
import sys
from collections.abc import AsyncIterator, Callable, Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

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
from urdaemon.publish import service_requests, services, signing
from urdaemon.publish.envelope import SCHEMA_VERSION, client_text
from urdaemon.publish.keys import CellKeys, RobotKeys
from urdaemon.publish.node import zenoh_config
from urdaemon.runtime.lease import HOLDER_MAX_CHARS, TOKEN_BYTES, fingerprint

__all__ = [
    "DEFAULT_ENDPOINT",
    "Client",
    "GoalHandle",
    "Lease",
    "LeaseHeld",
    "NoSuchRobot",
    "NoSuchService",
    "Received",
    "RobotClient",
    "Subscription",
    "default_holder",
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
RELEASE_ON_CLOSE_S = 2.0
"""How long ``Client.close()`` waits for each lease's release (the session's end frees it anyway)."""
LEASE_SESSION_BYTES = 16
"""A lease's secret session id is this many random bytes, as hex (a fresh one per lease)."""
_LEASE_TOKEN = re.compile(rf"[0-9a-f]{{{2 * TOKEN_BYTES}}}")
_RESULT_KEY = re.compile(rf"[0-9a-f]{{{2 * signing.KEY_BYTES}}}")

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


class LeaseHeld(GoalRejected):
    """The daemon refused a command for the robot's command lease: another client holds it (the
    reason names the holder and since when), or this client's lease ended (taken over, released)."""


def default_holder(program: str | None = None) -> str:
    """The holder text a lease shows to humans: the program, its pid and host
    (``"urdaemon move (pid 1234 on cell-pc)"``), cut to what the daemon takes."""
    name = program or _program_name(sys.argv[0] if sys.argv else "")
    text = f"{name} (pid {os.getpid()} on {socket.gethostname()})"
    return _printable(text)


def _program_name(argv0: str) -> str:
    """The script's name; a package's for ``python -m package``; "python" for ``-c`` or none."""
    path = Path(argv0)
    if path.name == "__main__.py" and path.parent.name:
        return path.parent.name
    if not path.name or path.name.startswith("-"):
        return "python"
    return path.name


def _printable(text: str) -> str:
    shown = "".join(c if c.isprintable() else "?" for c in text).strip()
    return shown[:HOLDER_MAX_CHARS] or "python"


def _encode(body: dict[str, Any]) -> bytes:
    return json.dumps({"v": SCHEMA_VERSION, **body}, separators=(",", ":")).encode()


class Received(NamedTuple):
    """One sample as a subscription received it: its key, payload and Zenoh attachment (or None)."""

    key: str
    payload: bytes
    attachment: bytes | None


class Subscription:
    """Samples of a key expression, delivered to the loop; iterate with ``async for`` over
    ``(key, payload)``, or over ``samples()`` for each sample's attachment too."""

    def __init__(
        self, session: Any, key_expr: str, loop: asyncio.AbstractEventLoop, maxsize: int = 1000
    ) -> None:
        self.key_expr = key_expr
        self._queue: asyncio.Queue[Received] = asyncio.Queue(maxsize)
        self._loop = loop
        self.dropped = 0
        self._sub = session.declare_subscriber(key_expr, self._on_sample)

    def _on_sample(self, sample: Any) -> None:
        item = _received(sample)
        with contextlib.suppress(RuntimeError):
            self._loop.call_soon_threadsafe(self._put, item)

    def _put(self, item: Received) -> None:
        try:
            self._queue.put_nowait(item)
        except asyncio.QueueFull:
            self.dropped += 1

    async def get_sample(self, timeout: float | None = None) -> Received:
        """The next sample with its attachment; raises ``UrTimeoutError`` after ``timeout`` seconds."""
        try:
            return await asyncio.wait_for(self._queue.get(), timeout)
        except TimeoutError as err:
            raise UrTimeoutError(f"no sample on {self.key_expr} within {timeout} s") from err

    async def get(self, timeout: float | None = None) -> tuple[str, bytes]:
        """The next (key, payload); raises ``UrTimeoutError`` after ``timeout`` seconds."""
        item = await self.get_sample(timeout)
        return item.key, item.payload

    async def get_json(self, timeout: float | None = None) -> dict[str, Any]:
        """The next sample decoded as JSON."""
        _, payload = await self.get(timeout)
        data: dict[str, Any] = json.loads(payload)
        return data

    def __aiter__(self) -> AsyncIterator[tuple[str, bytes]]:
        return self._iterate()

    async def _iterate(self) -> AsyncIterator[tuple[str, bytes]]:
        while True:
            item = await self._queue.get()
            yield item.key, item.payload

    async def samples(self) -> AsyncIterator[Received]:
        """Every sample with its attachment, as it comes."""
        while True:
            yield await self._queue.get()

    def close(self) -> None:
        """Stop receiving."""
        with contextlib.suppress(Exception):
            self._sub.undeclare()


class Client:
    """A Zenoh session connected to a urdaemon cell."""

    def __init__(
        self,
        session: Any,
        loop: asyncio.AbstractEventLoop,
        endpoint: str = DEFAULT_ENDPOINT,
        *,
        holder: str | None = None,
    ) -> None:
        self.session = session
        self.endpoint = endpoint
        """Where this client connected (named in error messages)."""
        self.holder = default_holder() if holder is None else _printable(holder)
        """Who this client is, as its leases show it to others (``urdaemon lease``)."""
        self._loop = loop
        self._subscriptions: list[Subscription] = []
        self._tasks: list[asyncio.Task[None]] = []
        self._closers: list[Callable[[], object]] = []
        self._leases: dict[str, Lease] = {}

    @classmethod
    async def connect(
        cls,
        endpoint: str = DEFAULT_ENDPOINT,
        *,
        timeout: float = 5.0,
        low_latency: bool = False,
        holder: str | None = None,
        config_file: str | None = None,
    ) -> Client:
        """Open a Zenoh session connected to ``endpoint`` (no multicast scouting); ``low_latency``
        to match a daemon whose cell sets ``zenoh: {low_latency: true}`` (half the CPU per sample
        for both; without it the client still works).

        ``config_file``: a Zenoh JSON5 configuration to start from (TLS certificates, docs/security.md);
        the endpoint, mode and scouting are still set as above. ``holder``: how this client's leases
        name it (default: the program, its pid and host).

        Raises ``UrDaemonError`` naming ``endpoint`` when nothing answers there within ``timeout`` s.
        """
        loop = asyncio.get_running_loop()
        try:
            conf = _session_config(endpoint, low_latency, config_file)
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
        return cls(session, loop, endpoint, holder=holder)

    async def __aenter__(self) -> Client:
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    async def close(self) -> None:
        """Release every lease this client holds, stop background tasks, undeclare subscriptions and
        close the session."""
        for lease in list(self._leases.values()):
            with contextlib.suppress(UrDaemonError):
                await lease.release(timeout=RELEASE_ON_CLOSE_S)
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
        self,
        key: str,
        body: dict[str, Any] | None = None,
        *,
        timeout: float = QUERY_TIMEOUT_S,
        attachment: bytes | None = None,
    ) -> list[bytes]:
        """Ask a queryable; every reply's payload. ``attachment``: e.g. a lease's token."""
        replies = await self.query_replies(key, body, timeout=timeout, attachment=attachment)
        return [reply.payload for reply in replies]

    async def query_replies(
        self,
        key: str,
        body: dict[str, Any] | None = None,
        *,
        timeout: float = QUERY_TIMEOUT_S,
        attachment: bytes | None = None,
        every_queryable: bool = False,
    ) -> list[Received]:
        """Ask a queryable; every reply with its attachment. ``every_queryable``: ask all that serve
        ``key`` and keep every reply (not just the best match, nor one reply per key)."""
        payload = None if body is None else _encode(body)
        options: dict[str, Any] = {}
        if every_queryable:
            options = {"target": zenoh.QueryTarget.ALL, "consolidation": zenoh.ConsolidationMode.NONE}

        def ask() -> list[Received]:
            replies = self.session.get(
                key, payload=payload, timeout=timeout, attachment=attachment, **options
            )
            return [_received(r.ok) for r in replies if r.ok is not None]

        try:
            return await self._loop.run_in_executor(None, ask)
        except zenoh.ZError as err:
            raise UrDaemonError(f"cannot ask {key!r} at {self.endpoint}: {zenoh_message(err)}") from err

    async def request(
        self,
        key: str,
        body: dict[str, Any] | None = None,
        *,
        timeout: float = QUERY_TIMEOUT_S,
        attachment: bytes | None = None,
    ) -> dict[str, Any]:
        """Ask a queryable that must answer once.

        Raises ``NoSuchService`` when the query ends at once without a reply (nobody serves ``key``),
        ``UrTimeoutError`` when nobody answers within ``timeout`` s.
        """
        start = self._loop.time()
        replies = await self.query(key, body, timeout=timeout, attachment=attachment)
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

    def lease(self, keys: RobotKeys) -> Lease:
        """This client's lease on the robot of ``keys`` (one per robot, whichever handle asks)."""
        lease = self._leases.get(keys.base)
        if lease is None:
            lease = self._leases[keys.base] = Lease(self, keys)
        return lease


def _session_config(endpoint: str, low_latency: bool, config_file: str | None) -> Any:
    """The client session's Zenoh config: ``config_file`` (if any) as the base, then a peer with
    ``endpoint`` and no scouting, as ``zenoh_config`` makes it."""
    ours = zenoh_config("peer", [], [endpoint], low_latency=low_latency)
    if config_file is None:
        return ours
    try:
        conf = zenoh.Config.from_file(config_file)
    except (zenoh.ZError, OSError) as err:
        reason = zenoh_message(err) if isinstance(err, zenoh.ZError) else (err.strerror or str(err))
        raise UrDaemonError(f"cannot read the Zenoh config {config_file}: {reason}") from err
    keys = ["mode", "listen/endpoints", "connect/endpoints", "scouting/multicast/enabled"]
    if low_latency:
        keys += ["transport/unicast/lowlatency", "transport/unicast/qos/enabled"]
    for key in keys:
        conf.insert_json5(key, ours.get_json(key))
    return conf


def _received(sample: Any) -> Received:
    attachment = sample.attachment
    return Received(
        str(sample.key_expr), sample.payload.to_bytes(), None if attachment is None else attachment.to_bytes()
    )


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

    def __init__(
        self, robot: RobotClient, goal_id: str, duration: float, result_key: str | None = None
    ) -> None:
        self.robot = robot
        self.goal_id = goal_id
        self.duration = duration
        self.result_key = result_key
        """The key the accepting reply gave: only messages signed with it are taken (None: a daemon
        that signs nothing, whose messages are taken as they come)."""
        self.forged = 0
        """Messages on this goal's keys (or replies to its result query) that were not signed with
        its key for the key they came on, or are no message of this goal: ignored."""
        keys = robot.keys
        self._kinds = {keys.goal_feedback(goal_id): "feedback", keys.goal_result(goal_id): "result"}
        self._feedback: asyncio.Queue[dict[str, Any]] = asyncio.Queue(self.MAX_QUEUED_FEEDBACK)
        self._result: asyncio.Future[dict[str, Any]] = asyncio.get_running_loop().create_future()

    def _receive(self, key: str, payload: bytes, attachment: bytes | None) -> str | None:
        """Take one message that arrived on ``key`` if that is this goal's feedback or result key,
        it is signed with the goal's key for that key, and it is one of this goal's messages (a
        result: with a ``status``); which it was (``"feedback"``, ``"result"``), None when not taken
        (counted in ``forged`` when it was on this goal's keys)."""
        kind = self._kinds.get(key)
        if kind is None:
            return None
        signed = self.result_key is None or signing.verify(self.result_key, key, payload, attachment)
        data = _goal_message(payload, self.goal_id, result=kind == "result") if signed else None
        if data is None:
            self.forged += 1
            return None
        self._deliver(kind, data)
        return kind

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
        """Ask every queryable of the goal's result key (another session may answer it too: only a
        reply signed with the goal's key counts)."""
        try:
            replies = await self.robot.client.query_replies(
                self.robot.keys.goal_result(self.goal_id), timeout=timeout, every_queryable=True
            )
        except UrDaemonError:
            return
        for reply in replies:  # a reply on another key than the result's is never the result
            if self._receive(reply.key, reply.payload, reply.attachment) == "result":
                self.robot._forget(self.goal_id)
                return


def _three(values: Sequence[float]) -> tuple[float, float, float]:
    """A centre of gravity as sent: the daemon refuses one that is not three numbers, naming it."""
    return tuple(values)  # type: ignore[return-value]


def _goal_message(payload: bytes, goal_id: str, *, result: bool = False) -> dict[str, Any] | None:
    """``payload`` decoded if it is a message of goal ``goal_id`` (a ``result``: with a ``status``),
    else None (garbage is ignored)."""
    try:
        data = json.loads(payload)
    except ValueError:
        return None
    if not isinstance(data, dict) or data.get("goal_id") != goal_id:
        return None
    if result and not isinstance(data.get("status"), str):
        return None
    return data


class Lease:
    """A client's command lease on one robot (docs/security.md): the liveliness token that binds it
    to the client's session, and the token the daemon granted, attached to every command.

    Each acquire that declares a token picks a fresh secret session id S (``secrets.token_hex(16)``):
    the liveliness token is ``<cell>/<robot>/lease/<S>`` and the daemon binds the lease to it. The
    daemon never shows S, only its fingerprint (``urdaemon.runtime.lease.fingerprint``), so nobody
    can acquire in this client's name. A refusal, a release or a lease that ended undeclares the token.

    A lease that ended without this client releasing it (taken over, lost, released: heard on the
    robot's events and confirmed by asking the daemon, or a command refused for the lease) is not
    acquired again behind the program's back: commands raise ``LeaseHeld`` saying why until
    ``acquire(again=True)`` (``RobotClient.ensure_lease``). A forced take-over would mean little if
    the client it stopped took the lease back with its next command. An event alone never ends it:
    anyone can publish on the events key, so the client asks ``show`` first.
    """

    def __init__(self, client: Client, keys: RobotKeys) -> None:
        self.client = client
        self.keys = keys
        self.token: str | None = None
        """The daemon's grant while this client holds the lease, else None."""
        self.unchecked = False
        """The daemon serves no lease for this robot (one older than leases): commands go without."""
        self.ended_reason: str | None = None
        """Why this client's lease ended without its release (None: it did not)."""
        self.refusal: str | None = None
        """The daemon's reason when this client last asked for the lease in vain (None: granted)."""
        self.ended = asyncio.Event()
        """Set when the lease ends without this client's release; cleared when it acquires again."""
        self.fingerprint: str | None = None
        """What the daemon shows of this client's lease (None while no liveliness token is declared)."""
        self.checks = 0
        """Lease events about this lease confirmed or denied by asking the daemon (``show``)."""
        self.checking: asyncio.Task[None] | None = None
        """The check under way, if any (one at a time: a flood of events asks once more at most)."""
        self._session = ""
        self._heard: dict[str, Any] | None = None
        self._again = False
        self._alive: Any = None
        self._events: Any = None
        self._lock = asyncio.Lock()

    @property
    def usable(self) -> bool:
        """Whether commands can be sent now: the lease is held, or the daemon checks none."""
        return self.token is not None or self.unchecked

    def attachment(self) -> bytes | None:
        """What goes with a command: the token's ASCII bytes (None without one)."""
        return None if self.token is None else self.token.encode()

    async def acquire(self, *, force: bool = False, reason: str = "", again: bool = False) -> dict[str, Any]:
        """The daemon's grant (acquired unless held already, or taken over with ``force``); raises
        ``LeaseHeld`` with the daemon's reason when refused, or why the lease ended unless ``again``."""
        async with self._lock:
            if self.usable and not force:
                return {"ok": True, "token": self.token}
            if self.ended_reason is not None and not (again or force):
                raise LeaseHeld(self.ended_reason)
            self._declare()
            body: dict[str, Any] = {"action": "acquire", "session": self._session}
            body["holder"] = self.client.holder
            if force:
                body.update(force=True, reason=reason)
            try:
                reply = await self.client.request(self.keys.lease, body)
            except NoSuchService:
                self._undeclare()
                self.unchecked = True
                return {"ok": True, "token": None}
            except BaseException:
                self._undeclare()
                raise
            token = reply.get("token")
            if reply.get("ok") is True and isinstance(token, str) and _LEASE_TOKEN.fullmatch(token):
                self._granted(token)
                return reply
            self._undeclare()
            self.refusal = str(reply.get("reason") or f"lease: not granted ({reply})")
            raise LeaseHeld(self.refusal)

    def _granted(self, token: str) -> None:
        self.token = token
        self.ended_reason = self.refusal = None
        self.ended.clear()
        if self._events is None:  # an end is published there: streams stop at once, not silently
            loop = asyncio.get_running_loop()

            def on_event(sample: Any) -> None:
                payload = sample.payload.to_bytes()
                if _may_end_a_lease(payload):  # the loop parses only what may end a lease
                    with contextlib.suppress(RuntimeError):
                        loop.call_soon_threadsafe(self._on_event, payload)

            self._events = self.client.session.declare_subscriber(self.keys.events, on_event)
            self.client._closers.append(self._events.undeclare)

    def _on_event(self, payload: bytes) -> None:
        """A lease event that says this client's lease ended (taken over, lost, released): ask the
        daemon whether it did (whoever can publish on the events key can forge one)."""
        event = _ending_event(payload)
        if event is None or self.token is None or self.fingerprint is None:
            return
        if _ended_fingerprint(event) != self.fingerprint:
            return  # another lease's end (an earlier one of this client's, or someone else's)
        self._heard = event
        if self.checking is not None and not self.checking.done():
            self._again = True  # the check under way may have asked before this end happened
            return
        self.checking = asyncio.get_running_loop().create_task(self._check())
        self.client._tasks.append(self.checking)
        self.checking.add_done_callback(self._checked)

    def _checked(self, task: asyncio.Task[None]) -> None:
        with contextlib.suppress(ValueError):
            self.client._tasks.remove(task)

    async def _check(self) -> None:
        """Ask ``show`` (off Zenoh's thread; the loop keeps running) until no event came meanwhile;
        end the lease when the daemon shows it free or another's. A failed ask ends nothing."""
        again = True
        while again and self.token is not None:
            self._again = False
            token, mine = self.token, self.fingerprint
            try:
                shown = await self.show()
            except UrDaemonError:
                return
            self.checks += 1
            if self.token == token and (shown is None or shown.get("fingerprint") != mine):
                self.end(_ended_text(self.keys.robot, self._heard, shown))
                return
            again = self._again

    async def confirm_end(self, reason: str) -> None:
        """A command was refused for the lease: end it for ``reason`` unless the daemon still shows
        it as this client's (the refusal came from another session answering the command's query),
        or when the daemon cannot be asked."""
        token, mine = self.token, self.fingerprint
        if token is None:
            return
        try:
            shown = await self.show()
        except UrDaemonError:
            shown = None
        if self.token == token and (shown is None or shown.get("fingerprint") != mine):
            self.end(reason)

    async def release(self, *, timeout: float = QUERY_TIMEOUT_S) -> dict[str, Any] | None:
        """Give the lease back (stops whatever still moves the robot); the daemon's reply, or None
        when this client held none."""
        async with self._lock:
            attachment = self.attachment()
            self.token = None
            try:
                if attachment is None:
                    return None
                return await self.client.request(
                    self.keys.lease, {"action": "release"}, timeout=timeout, attachment=attachment
                )
            finally:
                self._undeclare()

    def end(self, reason: str) -> None:
        """The lease is no longer this client's, for ``reason`` (taken over, lost, or a command
        refused for it: released by whoever took it over, or a daemon that restarted)."""
        self.token = None
        self.ended_reason = reason
        self.ended.set()
        self._undeclare()

    async def show(self) -> dict[str, Any] | None:
        """The lease as the daemon shows it (``holder``, ``fingerprint``, ``since``), None when free."""
        reply = await self.client.request(self.keys.lease, {"action": "show"})
        if reply.get("ok") is not True:
            raise UrDaemonError(str(reply.get("reason") or f"lease: no answer to show ({reply})"))
        lease = reply.get("lease")
        return lease if isinstance(lease, dict) else None

    def _declare(self) -> None:
        if self._alive is None:
            session = secrets.token_hex(LEASE_SESSION_BYTES)  # a secret per lease: never shown
            key = self.keys.lease_holder(session)
            try:
                self._alive = self.client.session.liveliness().declare_token(key)
            except zenoh.ZError as err:
                raise UrDaemonError(f"cannot declare the lease token {key}: {zenoh_message(err)}") from err
            self._session, self.fingerprint = session, fingerprint(session)

    def _undeclare(self) -> None:
        alive, self._alive = self._alive, None
        if alive is not None:
            with contextlib.suppress(Exception):
                alive.undeclare()


_ENDING_ACTIONS = ("taken_over", "lost", "released")


def _may_end_a_lease(payload: bytes) -> bool:
    """On Zenoh's thread: whether an event may be a lease's end (cheap; the loop parses it)."""
    return b"lease" in payload and any(action.encode() in payload for action in _ENDING_ACTIONS)


def _ending_event(payload: bytes) -> dict[str, Any] | None:
    """``payload`` decoded if it is a lease event saying a lease ended, else None."""
    try:
        event = json.loads(payload)
    except ValueError:
        return None
    if not isinstance(event, dict) or event.get("kind") != "lease":
        return None
    return event if event.get("action") in _ENDING_ACTIONS else None


def _ended_fingerprint(event: dict[str, Any]) -> object:
    """The fingerprint of the lease an ending event says ended (a take-over names it as previous)."""
    if event.get("action") == "taken_over":
        previous = event.get("previous")
        return previous.get("fingerprint") if isinstance(previous, dict) else None
    return event.get("fingerprint")


def _ended_text(robot: str, heard: dict[str, Any] | None, shown: dict[str, Any] | None) -> str:
    """Why a lease ended, as the daemon shows the robot's lease now (``shown``), in the words of the
    event heard when it agrees with the daemon (a take-over by the holder shown, or a free lease)."""
    heard = heard or {}
    why = heard.get("reason")
    again = "ensure_lease() acquires it again"
    if shown is None:
        cause = why if isinstance(why, str) and heard.get("action") == "lost" else "it is free now"
        return f"lease: robot {robot!r} is no longer this client's ({client_text(cause, 200)}); {again}"
    holder = client_text(str(shown.get("holder")), HOLDER_MAX_CHARS)
    if heard.get("action") == "taken_over" and heard.get("fingerprint") == shown.get("fingerprint"):
        return f"lease: robot {robot!r} was taken over by {holder}: {client_text(str(why), 200)}; {again}"
    return f"lease: robot {robot!r} is held by {holder} now, no longer by this client; {again}"


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


class _CartesianCommands:
    """A robot's Cartesian commands (issue 17): pose and linear goals, twists, the TCP offset.

    Poses are (x, y, z, rx, ry, rz): metres and a rotation vector (rad), of the TCP (the robot's
    current TCP offset applied), in the robot's base frame (``frame="base"``, the frame of
    ``tcp_pose``) or the cell's world frame (``frame="world"``, for a robot mounted on ``world``).
    A part of ``RobotClient``: it sends through the robot's goal and lease machinery.
    """

    keys: RobotKeys
    client: Client

    if TYPE_CHECKING:  # RobotClient's

        async def _send_goal(self, key: str, body: dict[str, Any]) -> GoalHandle: ...

        async def _command(
            self, key: str, body: dict[str, Any], answer: str, timeout: float
        ) -> dict[str, Any]: ...

        def _stream_attachment(self) -> bytes | None: ...

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
        body: dict[str, Any] = {"pose": list(pose), "frame": frame}
        body.update(velocity_scale=velocity_scale, acceleration_scale=acceleration_scale, preempt=preempt)
        _put_given(body, configuration=configuration, duration=duration, tolerances=tolerances)
        return await self._send_goal(self.keys.goal_move, body)

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
        body: dict[str, Any] = {"poses": _pose_list(poses), "frame": frame}
        _put_given(
            body,
            blend_radii=None if blend_radii is None else list(blend_radii),
            speed=speed,
            acceleration=acceleration,
            jerk=jerk,
            angular_speed=angular_speed,
            angular_acceleration=angular_acceleration,
            angular_jerk=angular_jerk,
        )
        return await self._send_goal(self.keys.goal_linear, body)

    def twist(self, linear: Sequence[float], angular: Sequence[float], *, frame: str = "base") -> None:
        """Publish one twist command: the TCP point's velocity (m/s) and the angular velocity (rad/s),
        in the base frame or the TCP's own (``frame="tool"``). Repeat it faster than the robot's stream
        timeout, as with joint streams: when twists stop coming the robot stops; a zero twist
        decelerates it. Needs the lease held, as ``stream_positions``; the daemon's refusals (over its
        speed caps, no kinematics) are ``command_rejected`` events on the robot's events."""
        body = {"linear": list(linear), "angular": list(angular), "frame": frame}
        attachment = self._stream_attachment()
        self.client.session.put(self.keys.command_twist, _encode(body), attachment=attachment)

    async def set_tcp(self, pose: Sequence[float], *, timeout: float = QUERY_TIMEOUT_S) -> None:
        """Set the TCP offset (x, y, z, rx, ry, rz of the TCP in the flange frame): applied to
        ``tcp_pose``, every later Cartesian command and, on a UR robot, the controller's TCP.
        Raises ``GoalRejected`` with the daemon's reason (the robot moves, a value out of range),
        ``LeaseHeld`` when another client holds the lease."""
        reply = await self._command(self.keys.service("set_tcp"), {"pose": list(pose)}, "ok", timeout)
        if reply.get("ok") is not True:
            raise GoalRejected(str(reply.get("reason") or f"set_tcp: refused ({reply})"))


def _put_given(body: dict[str, Any], **fields: object) -> None:
    """Add each field that is not None to ``body`` (left out: the daemon's default)."""
    body.update({name: value for name, value in fields.items() if value is not None})


def _pose_list(poses: Sequence[float] | Sequence[Sequence[float]]) -> list[Any]:
    """``poses`` as a list of poses: one pose (six numbers) becomes a list of one."""
    items = list(poses)
    if items and all(isinstance(v, numbers.Real) for v in items):
        return [items]
    return [list(p) if isinstance(p, Iterable) and not isinstance(p, str) else p for p in items]


class RobotClient(_CartesianCommands):
    """Commands and state of one robot."""

    def __init__(self, client: Client, keys: RobotKeys) -> None:
        self.client = client
        self.keys = keys
        self._goals: dict[str, GoalHandle] = {}
        self._early: dict[str, list[tuple[str, bytes, bytes | None]]] = {}
        self._goal_sub: Subscription | None = None
        self._pump: asyncio.Task[None] | None = None
        self._alive_sub: Any = None
        self._lost: asyncio.Task[None] | None = None

    @property
    def name(self) -> str:
        """The robot's name."""
        return self.keys.robot

    @property
    def lease(self) -> Lease:
        """This client's command lease on the robot."""
        return self.client.lease(self.keys)

    async def ensure_lease(self) -> str:
        """Acquire the robot's command lease unless this client holds it; its token ("" when the
        daemon checks none). Raises ``LeaseHeld`` naming the holder when another client holds it.

        Goals, cancels and commanding services acquire by themselves, except after the lease was
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
        """Cancel a goal (default: the active one); needs the lease like any command."""
        body = {} if goal_id is None else {"goal_id": goal_id}
        return await self._command(self.keys.goal_cancel, body, "canceled", QUERY_TIMEOUT_S)

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
        body: dict[str, Any] = {"positions": list(positions)}
        if velocities is not None:
            body["velocities"] = list(velocities)
        attachment = self._stream_attachment()
        self.client.session.put(self.keys.command_joint_position, _encode(body), attachment=attachment)

    def freedrive(self, active: bool = True) -> None:
        """Keep freedrive (hand guiding) on for one deadman period, or end it; repeat while it should
        last. Needs the lease held, as ``stream_positions``."""
        attachment = self._stream_attachment()
        self.client.session.put(
            self.keys.command_freedrive, _encode({"active": active}), attachment=attachment
        )

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
        body = _encode({"velocities": list(velocities)})
        self.client.session.put(self.keys.command_joint_velocity, body, attachment=attachment)

    async def _send_goal(self, key: str, body: dict[str, Any]) -> GoalHandle:
        self._ensure_goal_subscription()
        reply = await self._command(key, body, "accepted", QUERY_TIMEOUT_S)
        if not reply.get("accepted"):
            raise GoalRejected(str(reply.get("reason", "rejected without a reason")))
        handle = GoalHandle(
            self, str(reply["goal_id"]), float(reply.get("duration", 0.0)), self._result_key(reply)
        )
        self._goals[handle.goal_id] = handle
        for msg_key, payload, attachment in self._early.pop(handle.goal_id, []):
            if handle._receive(msg_key, payload, attachment) == "result":
                self._forget(handle.goal_id)
        return handle

    def _result_key(self, reply: dict[str, Any]) -> str | None:
        """The goal's key from its accepting reply: 64 hex characters; None only from a daemon older
        than leases (it signs nothing). A daemon with leases always gives one: without, the goal's
        messages could not be told from forgeries, so that is an error naming ``result_key``."""
        key = reply.get("result_key")
        if isinstance(key, str) and _RESULT_KEY.fullmatch(key):
            return key
        if key is None and self.lease.unchecked:
            return None
        raise UrDaemonError(
            f"robot {self.name!r}: the daemon accepted goal {client_text(str(reply.get('goal_id')), 80)} "
            f"without a valid 'result_key' ({2 * signing.KEY_BYTES} hex characters): its result "
            "cannot be told from a forgery"
        )

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
        async for key, payload, attachment in sub.samples():
            parts = key.split("/")
            if len(parts) < 2 or parts[-1] not in ("feedback", "result"):
                continue
            goal_id = parts[-2]
            handle = self._goals.get(goal_id)
            if handle is not None:
                # the handle keeps its result; the robot need not track it further
                if handle._receive(key, payload, attachment) == "result":
                    self._forget(goal_id)
            elif _goal_message(payload, goal_id) is not None:  # else someone else's garbage
                # before the accepting reply: checked once the reply gives the goal's key
                early = self._early.setdefault(goal_id, [])
                if len(early) < 100:
                    early.append((key, payload, attachment))
                if len(self._early) > 100:
                    self._early.pop(next(iter(self._early)))
