"""Transport security end to end: a daemon on a ``tls/`` loopback endpoint with mutual TLS and access
control from its cell file, reached by raw Zenoh sessions made from ``client_config`` (no urdaemon
client code on the far side, as an intruder would have none).

Certificates come from trustme (a throw-away CA per module): the daemon's for 127.0.0.1, clients
``operator`` (commands alice), ``viewer`` (reads alice), ``visitor`` (signed by the CA, granted
nothing) and ``stranger`` (signed by another CA).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
import trustme
import zenoh

from tests.helpers import acquire_lease, free_tcp_port, zenoh_ask
from urdaemon.cell import Cell, parse_cell
from urdaemon.daemon import Daemon
from urdaemon.publish import session_config
from urdaemon.publish.session_config import configure_daemon
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
    grants:
      - {{identities: [viewer], read: [alice]}}
      - {{identities: [operator], command: [alice]}}
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

        def on_sample(sample: Any) -> None:
            data = json.loads(bytes(sample.payload.to_bytes()))
            loop.call_soon_threadsafe(self.queue.put_nowait, data)

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


@pytest.mark.usefixtures("rules_for")
async def test_a_reader_subscribes_but_its_commands_never_reach_the_daemon(certs: Certs) -> None:
    """Reproduction (issue 16): any session could command any robot. With access control the viewer
    (granted ``read: [alice]``) receives alice's joint states, but its move goal, trajectory goal,
    cancel and service queries get no reply at all and its stream puts (a valid target and a
    malformed one) never arrive (issue 17: nor its linear goal, set_tcp, or twist puts): after a
    round trip on the same link (cycle_stats, which it may ask)
    the daemon has counted no rejected command and alice has not moved. The operator's identical
    malformed put is rejected and its move goal accepted (positive control). ``command_lease:
    false`` so the operator's commands do not depend on the lease (tested on its own below)."""
    async with secure_daemon(certs, lease=False) as secure:
        runtime = secure.daemon.runtimes[0]
        viewer, operator = await secure.session("viewer"), await secure.session("operator")
        try:
            states = Samples(viewer, f"{CELL}/alice/joint_states")
            before = (await states.next())["position"]
            target = [q + 0.3 for q in START]
            for key, body in (
                ("goal/move", {"positions": target}),
                ("goal/trajectory", {"points": [{"positions": target, "time_from_start": 2.0}]}),
                ("goal/cancel", {}),
                ("goal/linear", {"poses": [[0.3, 0.1, 0.4, 3.1, 0.0, 0.0]]}),  # issue 17's goal
                ("service/set_speed_slider", {"fraction": 0.1}),
                ("service/set_tcp", {"pose": [0.0, 0.0, 0.1, 0.0, 0.0, 0.0]}),
                ("service/dashboard", {"command": "power off"}),
            ):
                replies = await zenoh_ask(viewer, f"{CELL}/alice/{key}", body, timeout=WAIT_S)
                assert replies == [], f"the viewer's {key} reached the daemon: {replies}"
            viewer.put(f"{CELL}/alice/command/joint_position", json.dumps({"positions": target}))
            viewer.put(f"{CELL}/alice/command/joint_velocity", json.dumps({"velocities": [0.1] * 6}))
            viewer.put(f"{CELL}/alice/command/joint_position", b"not json")
            viewer.put(
                f"{CELL}/alice/command/twist", json.dumps({"linear": [0.05, 0, 0], "angular": [0, 0, 0]})
            )
            viewer.put(f"{CELL}/alice/command/twist", b"not json")
            stats = await zenoh_ask(viewer, f"{CELL}/alice/service/cycle_stats", {})
            assert [r.get("ok") for r in stats] == [True], stats
            assert runtime.status.rejected_commands == 0
            after = (await states.next())["position"]
            assert after == pytest.approx(before, abs=1e-9), "alice moved on the viewer's command"

            events = Samples(operator, f"{CELL}/alice/events")
            await _wait_matched(operator, f"{CELL}/alice/command/joint_position")
            operator.put(f"{CELL}/alice/command/joint_position", b"not json")
            rejected = await events.matching("command_rejected")
            assert rejected["key"] == f"{CELL}/alice/command/joint_position"
            assert runtime.status.rejected_commands == 1
            accepted = await zenoh_ask(operator, f"{CELL}/alice/goal/move", {"positions": target})
            assert [r.get("accepted") for r in accepted] == [True], accepted
        finally:
            _close(viewer, operator)


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
