"""Every key the daemon serves, declared once: ``ROBOT_ENDPOINTS`` (under ``<cell>/<robot>/``) and
``CELL_ENDPOINTS`` (under ``<cell>/``), one ``Endpoint`` row per key.

A row says what the key is (``kind``: the daemon publishes on it, answers queries on it, subscribes
to it, holds a liveliness token on it, or watches its clients' tokens on it), who may use it
(``audience``: anyone, the robot's readers, its commanders, or nobody the grants name), whether a
message on it needs the robot's command lease (``lease``), what a read-only robot does with it
(``read_only``), how large a message may be (``max_bytes``), how a query is answered (``answer``,
``any_id``) and the type its body decodes to (``message``). The services are one family of rows,
derived from publish/services.py's ``SERVICES``.

From the rows follow: the runtime's declarations (``declare_endpoints``: robot.py for a robot's
rows, daemon.py for the cell's), the access-control rules of the cell file's grants (access.py),
what a read-only robot refuses, and docs/keys.md's table of endpoints (``markdown_rows``;
``python -m urdaemon.publish.endpoints`` prints it, tests/publish/test_endpoints.py holds the two
together).
"""

from __future__ import annotations

import enum
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Any, Protocol

from urdaemon.cell.robot_options import READ_ONLY_REASON, Robot
from urdaemon.errors import MessageError
from urdaemon.publish.admission import Guard, refuse_query
from urdaemon.publish.cell_goal import CellGoalMessage
from urdaemon.publish.envelope import MAX_MESSAGE_BYTES, SMALL_MESSAGE_BYTES
from urdaemon.publish.keys import CellKeys, RobotKeys
from urdaemon.publish.linear_goal import LINEAR_MESSAGE_BYTES, LinearGoalMessage
from urdaemon.publish.move_goal import MoveGoalMessage
from urdaemon.publish.services import SERVICES, STOP, ServiceSpec
from urdaemon.publish.stream_commands import StreamMessage, TwistMessage
from urdaemon.publish.trajectory_goal import TrajectoryGoalMessage

__all__ = [
    "CELL",
    "CELL_ENDPOINTS",
    "ROBOT",
    "ROBOT_ENDPOINTS",
    "Audience",
    "Audit",
    "AuditedGuard",
    "Endpoint",
    "Kind",
    "Node",
    "ReadOnly",
    "ReadOnlyGuard",
    "declare_endpoints",
    "markdown_rows",
    "read_only_reason",
    "service_row",
]


class Node(Protocol):
    """What declaring a row uses of the daemon's session (publish/node.py's ``ZenohNode``)."""

    def publisher(self, key: str, *, realtime: bool = False) -> Any:
        """Declare a publisher."""

    def queryable(
        self,
        key: str,
        handler: Callable[[Any], None],
        *,
        max_bytes: int | None = ...,
        answer: str = ...,
        any_id: bool = ...,
        guard: Guard | None = ...,
    ) -> None:
        """Declare a queryable answering its exact key."""

    def cell_queryable(self, key: str, handler: Callable[[Any], None]) -> None:
        """Declare a queryable that shares its key with others."""

    def subscriber(
        self,
        key: str,
        handler: Callable[[str, bytes], None],
        *,
        max_bytes: int = ...,
        refused: Callable[[str, str], None] | None = ...,
        guard: Guard | None = ...,
    ) -> None:
        """Declare a subscriber handling samples on its exact key."""

    def liveliness_token(self, key: str) -> None:
        """Declare a liveliness token."""


class Audit(Protocol):
    """What hears of a commanding message for the audit log (runtime/audit.py's ``RobotAudit``)."""

    def refused(self, key: str, reason: str, attachment: bytes | None) -> None:
        """A message refused by its guard (the lease, a read-only robot), on Zenoh's thread."""

    def asked(self, key: str, query: Any, answer: str) -> Any:
        """A query reaching its handler, on the loop: the query to hand on, which tells its answer."""


class Kind(enum.StrEnum):
    """What the daemon does on a key (the client does the other half)."""

    PUBLICATION = "publication"
    """The daemon publishes; a client subscribes."""
    QUERYABLE = "queryable"
    """A client asks (a Zenoh get); the daemon answers."""
    SUBSCRIBER = "subscriber"
    """A client puts; the daemon subscribes."""
    LIVELINESS = "liveliness"
    """The daemon holds a liveliness token; a client watches or asks for it."""
    TOKEN = "token"
    """A client holds a liveliness token (the lease holder's); the daemon watches it."""


class Audience(enum.StrEnum):
    """Who may use a key: the access-control grants it falls under (access.py)."""

    ANYONE = "anyone"
    """Every connection, whatever the grants (``stop``, and a robot's ``goal/cancel``: it only stops)."""
    READER = "reader"
    """A grant that reads (or commands) the robot; for a key of the cell, any of its robots."""
    CELL_READER = "cell reader"
    """A key of the cell about every robot (tf, the cell goals' messages): a grant reading ``*``."""
    COMMANDER = "commander"
    """A grant that commands the robot; for a key of the cell, every robot (``*``)."""
    NOBODY = "nobody"
    """No grant names it: the cell's default permission decides."""


class ReadOnly(enum.StrEnum):
    """What a read-only robot (``ur.read_only``) does with a message on the key."""

    SERVED = "served"
    """As any robot does: the key reads, or (stop, cancel, the lease) commands nothing."""
    REFUSED = "refused"
    """Refused on Zenoh's thread with ``READ_ONLY_REASON``, before anything reads it."""
    BY_REQUEST = "by request"
    """The service decides per request (``ServiceSpec.read_only_refusal``: the dashboard's lines)."""


@dataclass(frozen=True, slots=True, eq=False)
class Endpoint:
    """One key the daemon serves, and everything that follows from it."""

    name: str
    """The row's name: the ``RobotKeys``/``CellKeys`` member that makes its key, or ``service/<name>``."""
    key_of: Callable[[Any], str]
    """The key, from the robot's ``RobotKeys`` (or the cell's ``CellKeys``)."""
    kind: Kind
    audience: Audience
    summary: str
    """One line: what the key is for."""
    lease: bool = False
    """A message needs the command lease holder's token as its attachment (publish/node.py's guard)."""
    read_only: ReadOnly = ReadOnly.SERVED
    max_bytes: int | None = SMALL_MESSAGE_BYTES
    """The largest message accepted (queryables and subscribers; None: any, the payload is not read)."""
    answer: str | None = None
    """A queryable's reply field that says yes or no (``ok``, ``accepted``, ``canceled``); None: not a
    complete queryable (it answers in its own shape, or stays silent for others to answer)."""
    any_id: bool = False
    """A queryable whose key has a ``*`` chunk: any concrete key matching it is answered."""
    realtime: bool = False
    """A publication of the state streams (express, top priority)."""
    message: type | None = None
    """The type a message's body decodes to (model.py or publish/), None: no typed body."""
    service: ServiceSpec | None = None
    """The service of a service row (publish/services.py)."""

    @property
    def commanding(self) -> bool:
        """Whether only the robot's commanders may use it."""
        return self.audience is Audience.COMMANDER

    @property
    def audited(self) -> bool:
        """Whether the audit log hears of messages on it: every row that commands or stops a robot
        (commanders', anyone's) a client sends to (a query, a put)."""
        return self.audience in (Audience.COMMANDER, Audience.ANYONE) and self.kind in (
            Kind.QUERYABLE,
            Kind.SUBSCRIBER,
        )

    @property
    def cell_level(self) -> bool:
        """Whether the key is the cell's (``CELL_ENDPOINTS``), not a robot's."""
        return self in CELL_ENDPOINTS

    def key(self, keys: RobotKeys | CellKeys) -> str:
        """The key for this robot (``RobotKeys``) or cell (``CellKeys``)."""
        return self.key_of(keys)

    @property
    def pattern(self) -> str:
        """The key as docs/keys.md writes it (``<cell>/<robot>/goal/<id>/result``)."""
        keys: RobotKeys | CellKeys = CellKeys("<cell>") if self.cell_level else RobotKeys("<cell>", "<robot>")
        key = self.key(keys)
        wild = {"goal": "<id>", "lease": "<session>", "<id>": "<kind>"}
        chunks = key.split("/")
        for i, chunk in enumerate(chunks):
            if chunk == "*":
                chunks[i] = wild.get(chunks[i - 1], chunk)
        return "/".join(chunks)

    def guard(self, lease: Guard | None, read_only: str | None) -> Guard | None:
        """What checks a message on Zenoh's thread: a read-only robot's refusal, or the lease."""
        if read_only is not None and self.read_only is ReadOnly.REFUSED:
            return ReadOnlyGuard(read_only)
        return lease if self.lease else None

    def _audited(self, key: str, guard: Guard | None, handler: Any, audit: Audit | None) -> tuple[Any, Any]:
        """The guard and handler with the audit told of each refusal and each answer."""
        if audit is None or not self.audited:
            return guard, handler
        if guard is not None:
            guard = AuditedGuard(guard, key, audit)
        if self.kind is Kind.QUERYABLE:
            inner, answer = handler, self.answer or "ok"

            def handle(query: Any) -> None:
                inner(audit.asked(key, query, answer))

            handler = handle
        return guard, handler

    def declare(
        self,
        node: Node,
        keys: RobotKeys | CellKeys,
        handler: Any = None,
        *,
        guard: Guard | None = None,
        read_only: str | None = None,
        refused: Callable[[str, str], None] | None = None,
        audit: Audit | None = None,
    ) -> Any:
        """Declare this row on ``node`` with its settings: a publication's publisher is returned.
        With ``audit``, an audited row's refusals and answers are told to it."""
        key = self.key(keys)
        if self.kind is Kind.PUBLICATION:
            return node.publisher(key, realtime=self.realtime) if self.realtime else node.publisher(key)
        if self.kind is Kind.LIVELINESS:
            node.liveliness_token(key)
            return None
        if self.kind is Kind.TOKEN:
            raise ValueError(f"{self.name}: a client's token is watched for the cell (lease_keeper.py)")
        if handler is None:
            raise ValueError(f"{self.name}: a {self.kind} needs a handler")
        checked = self.guard(guard, read_only)
        by_request = read_only is not None and self.read_only is ReadOnly.BY_REQUEST
        if self.kind is not Kind.SUBSCRIBER and self.answer is not None and by_request:
            assert self.service is not None, "only a service decides per request"
            handler = _read_only_checked(self.service, handler, self.answer)
        checked, handler = self._audited(key, checked, handler, audit)
        if self.kind is Kind.SUBSCRIBER:
            assert self.max_bytes is not None, "a subscriber's samples are bounded"
            node.subscriber(key, handler, max_bytes=self.max_bytes, refused=refused, guard=checked)
        elif self.answer is None:
            node.cell_queryable(key, handler)
        else:
            node.queryable(
                key, handler, max_bytes=self.max_bytes, answer=self.answer, any_id=self.any_id, guard=checked
            )
        return None


@dataclass(frozen=True, slots=True)
class AuditedGuard:
    """A guard whose refusals the audit log hears of (on Zenoh's thread, as the guard decides)."""

    inner: Guard
    key: str
    audit: Audit

    def refusal(self, attachment: bytes | None) -> str | None:
        """The inner guard's answer; a refusal told to the audit."""
        refusal = self.inner.refusal(attachment)
        if refusal is not None:
            self.audit.refused(self.key, refusal, attachment)
        return refusal


@dataclass(frozen=True, slots=True)
class ReadOnlyGuard:
    """A read-only robot's guard of a commanding key: every message is refused, with ``reason``."""

    reason: str

    def refusal(self, attachment: bytes | None) -> str | None:
        """Always the reason: a read-only robot is watched, not commanded."""
        return self.reason


def read_only_reason(robot: Robot) -> str | None:
    """Why ``robot`` refuses commanding messages: ``READ_ONLY_REASON`` for a read-only robot, else None."""
    ur = robot.ur
    return READ_ONLY_REASON if robot.backend == "ur" and ur is not None and ur.read_only else None


def _read_only_checked(
    spec: ServiceSpec, handler: Callable[[Any], None], answer: str
) -> Callable[[Any], None]:
    """``handler``, run for a request ``spec`` lets a read-only robot serve; another is refused naming why."""
    check = spec.read_only_refusal
    assert check is not None, "a service that decides per request has the check"

    def handle(query: Any) -> None:
        data = query.payload
        try:
            refusal = check(spec.decode(None if data is None else bytes(data.to_bytes())))
        except MessageError:  # the service itself refuses it, naming the field
            refusal = None
        if refusal is None:
            handler(query)
        else:
            refuse_query(query, refusal, answer=answer)

    return handle


def _attr(name: str) -> Callable[[Any], str]:
    def key_of(keys: Any) -> str:
        return str(getattr(keys, name))

    return key_of


def _row(name: str, kind: Kind, audience: Audience, summary: str, **rest: Any) -> Endpoint:
    return Endpoint(name, _attr(name), kind, audience, summary, **rest)


def service_row(spec: ServiceSpec) -> Endpoint:
    """The row of one service (``stop``: anyone's, never refused for its payload or the lease)."""
    name = spec.name

    def key_of(keys: Any) -> str:
        return str(keys.service(name))

    if spec is STOP:
        return Endpoint(
            f"service/{name}",
            key_of,
            Kind.QUERYABLE,
            Audience.ANYONE,
            spec.summary,
            max_bytes=None,
            answer="ok",
            service=spec,
        )
    if not spec.commanding:
        read_only = ReadOnly.SERVED
    else:
        read_only = ReadOnly.REFUSED if spec.read_only_refusal is None else ReadOnly.BY_REQUEST
    audience = Audience.COMMANDER if spec.commanding else Audience.READER
    return Endpoint(
        f"service/{name}",
        key_of,
        Kind.QUERYABLE,
        audience,
        spec.summary,
        lease=spec.commanding,
        read_only=read_only,
        answer="ok",
        message=spec.request,
        service=spec,
    )


_P, _Q, _S = Kind.PUBLICATION, Kind.QUERYABLE, Kind.SUBSCRIBER
_READER, _COMMANDER = Audience.READER, Audience.COMMANDER
_REFUSED = ReadOnly.REFUSED


def _goal(name: str, summary: str, message: type, max_bytes: int = SMALL_MESSAGE_BYTES) -> Endpoint:
    return _row(
        name,
        _Q,
        _COMMANDER,
        summary,
        lease=True,
        read_only=_REFUSED,
        max_bytes=max_bytes,
        answer="accepted",
        message=message,
    )


def _stream(name: str, summary: str, message: type | None) -> Endpoint:
    return _row(name, _S, _COMMANDER, summary, lease=True, read_only=_REFUSED, message=message)


class _RobotRows:
    """A robot's rows by name (``ROBOT.goal_move``), in the order ``ROBOT_ENDPOINTS`` lists them."""

    joint_states = _row("joint_states", _P, _READER, "joint positions, velocities, efforts", realtime=True)
    tcp_pose = _row("tcp_pose", _P, _READER, "the TCP pose in the robot's base frame", realtime=True)
    status = _row("status", _P, _READER, "lifecycle, modes, speed scaling, counters, lease")
    io = _row("io", _P, _READER, "inputs, outputs, tool voltage, payload")
    events = _row("events", _P, _READER, "refused commands and the robot's notices")
    servo_command = _row("servo_command", _P, _READER, "a servo robot's pulses (outputs: zenoh)")
    goal_messages = _row("goal_messages", _P, _READER, "each goal's signed feedback and result")
    alive = _row("alive", Kind.LIVELINESS, _READER, "present while the daemon serves the robot")
    goal_trajectory = _goal(
        "goal_trajectory", "a joint trajectory goal", TrajectoryGoalMessage, max_bytes=MAX_MESSAGE_BYTES
    )
    goal_move = _goal("goal_move", "a point-to-point move goal (joints or a TCP pose)", MoveGoalMessage)
    goal_linear = _goal(
        "goal_linear", "straight TCP lines through poses", LinearGoalMessage, max_bytes=LINEAR_MESSAGE_BYTES
    )
    goal_cancel = _row(
        "goal_cancel",
        _Q,
        Audience.ANYONE,
        "cancel a goal: it only stops the robot, so anyone who may stop it may (no lease)",
        answer="canceled",
    )
    goal_results = _row(
        "goal_results", _Q, _READER, "a finished goal's result, signed", answer="ok", any_id=True
    )
    lease = _row("lease", _Q, _COMMANDER, "acquire, release, take over or show the lease", answer="ok")
    lease_holder = Endpoint(
        "lease_holder",
        lambda keys: str(keys.lease_holder("*")),
        Kind.TOKEN,
        _COMMANDER,
        "the lease holder's liveliness token, binding the lease to its session",
    )
    command_joint_position = _stream("command_joint_position", "joint position stream", StreamMessage)
    command_joint_velocity = _stream("command_joint_velocity", "joint velocity stream", StreamMessage)
    command_twist = _stream("command_twist", "TCP twist stream", TwistMessage)
    command_freedrive = _stream("command_freedrive", "freedrive on for one deadman period, or off", None)
    services: Mapping[str, Endpoint] = {spec.name: service_row(spec) for spec in (*SERVICES, STOP)}

    @classmethod
    def service(cls, name: str) -> Endpoint:
        """The row of service ``name`` (KeyError for no such service)."""
        return cls.services[name]


class _CellRows:
    """The cell's rows by name (``CELL.stop``), in the order ``CELL_ENDPOINTS`` lists them."""

    tf = _row("tf", _P, Audience.CELL_READER, "every link pose of the cell in the world frame")
    goal_messages = _row("goal_messages", _P, Audience.CELL_READER, "each cell goal's signed result")
    """Published on ``goal/<id>/result`` only; a client follows ``goal/*/*``."""
    robot_description = _row("robot_description", _Q, _READER, "the cell URDF", max_bytes=None, answer="ok")
    daemon = _row("daemon", _Q, _READER, "the daemon describes itself and its robots", max_bytes=None)
    any_robot = _row(
        "any_robot", _Q, Audience.NOBODY, "names the robots or services there are", max_bytes=None
    )
    stop = _row("stop", _Q, Audience.ANYONE, "every robot of the cell stops", max_bytes=None, answer="ok")
    flight_record = _row(
        "flight_record", _Q, Audience.NOBODY, "the flight recorder writes a file now", answer="ok"
    )
    goal_trajectory = _row(
        "goal_trajectory",
        _Q,
        _COMMANDER,
        "trajectories that start together on several robots (each robot's lease token attached)",
        max_bytes=MAX_MESSAGE_BYTES,
        answer="accepted",
        message=CellGoalMessage,
    )
    goal_cancel = _row(
        "goal_cancel",
        _Q,
        Audience.ANYONE,
        "cancel a cell goal: it only stops the robots, so anyone who may stop them may (no lease)",
        answer="canceled",
    )
    audit = _row(
        "audit", _P, _COMMANDER, "the audit log: each commanding request, who asked, accepted or refused, why"
    )
    goal_results = _row(
        "goal_results", _Q, Audience.CELL_READER, "a finished cell goal's result", answer="ok", any_id=True
    )


ROBOT = _RobotRows
"""A robot's rows by name: ``ROBOT.goal_move``, ``ROBOT.service("set_io")``."""
CELL = _CellRows
"""The cell's rows by name: ``CELL.stop``."""


def _listed(rows: type) -> tuple[Endpoint, ...]:
    own = [value for value in vars(rows).values() if isinstance(value, Endpoint)]
    listed = [*own, *vars(rows).get("services", {}).values()]
    return tuple(sorted(listed, key=lambda row: row.kind is Kind.LIVELINESS))


ROBOT_ENDPOINTS: tuple[Endpoint, ...] = _listed(_RobotRows)
"""Every key under ``<cell>/<robot>/``: the services (``stop`` last) after the rest, and the
liveliness token last of all (declared last: once a client sees it, every other key is there)."""
CELL_ENDPOINTS: tuple[Endpoint, ...] = _listed(_CellRows)
"""Every key of the cell itself, under ``<cell>/``."""


def declare_endpoints(
    node: Node,
    keys: RobotKeys | CellKeys,
    served: Mapping[Endpoint, Any],
    *,
    guard: Guard | None = None,
    read_only: str | None = None,
    refused: Callable[[str, str], None] | None = None,
    audit: Audit | None = None,
) -> dict[Endpoint, Any]:
    """Declare every row of ``served`` (row → its handler; None for a publication or a token) in the
    table's order, each with its row's size limit, reply field and checks: the lease ``guard`` on a
    leased row, and with ``read_only`` (a read-only robot's reason) the refusal of every row a
    read-only robot does not serve. ``refused`` hears of every refused subscriber sample; ``audit``
    of every audited row's refusals and answers (``Endpoint.audited``). Returns each publication's
    publisher by row."""
    table = CELL_ENDPOINTS if isinstance(keys, CellKeys) else ROBOT_ENDPOINTS
    strangers = [row.name for row in served if row not in table]
    if strangers:
        raise ValueError(f"not rows of {'the cell' if table is CELL_ENDPOINTS else 'a robot'}: {strangers}")
    declared: dict[Endpoint, Any] = {}
    for row in table:
        if row in served:
            declared[row] = row.declare(
                node, keys, served[row], guard=guard, read_only=read_only, refused=refused, audit=audit
            )
    return declared


def _cell(value: object) -> str:
    return "" if value is None or value is False else ("yes" if value is True else str(value))


def markdown_rows(rows: Iterable[Endpoint] | None = None) -> list[str]:
    """docs/keys.md's table of endpoints: one line per row, the robot's then the cell's."""
    lines = []
    for row in (*ROBOT_ENDPOINTS, *CELL_ENDPOINTS) if rows is None else rows:
        reply = "" if row.answer is None else f"`{row.answer}`" + (", any id" if row.any_id else "")
        message = "" if row.message is None else f"`{row.message.__name__}`"
        size = "" if row.kind in (Kind.PUBLICATION, Kind.LIVELINESS, Kind.TOKEN) else _size(row.max_bytes)
        read_only = "—" if row.cell_level else str(row.read_only)
        lines.append(
            f"| `{row.pattern}` | {row.kind} | {row.audience} | {_cell(row.lease)} | {read_only} "
            f"| {size} | {reply} | {message} |"
        )
    return lines


def _size(max_bytes: int | None) -> str:
    if max_bytes is None:
        return "any (not read)"
    return f"{max_bytes // (1024 * 1024)} MiB" if max_bytes >= 1024 * 1024 else f"{max_bytes // 1024} KiB"


if __name__ == "__main__":
    print("\n".join(markdown_rows()))
