"""Transport security end to end: a daemon on a ``tls/`` loopback endpoint with mutual TLS and access
control from its cell file, reached by raw Zenoh sessions made from ``client_config`` (no urdaemon
client code on the far side, as an intruder would have none).

Certificates come from trustme (a throw-away CA per module): the daemon's for 127.0.0.1, clients
``operator`` (commands alice), ``viewer`` (reads alice), ``overseer`` (commands every robot: the
cell's own rows), ``visitor`` (signed by the CA, granted nothing) and ``stranger`` (signed by
another CA).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
from collections.abc import AsyncIterator, Callable, Mapping, Sequence
from contextlib import asynccontextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
import trustme
import zenoh

from tests.helpers import acquire_lease, free_tcp_port, zenoh_ask
from urdaemon.cell import Cell, parse_cell
from urdaemon.cell.zenoh_options import ALL_ROBOTS, AccessOptions
from urdaemon.daemon import Daemon
from urdaemon.model import (
    CycleStatsRequest,
    DashboardRequest,
    ForceModeRequest,
    SetIoRequest,
    SetPayloadRequest,
    SetTcpRequest,
    SpeedSliderRequest,
    ToolVoltageRequest,
)
from urdaemon.publish import session_config
from urdaemon.publish.cell_goal import CellGoalMessage, CellGoalRequest, cell_goal_body
from urdaemon.publish.endpoints import CELL as CELL_ROWS
from urdaemon.publish.endpoints import CELL_ENDPOINTS, ROBOT, ROBOT_ENDPOINTS, Audience, Endpoint, Kind
from urdaemon.publish.envelope import encode
from urdaemon.publish.goal_cancel import cancel_body, decode_cancel, decode_cell_cancel
from urdaemon.publish.keys import CellKeys, RobotKeys
from urdaemon.publish.lease_request import LeaseRequest, lease_body, parse_request
from urdaemon.publish.linear_goal import (
    LinearGoalMessage,
    LinearGoalRequest,
    decode_linear_goal,
    linear_goal_body,
)
from urdaemon.publish.move_goal import MoveGoalMessage, MoveGoalRequest, decode_move_goal, move_goal_body
from urdaemon.publish.service_requests import request_body
from urdaemon.publish.session_config import configure_daemon
from urdaemon.publish.stream_commands import (
    TwistMessage,
    decode_freedrive,
    decode_stream_position,
    decode_stream_velocity,
    decode_twist,
    freedrive_body,
)
from urdaemon.publish.trajectory_goal import (
    TrajectoryGoalMessage,
    TrajectoryGoalRequest,
    trajectory_goal_body,
)
from urdaemon.publish.trajectory_json import decode_trajectory_goal
from urdaemon.transport_security import client_config

CELL = "seccell"
START = [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]
CELL_TEXT = """
cell: seccell
command_lease: {lease}
zenoh:
  listen: ["{listen}"]
  tls: {{root_ca: ca.pem, certificate: daemon.pem, private_key: daemon-key.pem, mutual: true}}
  access:
    default: deny
    identities:
      operator: {{cert_common_names: [operator]}}
      viewer: {{cert_common_names: [viewer]}}
      overseer: {{cert_common_names: [overseer]}}
    grants:
      - {{identities: [viewer], read: [alice]}}
      - {{identities: [operator], command: [alice]}}
      - {{identities: [overseer], command: ["*"]}}
robots:
  - name: alice
    model: ur10e
    backend: mock
    mock: {{initial_positions: {start}}}
"""
CONNECT_TIMEOUT_MS = 5000
"""How long a client session tries to reach the daemon before ``zenoh.open`` gives up."""
WAIT_S = 10.0
"""The longest any one wait lasts. A query nothing serves (what access control leaves a session
that may not ask) ends at once with no reply, so the negative checks do not wait this long."""


@dataclass(frozen=True)
class Certs:
    """Where the module's certificate files are: ``<name>.pem`` and ``<name>-key.pem``."""

    folder: Path

    def pair(self, name: str) -> tuple[str, str]:
        return str(self.folder / f"{name}.pem"), str(self.folder / f"{name}-key.pem")


@pytest.fixture(params=["named cell", "any cell"])
def rules_for(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> None:
    """The cell the daemon's access rules name: ``seccell`` (what ``configure_daemon`` writes when the
    daemon passes its cell's name) or ``*`` (when it does not: the same robots of any cell)."""
    if request.param == "named cell":

        def named(conf: Any, options: Any, cell: str | None = None) -> None:
            configure_daemon(conf, options, CELL)

        monkeypatch.setattr(session_config, "configure_daemon", named)


@pytest.fixture(scope="module")
def certs(tmp_path_factory: pytest.TempPathFactory) -> Certs:
    folder = tmp_path_factory.mktemp("certs")
    ca, other_ca = trustme.CA(), trustme.CA()
    ca.cert_pem.write_to_path(str(folder / "ca.pem"))
    issued = {
        "daemon": ca.issue_cert("127.0.0.1", common_name="urdaemon"),
        "operator": ca.issue_cert("operator.invalid", common_name="operator"),
        "viewer": ca.issue_cert("viewer.invalid", common_name="viewer"),
        "overseer": ca.issue_cert("overseer.invalid", common_name="overseer"),
        "visitor": ca.issue_cert("visitor.invalid", common_name="visitor"),
        "stranger": other_ca.issue_cert("operator.invalid", common_name="operator"),
    }
    for name, leaf in issued.items():
        leaf.cert_chain_pems[0].write_to_path(str(folder / f"{name}.pem"))
        leaf.private_key_pem.write_to_path(str(folder / f"{name}-key.pem"))
    return Certs(folder)


def _config(data: dict[str, Any]) -> Any:
    conf = zenoh.Config.from_json5(json.dumps(data))
    conf.insert_json5("connect/timeout_ms", json.dumps(CONNECT_TIMEOUT_MS))
    return conf


async def _open(conf: Any) -> Any:
    return await asyncio.get_running_loop().run_in_executor(None, zenoh.open, conf)


@dataclass
class Secure:
    """A running secure daemon and how to reach it."""

    daemon: Daemon
    cell: Cell
    listen: str
    certs: Certs

    def config(self, name: str | None) -> Any:
        """A client config for identity ``name`` (None: the root CA only, no client certificate)."""
        if name is None:
            ca = str(self.certs.folder / "ca.pem")
            return _config(
                {
                    "mode": "client",
                    "connect": {"endpoints": [self.listen]},
                    "scouting": {"multicast": {"enabled": False}},
                    "transport": {"link": {"tls": {"root_ca_certificate": ca}}},
                }
            )
        cert, key = self.certs.pair(name)
        return _config(client_config(self.cell, certificate=cert, private_key=key, endpoint=self.listen))

    async def session(self, name: str, mode: str = "peer") -> Any:
        """A session of identity ``name`` that reached the daemon (it sees alice's liveliness token,
        which every connection may). ``peer`` as the Python client opens its session."""
        conf = self.config(name)
        conf.insert_json5("mode", json.dumps(mode))
        session = await _open(conf)
        try:
            await _wait_alive(session, f"{CELL}/alice/alive")
        except BaseException:
            session.close()
            raise
        return session


@asynccontextmanager
async def secure_daemon(certs: Certs, *, lease: bool) -> AsyncIterator[Secure]:
    """Serve the secure cell on a free loopback port; yield once an operator sees alice alive."""
    for attempt in range(3):
        listen = f"tls/127.0.0.1:{free_tcp_port()}"
        text = CELL_TEXT.format(lease=str(lease).lower(), listen=listen, start=START)
        cell = parse_cell(text, base_dir=certs.folder)
        daemon = Daemon(cell, listen=(listen,))
        stop = asyncio.Event()
        task = asyncio.create_task(daemon.run(stop))
        secure = Secure(daemon, cell, listen, certs)
        opening = asyncio.ensure_future(_open(secure.config("operator")))  # client mode: waits to connect
        await asyncio.wait({task, opening}, return_when=asyncio.FIRST_COMPLETED)
        if task.done():  # the daemon could not start (its port was taken meanwhile): another port
            with contextlib.suppress(BaseException):
                (await opening).close()
            if attempt == 2:
                task.result()
            continue
        probe = await opening
        try:
            await _wait_alive(probe, f"{CELL}/alice/alive")
            yield secure
        finally:
            probe.close()
            stop.set()
            await asyncio.wait_for(task, 20.0)
        return


async def _wait_alive(session: Any, key: str) -> None:
    loop = asyncio.get_running_loop()
    seen = asyncio.Event()
    sub = session.liveliness().declare_subscriber(
        key, lambda sample: loop.call_soon_threadsafe(seen.set), history=True
    )
    try:
        await asyncio.wait_for(seen.wait(), WAIT_S)
    finally:
        sub.undeclare()


class Samples:
    """Samples of one key received by a session's subscriber, awaitable from the loop."""

    def __init__(self, session: Any, key: str) -> None:
        loop = asyncio.get_running_loop()
        self.queue: asyncio.Queue[dict[str, Any]] = asyncio.Queue()
        self.seen = 0
        """How many samples arrived, taken from the queue or not."""

        def arrived(data: dict[str, Any]) -> None:
            self.seen += 1
            self.queue.put_nowait(data)

        def on_sample(sample: Any) -> None:
            data = json.loads(bytes(sample.payload.to_bytes()))
            loop.call_soon_threadsafe(arrived, data)

        self.sub = session.declare_subscriber(key, on_sample)

    async def next(self, timeout: float = WAIT_S) -> dict[str, Any]:
        return await asyncio.wait_for(self.queue.get(), timeout)

    async def matching(self, kind: str, timeout: float = WAIT_S) -> dict[str, Any]:
        """The next sample whose ``kind`` is ``kind`` (bounded: at most 1000 samples looked at)."""
        for _ in range(1000):
            data = await self.next(timeout)
            if data.get("kind") == kind:
                return data
        raise AssertionError(f"no {kind} event in 1000 samples")


def _close(*sessions: Any) -> None:
    for session in sessions:
        session.close()


async def test_mtls_lets_in_only_clients_with_a_certificate_of_the_cells_ca(certs: Certs) -> None:
    """With mutual TLS, a session without a client certificate, with one another CA signed (even
    naming ``operator``), or over plain TCP never reaches the daemon: its ``zenoh.open`` (client mode)
    fails. The operator's certificate, opened at the same time with the same timeout, gets in and
    sees alice's liveliness token (positive control)."""
    async with secure_daemon(certs, lease=False) as secure:
        plain = _config({"mode": "client", "connect": {"endpoints": [secure.listen.replace("tls/", "tcp/")]}})
        configs = {"no certificate": secure.config(None), "other CA": secure.config("stranger"), "tcp": plain}
        configs["operator"] = secure.config("operator")
        opened = await asyncio.gather(*(_open(c) for c in configs.values()), return_exceptions=True)
        outcome = dict(zip(configs, opened, strict=True))
        operator = outcome.pop("operator")
        assert not isinstance(operator, BaseException), f"the operator could not connect: {operator}"
        try:
            await _wait_alive(operator, f"{CELL}/alice/alive")
        finally:
            operator.close()
        for name, result in outcome.items():
            if not isinstance(result, BaseException):
                result.close()
            assert isinstance(result, zenoh.ZError), f"{name}: the session reached the daemon"


IDENTITIES = ("viewer", "operator", "overseer")
"""The identities the walk connects as: one that reads alice, one that commands her, one that
commands every robot (the cell's own rows)."""
ROUND_TRIP = ROBOT.service("cycle_stats")
"""A row every identity of the walk may ask: its reply, on the same link after what was sent before,
closes a check that something never arrived."""
ROWS = (*ROBOT_ENDPOINTS, *CELL_ENDPOINTS)


def _may(access: AccessOptions, identity: str, row: Endpoint, robot: str = "alice") -> bool:
    """Whether ``identity``'s grants reach ``row`` (of ``robot``, or of the cell), as ``Audience`` and
    cell/zenoh_options.py's ``Grant`` say it: the walk's expectation, from the row's audience."""
    grants = [grant for grant in access.grants if identity in grant.identities]
    read = {name for grant in grants for name in (*grant.read, *grant.command)}
    command = {name for grant in grants for name in grant.command}
    if row.audience is Audience.ANYONE:
        return True
    if row.audience is Audience.READER:
        return bool(read) if row.cell_level else bool(read & {robot, ALL_ROBOTS})
    if row.audience is Audience.CELL_READER:
        return ALL_ROBOTS in read
    if row.audience is Audience.COMMANDER:
        return ALL_ROBOTS in command if row.cell_level else bool(command & {robot, ALL_ROBOTS})
    assert row.audience is Audience.NOBODY, row.audience
    return False


def _key(row: Endpoint, goal_ids: Mapping[bool, str] | None = None) -> str:
    """``row``'s key for alice (or the cell), each ``*`` chunk made concrete: a goal's id (``goal_ids``
    by whether the row is the cell's), else a robot the cell lacks; ``**``: a key under it."""
    chunks = row.key(CellKeys(CELL) if row.cell_level else RobotKeys(CELL, "alice")).split("/")
    for i, chunk in enumerate(chunks):
        if chunk == "*":
            chunks[i] = (goal_ids or {}).get(row.cell_level, "none") if chunks[i - 1] == "goal" else "bob"
        elif chunk == "**":
            chunks[i] = "status"
    return "/".join(chunks)


def _bodies(target: Sequence[float], cell_goal_id: str = "none") -> dict[Endpoint, dict[str, Any]]:
    """A body for every row a client sends on, of the row's message type and valid: the daemon would
    act on it (no message type: the body the row's decoder takes, ``{}`` for none). A row whose
    message type has no body here fails the walk (KeyError) until it gets one."""
    point = {"positions": list(target), "time_from_start": 1.0}
    trajectory = TrajectoryGoalRequest(points=(point,))
    force = ForceModeRequest(
        task_frame=(0.0,) * 6,
        selection=(0, 0, 1, 0, 0, 0),
        wrench=(0.0, 0.0, -5.0, 0.0, 0.0, 0.0),
        limits=(0.1, 0.1, 0.1, 0.3, 0.3, 0.3),
    )
    requests: tuple[Any, ...] = (
        SetIoRequest("digital", 0, True),
        SetPayloadRequest(1.0),
        SpeedSliderRequest(0.1),
        DashboardRequest("power off"),
        SetTcpRequest((0.0, 0.0, 0.1, 0.0, 0.0, 0.0)),
        ToolVoltageRequest(24),
        force,
        CycleStatsRequest(),
    )
    by_type: dict[type, dict[str, Any]] = {type(r): request_body(r) for r in requests}
    by_type |= {
        MoveGoalMessage: move_goal_body(MoveGoalRequest(positions=tuple(target))),
        TrajectoryGoalMessage: trajectory_goal_body(trajectory),
        LinearGoalMessage: linear_goal_body(LinearGoalRequest(poses=((0.3, 0.1, 0.4, 3.1, 0.0, 0.0),))),
        TwistMessage: {"linear": [0.05, 0.0, 0.0], "angular": [0.0, 0.0, 0.0]},
        CellGoalMessage: cell_goal_body(CellGoalRequest({"alice": trajectory})),
    }
    by_row: dict[Endpoint, dict[str, Any]] = {  # a message type two rows share, or no type
        ROBOT.command_joint_position: {"positions": list(target)},
        ROBOT.command_joint_velocity: {"velocities": [0.1] * 6},
        ROBOT.command_freedrive: freedrive_body(True),
        ROBOT.lease: lease_body(LeaseRequest("show")),
        CELL_ROWS.goal_cancel: cancel_body(cell_goal_id),
    }
    sent = [row for row in ROWS if row.kind in (Kind.QUERYABLE, Kind.SUBSCRIBER)]
    return {
        row: by_row[row] if row in by_row else by_type[row.message] if row.message else {} for row in sent
    }


def test_the_walks_bodies_are_messages_the_daemon_would_act_on() -> None:
    """Each body the walk sends decodes, with the daemon's own decoder, to its row's message type:
    a command the access control drops is one the daemon would have carried out."""
    decoders: dict[Endpoint, Callable[[bytes | None], Any]] = {
        ROBOT.goal_move: decode_move_goal,
        ROBOT.goal_trajectory: decode_trajectory_goal,
        ROBOT.goal_linear: decode_linear_goal,
        ROBOT.goal_cancel: decode_cancel,
        ROBOT.lease: parse_request,
        ROBOT.command_joint_position: decode_stream_position,
        ROBOT.command_joint_velocity: decode_stream_velocity,
        ROBOT.command_twist: decode_twist,
        ROBOT.command_freedrive: decode_freedrive,
        CELL_ROWS.goal_cancel: decode_cell_cancel,
    }
    for row, body in _bodies(START).items():
        decode = row.service.decode if row.service is not None else decoders.get(row)
        if decode is None:
            assert row.message is None or row is CELL_ROWS.goal_trajectory, row.name  # decoded robot by robot
            continue
        decoded = decode(encode(body))
        assert row.message is None or isinstance(decoded, row.message), (row.name, decoded)


async def _walk(
    session: Any,
    rows: Sequence[Endpoint],
    bodies: Mapping[Endpoint, dict[str, Any]],
    goal_ids: Mapping[bool, str],
) -> dict[Endpoint, list[bytes]]:
    """Every reply's payload to one query on each queryable row, asked all at once (a dropped query
    ends at once with none, an unanswered one after ``WAIT_S``)."""
    asked = [row for row in rows if row.kind is Kind.QUERYABLE]
    replies = await asyncio.gather(*(_ask(session, _key(row, goal_ids), bodies[row]) for row in asked))
    return dict(zip(asked, replies, strict=True))


async def _ask(session: Any, key: str, body: dict[str, Any]) -> list[bytes]:
    """Every reply's payload (an error reply's too) to a ``get`` on ``key`` with ``body``, as it came:
    a queryable may answer in its own shape (``robot_description``: the URDF)."""
    loop = asyncio.get_running_loop()
    done: asyncio.Future[None] = loop.create_future()
    replies: list[bytes] = []

    def on_reply(reply: Any) -> None:
        sample = reply.ok if reply.ok is not None else reply.err
        loop.call_soon_threadsafe(replies.append, bytes(sample.payload.to_bytes()))

    def finish() -> None:
        if not done.done():
            done.set_result(None)

    handler = zenoh.handlers.Callback(on_reply, lambda: loop.call_soon_threadsafe(finish))
    session.get(key, handler, payload=encode(body), timeout=WAIT_S)
    await asyncio.wait_for(done, 2 * WAIT_S)
    return replies


def _answer(payload: bytes) -> Any:
    """A reply's message (None: not JSON)."""
    with contextlib.suppress(ValueError):
        return json.loads(payload)
    return None


def _wrong(access: AccessOptions, identity: str, walked: Mapping[Endpoint, list[bytes]]) -> list[str]:
    """The rows whose replies are not what ``identity``'s grants say: one answer where it may ask,
    none at all where it may not."""
    wrong = []
    for row, replies in walked.items():
        if not _may(access, identity, row):
            if replies:
                wrong.append(f"{identity} reached {row.name} ({row.audience}): {replies}")
        elif len(replies) != 1:
            wrong.append(f"{identity} was not answered on {row.name} ({row.audience}): {replies}")
    return wrong


def _unanswered(walks: Sequence[tuple[str, Mapping[Endpoint, list[bytes]]]]) -> list[str]:
    """The queryable rows some grant reaches that no identity's walk had answered: where nobody is
    answered, a query without a reply proves nothing (the rows for nobody excepted: no grant names
    them, the cell's default denies them)."""
    answered = {row for _, walk in walks for row, replies in walk.items() if replies}
    return [
        f"nobody was answered on {row.name} ({row.audience}): its refusals prove nothing"
        for row in ROWS
        if row.kind is Kind.QUERYABLE and row.audience is not Audience.NOBODY and row not in answered
    ]


@pytest.mark.usefixtures("rules_for")
async def test_each_endpoint_serves_exactly_the_grants_its_row_names(certs: Certs) -> None:
    """The endpoint table walked under access control (issues 16, 17, 31), each row's expectation
    from its audience and the cell file's grants: the viewer (``read: [alice]``), the operator
    (``command: [alice]``) and the overseer (``command: ["*"]``: the cell's goals) each ask every
    queryable row, all at once, with a valid body of the row's message type (the daemon would act on
    it); where the grants reach the row it is answered once, where not the query gets no reply at
    all, and every row some grant reaches is answered for someone. The viewer's puts on every
    commanding subscriber row (a valid command and a malformed one) never arrive: after a round
    trip on its link the daemon has counted no rejected command and alice has not moved, while the
    operator's identical malformed put is rejected (an event the viewer reads) and its move goal
    accepted. Each identity receives a sample of every publication the daemon serves that it may
    read (the events, goal messages and tf the walk makes happen) and none of the others.

    ``command_lease: false`` so the commands do not depend on the lease; the lease holder's token
    (the one row of kind token) is walked by the lease test below, and alive (liveliness, anyone's)
    by every session, which waits for it."""
    async with secure_daemon(certs, lease=False) as secure:
        runtime, access = secure.daemon.runtimes[0], secure.cell.zenoh.access
        assert access is not None
        sessions = {name: await secure.session(name) for name in IDENTITIES}
        viewer, operator, overseer = sessions.values()
        try:
            published = [row for row in ROWS if row.kind is Kind.PUBLICATION]
            samples = {
                (n, row): Samples(s, row.key(_keys(row))) for n, s in sessions.items() for row in published
            }
            before = (await samples["viewer", ROBOT.joint_states].next())["position"]
            target = [q + 0.3 for q in START]
            bodies = _bodies(target)
            commands = [
                row for row in ROWS if row.kind is Kind.SUBSCRIBER and not _may(access, "viewer", row)
            ]
            assert commands, "the viewer may put on every subscriber row"
            for row in commands:
                viewer.put(_key(row), encode(bodies[row]))
                viewer.put(_key(row), b"not json")
            walked = await _walk(viewer, [row for row in ROWS if not row.any_id], bodies, {})
            wrong = _wrong(access, "viewer", walked)
            assert wrong == [], "\n".join(wrong)
            assert walked[ROUND_TRIP], "no round trip after the viewer's puts"
            assert runtime.status.rejected_commands == 0
            after = (await samples["viewer", ROBOT.joint_states].next())["position"]
            assert after == pytest.approx(before, abs=1e-9), "alice moved on the viewer's command"

            key = _key(ROBOT.command_joint_position)
            await _wait_matched(operator, key)
            operator.put(key, b"not json")
            rejected = await samples["viewer", ROBOT.events].matching("command_rejected")
            assert rejected["key"] == key
            assert runtime.status.rejected_commands == 1
            goal_ids = {
                False: await _goal(
                    operator, ROBOT.goal_move, bodies, samples["operator", ROBOT.goal_messages]
                )
            }
            goal_ids[True] = await _goal(
                overseer, CELL_ROWS.goal_trajectory, bodies, samples["overseer", CELL_ROWS.goal_messages]
            )

            bodies = _bodies(target, goal_ids[True])
            walks = [("viewer", walked)]
            walks.append(("viewer", await _walk(viewer, [r for r in ROWS if r.any_id], bodies, goal_ids)))
            walks += [(name, await _walk(sessions[name], ROWS, bodies, goal_ids)) for name in IDENTITIES[1:]]
            wrong = [line for name, walk in walks for line in _wrong(access, name, walk)]
            wrong += _unanswered(walks)
            assert wrong == [], "\n".join(wrong)
            wrong = await _reads(secure, sessions, samples)
            assert wrong == [], "\n".join(wrong)
        finally:
            _close(*sessions.values())


def _keys(row: Endpoint) -> RobotKeys | CellKeys:
    return CellKeys(CELL) if row.cell_level else RobotKeys(CELL, "alice")


async def _goal(
    session: Any, row: Endpoint, bodies: Mapping[Endpoint, dict[str, Any]], messages: Samples
) -> str:
    """The id of ``row``'s goal ``session`` sends (its body from the walk), once it is accepted and
    its result published (what the results' rows then answer)."""
    accepted = await zenoh_ask(session, _key(row), bodies[row])
    assert [r.get("accepted") for r in accepted] == [True], (row.name, accepted)
    goal_id: str = accepted[0]["goal_id"]
    await _result(messages, goal_id)
    return goal_id


async def _reads(
    secure: Secure, sessions: Mapping[str, Any], samples: Mapping[tuple[str, Endpoint], Samples]
) -> list[str]:
    """What each identity received of each publication the daemon serves (its description of itself
    says which), against its grants: a sample where it may read; none where it may not, although
    another identity received one before a round trip on its link."""
    access = secure.cell.zenoh.access
    assert access is not None
    described = [_answer(r) for r in await _ask(sessions["operator"], CellKeys(CELL).daemon, {})]
    assert len(described) == 1, described
    serves = {*described[0]["keys"]["published"], *described[0]["robots"][0]["keys"]["published"]}
    watched = {(name, row): sub for (name, row), sub in samples.items() if row.key(_keys(row)) in serves}
    for (name, row), sub in watched.items():
        if _may(access, name, row) and not sub.seen:
            await sub.next()
    for name, session in sessions.items():  # what was sent to it before is in its queue now
        answered = [_answer(r) for r in await _ask(session, _key(ROUND_TRIP), {})]
        assert [r.get("ok") for r in answered] == [True], (name, answered)
    received = {row for (_, row), sub in watched.items() if sub.seen}
    wrong = []
    for (name, row), sub in watched.items():
        if not _may(access, name, row) and sub.seen:
            wrong.append(f"{name} received {row.name} ({row.audience}): {sub.queue.get_nowait()}")
        elif not _may(access, name, row) and row not in received:
            wrong.append(f"nobody received {row.name}: {name}'s silence proves nothing")
    return wrong


async def _wait_matched(session: Any, key: str) -> None:
    """Wait until a publisher of ``session`` on ``key`` has a subscriber (the daemon's): the
    operator's put is then not dropped for want of a route."""
    loop = asyncio.get_running_loop()
    matched = asyncio.Event()
    publisher = session.declare_publisher(key)
    listener = publisher.declare_matching_listener(
        lambda status: status.matching and loop.call_soon_threadsafe(matched.set)
    )
    try:
        if not publisher.matching_status.matching:
            await asyncio.wait_for(matched.wait(), WAIT_S)
    finally:
        listener.undeclare()
        publisher.undeclare()


@pytest.mark.usefixtures("rules_for")
async def test_stop_passes_for_every_connection_whatever_the_grants(certs: Certs) -> None:
    """A stop is never refused: the viewer (read only) stops the operator's running goal, and a
    ``visitor`` whose certificate the cell's CA signed but that no grant names may stop alice and the
    whole cell, while its reading and commanding get no reply."""
    async with secure_daemon(certs, lease=False) as secure:
        viewer, operator, visitor = [await secure.session(n) for n in ("viewer", "operator", "visitor")]
        try:
            goals = Samples(viewer, f"{CELL}/alice/goal/*/*")
            target = [q + 0.5 for q in START]
            accepted = await zenoh_ask(
                operator, f"{CELL}/alice/goal/move", {"positions": target, "duration": 20.0}
            )
            assert accepted[0].get("accepted") is True, accepted
            stopped = await zenoh_ask(viewer, f"{CELL}/alice/service/stop", {})
            assert [r.get("ok") for r in stopped] == [True], stopped
            result = await _result(goals, accepted[0]["goal_id"])
            assert result["status"] != "succeeded", result

            for key in ("alice/service/stop", "service/stop"):
                replies = await zenoh_ask(visitor, f"{CELL}/{key}", {})
                assert [r.get("ok") for r in replies] == [True], (key, replies)
            for key, body in (("alice/service/cycle_stats", {}), ("alice/goal/move", {"positions": target})):
                replies = await zenoh_ask(visitor, f"{CELL}/{key}", body, timeout=WAIT_S)
                assert replies == [], f"the visitor's {key} reached the daemon: {replies}"
        finally:
            _close(viewer, operator, visitor)


async def _result(goals: Samples, goal_id: str) -> dict[str, Any]:
    """The result message of goal ``goal_id`` among a goal-messages subscription's samples."""
    for _ in range(10000):
        message = await goals.next()
        if message.get("goal_id") == goal_id and "status" in message:
            return message
    raise AssertionError(f"no result of goal {goal_id}")


@pytest.mark.usefixtures("rules_for")
async def test_the_command_lease_works_through_access_control(certs: Certs) -> None:
    """With the lease on, the operator's grant carries everything the lease needs: its liveliness
    token reaches the daemon (the acquire is granted, which the daemon does only once it has seen the
    token), its goal with the lease token is accepted, and when its session ends the daemon sees the
    token go (a ``lost`` lease event the viewer reads). The viewer cannot even ask for the lease."""
    async with secure_daemon(certs, lease=True) as secure:
        viewer, operator = await secure.session("viewer"), await secure.session("operator")
        try:
            events = Samples(viewer, f"{CELL}/alice/events")
            asked = await zenoh_ask(viewer, f"{CELL}/alice/lease", {"action": "show"}, timeout=WAIT_S)
            assert asked == [], f"the viewer reached the lease: {asked}"
            grant = await acquire_lease(operator, CELL, "alice", holder="operator")
            target = [q + 0.1 for q in START]
            accepted = await zenoh_ask(
                operator, f"{CELL}/alice/goal/move", {"positions": target}, attachment=grant.token
            )
            assert accepted[0].get("accepted") is True, accepted
            acquired = await events.matching("lease")
            assert acquired["action"] == "acquired", acquired
        finally:
            operator.close()
        try:
            lost = await events.matching("lease")
            assert lost["action"] == "lost", lost
        finally:
            viewer.close()
