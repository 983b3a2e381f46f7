"""Issue 32: ``cancel`` from anywhere (a second client cancels the goal of the lease holder: a cancel
only stops the robot), the audit log (an accepted goal, a lease refusal and a stop from a non-holder,
in the rotating file and on ``<cell>/audit``), a result query for an unknown goal id answered at once
with an error naming it, and a free lease that eight acquires without a token cannot block.

In-process daemon on a loopback port the OS gave; clients are urdaemon's own or bare Zenoh sessions.
"""

from __future__ import annotations

import asyncio
import json
import secrets
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

import pytest

from tests.helpers import acquire_lease, free_tcp_port, zenoh_ask
from tests.integration.conftest import ROOT, TWO_MOCKS
from tests.integration.test_lease import open_session
from urdaemon.cell import parse_cell
from urdaemon.cell.config import Cell
from urdaemon.client import Client
from urdaemon.daemon import Daemon
from urdaemon.runtime.audit import AuditOptions

pytestmark = pytest.mark.timeout(120)

TARGET = [0.3, -1.4, 1.4, -1.5, -1.6, 0.2]
WAIT_S = 20.0
"""Bound of every wait for a message (a busy machine is slow, never this slow)."""


@asynccontextmanager
async def served(
    audit: AuditOptions | None = None, cell: Cell | None = None
) -> AsyncIterator[tuple[Daemon, str]]:
    """A daemon serving ``cell`` (default: the two mocks) in this loop; yields it and its endpoint once
    alice's lease answers."""
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    cell = cell if cell is not None else parse_cell(TWO_MOCKS, base_dir=ROOT / "configs")
    daemon = Daemon(cell, listen=(endpoint,), audit=audit)
    stop = asyncio.Event()
    task = asyncio.create_task(daemon.run(stop))
    for _ in range(1000):
        if daemon.node is not None or task.done():
            break
        await asyncio.sleep(0)
    if task.done():
        task.result()
    probe = await asyncio.to_thread(open_session, endpoint)
    try:
        (shown,) = await zenoh_ask(probe, "testcell/alice/lease", {"action": "show"}, timeout=WAIT_S)
        assert shown["ok"] is True, shown
        yield daemon, endpoint
    finally:
        probe.close()
        stop.set()
        await asyncio.wait_for(task, 20.0)


class AuditFeed:
    """``<cell>/audit`` entries as they are published, decoded."""

    def __init__(self, session: Any) -> None:
        loop = asyncio.get_running_loop()
        self.queue: asyncio.Queue[dict[str, Any]] = asyncio.Queue()

        def on_sample(sample: Any) -> None:
            entry = json.loads(bytes(sample.payload.to_bytes()))
            loop.call_soon_threadsafe(self.queue.put_nowait, entry)

        self._sub = session.declare_subscriber("testcell/audit", on_sample)

    async def next(self, match: Callable[[dict[str, Any]], bool]) -> dict[str, Any]:
        async with asyncio.timeout(WAIT_S):
            for _ in range(10_000):
                entry = await self.queue.get()
                if match(entry):
                    return entry
        raise AssertionError("no such audit entry")


def on(key: str) -> Callable[[dict[str, Any]], bool]:
    return lambda entry: entry.get("key") == key


async def test_cancel_from_a_second_client_stops_the_holders_goal() -> None:
    """Reproduction before: ``urdaemon cancel alice`` from a second terminal while ``urdaemon move``
    held the lease raised ``LeaseHeld`` (the cancel acquired the lease first, and the daemon refused a
    cancel without the holder's token)."""
    async with (
        served() as (daemon, endpoint),
        await Client.connect(endpoint, holder="mover") as mover,
        await Client.connect(endpoint, holder="bystander") as bystander,
    ):
        alice = await mover.robot("alice")
        goal = await alice.move(TARGET, duration=30.0)
        other = await bystander.robot("alice")
        reply = await other.cancel()
        assert reply["canceled"] is True, reply
        assert reply["goal_id"] == goal.goal_id
        result = await goal.result(timeout=WAIT_S)
        assert result["status"] == "canceled", result
        assert other.lease.token is None, "the cancel took no lease"
        assert (await other.lease_info() or {}).get("holder") == "mover", "the holder keeps it"
        runtime = next(r for r in daemon.runtimes if r.robot.name == "alice")
        assert runtime.controller.mode in ("idle", "stopping"), runtime.controller.mode
        # what stays refused names the CLI's ways out, not a key
        refused = await bystander.request("testcell/alice/goal/move", {"positions": TARGET, "duration": 30.0})
        assert refused["accepted"] is False
        assert "`urdaemon stop alice`" in refused["reason"], refused
        assert "`urdaemon lease alice --take-over REASON`" in refused["reason"], refused
        assert "testcell/alice/lease" not in refused["reason"], refused


async def test_the_audit_log_has_an_accepted_goal_a_lease_refusal_and_a_stop_from_a_non_holder(
    tmp_path: Path,
) -> None:
    path = tmp_path / "logs" / "audit.log"
    async with served(AuditOptions(file=path)) as (_, endpoint):
        holder, stranger = open_session(endpoint), open_session(endpoint)
        try:
            feed = AuditFeed(stranger)
            grant = await acquire_lease(holder, "testcell", "alice", holder="the holder")
            acquired = await feed.next(on("testcell/alice/lease"))
            assert acquired["outcome"] == "accepted", acquired
            assert acquired["request"] == {"action": "acquire", "holder": "the holder"}, acquired
            body = {"positions": TARGET, "duration": 30.0}
            (accepted,) = await zenoh_ask(holder, "testcell/alice/goal/move", body, attachment=grant.token)
            assert accepted["accepted"] is True, accepted
            entry = await feed.next(on("testcell/alice/goal/move"))
            assert entry["outcome"] == "accepted", entry
            assert entry["goal_id"] == accepted["goal_id"]
            assert entry["who"]["lease_holder"] is True
            assert entry["who"]["holder"] == "the holder"
            assert entry["who"]["fingerprint"] == grant.reply["lease"]["fingerprint"]
            (refused,) = await zenoh_ask(stranger, "testcell/alice/goal/move", body)
            assert refused["accepted"] is False
            entry = await feed.next(on("testcell/alice/goal/move"))
            assert (entry["outcome"], entry["robot"]) == ("refused", "alice"), entry
            assert entry["reason"] == refused["reason"]
            assert entry["who"]["lease_holder"] is False
            assert entry["who"]["lease_token"] == "none"
            assert entry["who"]["lease"]["holder"] == "the holder"
            (stopped,) = await zenoh_ask(stranger, "testcell/alice/service/stop", None)
            assert stopped["ok"] is True
            entry = await feed.next(on("testcell/alice/service/stop"))
            assert entry["outcome"] == "accepted", entry
            assert entry["who"]["lease_holder"] is False
            (cell_stop,) = await zenoh_ask(stranger, "testcell/service/stop", None)
            assert cell_stop["ok"] is True
            entry = await feed.next(on("testcell/service/stop"))
            assert (entry["outcome"], entry["robot"]) == ("accepted", None), entry
        finally:
            holder.close()
            stranger.close()
    lines = [json.loads(line) for line in path.read_text(encoding="utf-8").splitlines()]
    assert [line["seq"] for line in lines] == sorted(line["seq"] for line in lines)
    requests = [(line.get("key"), line.get("outcome")) for line in lines if line["event"] == "request"]
    for expected in (
        ("testcell/alice/goal/move", "accepted"),
        ("testcell/alice/goal/move", "refused"),
        ("testcell/alice/service/stop", "accepted"),
        ("testcell/service/stop", "accepted"),
    ):
        assert expected in requests, (expected, requests)
    connected = [line for line in lines if line["event"] == "connected"]
    assert connected, "each session's link is audited"
    assert all(line["peer"].startswith("tcp/127.0.0.1:") for line in connected), connected


async def test_the_cell_files_audit_key_names_the_rotating_file(tmp_path: Path) -> None:
    """``audit: {file, max_bytes, backups}`` in the cell file: relative to the cell file's folder, its
    folder made at start; a stop from any session is written there."""
    text = TWO_MOCKS.replace("cell: testcell", "cell: testcell\naudit: {file: logs/audit.log, backups: 2}")
    cell = parse_cell(text, base_dir=tmp_path)
    assert cell.audit is not None
    assert (cell.audit.file, cell.audit.backups) == (str((tmp_path / "logs" / "audit.log").resolve()), 2)
    async with served(cell=cell) as (_, endpoint):
        session = await asyncio.to_thread(open_session, endpoint)
        try:
            (stopped,) = await zenoh_ask(session, "testcell/service/stop", None, timeout=WAIT_S)
            assert stopped["ok"] is True, stopped
        finally:
            session.close()
    lines = [json.loads(line) for line in (tmp_path / "logs" / "audit.log").read_text().splitlines()]
    assert ("testcell/service/stop", "accepted") in [(line.get("key"), line.get("outcome")) for line in lines]


@pytest.mark.parametrize(
    ("section", "says"),
    [
        ("audit: {file: .}", "is a directory"),
        ("audit: {file: a.log, max_bytes: 10}", "greater than or equal to 4096"),
        ("audit: {file: a.log, backups: -1}", "greater than or equal to 0"),
        ("audit: {file: a.log, rotate: 1}", "rotate"),
    ],
)
def test_a_bad_audit_key_is_refused_naming_it(tmp_path: Path, section: str, says: str) -> None:
    from urdaemon.errors import ConfigError

    with pytest.raises(ConfigError, match=says) as caught:
        parse_cell(TWO_MOCKS.replace("cell: testcell", f"cell: testcell\n{section}"), base_dir=tmp_path)
    assert "audit" in str(caught.value)


async def test_a_result_query_for_an_unknown_goal_id_is_answered_at_once_naming_it() -> None:
    async with served() as (_, endpoint):
        session = open_session(endpoint)
        try:
            for key, named in (
                (
                    "testcell/alice/goal/alice-nosuch-1/result",
                    "'alice-nosuch-1': robot 'alice' has no such goal",
                ),
                ("testcell/goal/cell-nosuch/result", "cell goal 'cell-nosuch': no such goal"),
            ):
                (reply,) = await zenoh_ask(session, key, timeout=60.0)
                assert "error" in reply, reply  # an error reply: it can never pass for a result
                assert named in reply["error"], reply
        finally:
            session.close()
        async with await Client.connect(endpoint) as client:
            with pytest.raises(Exception, match="alice-nosuch-2"):
                await client.request("testcell/alice/goal/alice-nosuch-2/result", timeout=60.0)


async def test_acquires_whose_token_never_appears_cannot_keep_a_free_lease_from_others(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The probe's finding: eight acquires without a liveliness token filled the waiting slots, and
    every other client's acquire was refused ("busy"), 10 tries of 10, reported as ``LeaseHeld``."""
    from urdaemon.runtime import lease_keeper

    monkeypatch.setattr(lease_keeper, "LEASE_BIND_TIMEOUT_S", 60.0)  # they would wait a minute
    async with served() as (_, endpoint):
        attacker, honest = open_session(endpoint), open_session(endpoint)
        try:
            asks = []
            for _ in range(lease_keeper.MAX_WAITING):
                body = {"action": "acquire", "session": secrets.token_hex(16), "holder": "blocker"}
                asks.append(
                    asyncio.create_task(zenoh_ask(attacker, "testcell/alice/lease", body, timeout=90.0))
                )
                # answered after the acquire before it on the same key and session: it waits now
                (shown,) = await zenoh_ask(attacker, "testcell/alice/lease", {"action": "show"})
                assert shown["lease"] is None
            assert not any(task.done() for task in asks), "every blocker waits for its token"
            for _ in range(3):  # a raw client with its token declared: granted every time
                grant = await acquire_lease(honest, "testcell", "alice", holder="honest")
                (released,) = await zenoh_ask(
                    honest, "testcell/alice/lease", {"action": "release"}, attachment=grant.token
                )
                assert released["ok"] is True
                grant.liveliness.undeclare()
            async with await Client.connect(endpoint, holder="client") as client:
                robot = await client.robot("alice")
                assert await robot.ensure_lease(), "urdaemon's client is granted too"
            for task in asks:
                task.cancel()
        finally:
            attacker.close()
            honest.close()
