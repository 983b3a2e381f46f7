"""The cell goal (``<cell>/goal/trajectory``): trajectories on several robots that start together, or
not at all, and end as one signed result (issue 16, "Cell coordination"; contract sections 2 and 3).

Before it, nothing answered the cell goal's keys: starting two arms together meant two goals sent one
after the other, and one arm failing left the other moving. A daemon on the mock cell runs in the
test's loop; waits are on replies, results and samples, each bounded.
"""

from __future__ import annotations

import asyncio
import json
import types
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

import pytest

from tests.helpers import Stepped, free_tcp_port, swing_trajectory
from tests.integration.conftest import TWO_MOCKS, running_daemon
from urdaemon.cell import parse_cell
from urdaemon.client import CellGoalHandle, Client, send_cell_trajectory
from urdaemon.daemon import Daemon
from urdaemon.errors import GoalRejected, UrDaemonError
from urdaemon.publish import cell_goal, envelope, signing
from urdaemon.publish.keys import CellKeys
from urdaemon.runtime.cell_goals import CellGoals
from urdaemon.runtime.goal_events import put_signed

pytestmark = pytest.mark.timeout(120)

HOME = [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]
ALICE = [0.3, -1.4, 1.4, -1.5, -1.6, 0.2]
BOB = [-0.3, -1.7, 1.7, -1.6, -1.5, -0.2]
CELL = "testcell"


def _points(target: list[float], duration: float) -> list[dict[str, Any]]:
    return [{"positions": target, "time_from_start": duration}]


@asynccontextmanager
async def _cell(monkeypatch: pytest.MonkeyPatch) -> AsyncIterator[tuple[Daemon, Client, list[str]]]:
    """The mock cell, and every cell goal result the daemon publishes (its key, in order)."""
    published: list[str] = []

    def counted(node: Any, key: str, payload: bytes, attachment: bytes) -> None:
        published.append(key)
        put_signed(node, key, payload, attachment)

    monkeypatch.setattr("urdaemon.runtime.cell_goals.put_signed", counted)
    async with running_daemon(TWO_MOCKS) as (daemon, client):
        yield daemon, client, published


def _part(daemon: Daemon, robot: str) -> str | None:
    runtime = next(rt for rt in daemon.runtimes if rt.robot.name == robot)
    return runtime.controller.active_goal_id


async def _long_goal(client: Client, on_abort: str = "stop_all") -> CellGoalHandle:
    return await send_cell_trajectory(
        client, CELL, {"alice": _points(ALICE, 30.0), "bob": _points(BOB, 30.0)}, on_abort=on_abort
    )


async def test_both_parts_start_with_one_reply_and_the_cell_goal_succeeds_once(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    async with _cell(monkeypatch) as (daemon, client, published):
        goal = await send_cell_trajectory(
            client, CELL, {"alice": _points(ALICE, 0.7), "bob": _points(BOB, 0.8)}
        )
        assert set(goal.goals) == {"alice", "bob"}
        # both run from the one reply on (the reply is sent in the turn both parts started)
        assert _part(daemon, "alice") == goal.goals["alice"]
        assert _part(daemon, "bob") == goal.goals["bob"]
        assert len(goal.result_key) == 2 * signing.KEY_BYTES
        assert goal.duration == pytest.approx(0.8, abs=0.05)
        assert goal.goals["alice"].startswith("alice-")
        assert goal.goals["bob"].startswith("bob-")
        result = await goal.result(timeout=20.0)
        assert result["status"] == "succeeded", result
        assert result["reason"] == ""
        assert {r: m["status"] for r, m in result["robots"].items()} == {
            "alice": "succeeded",
            "bob": "succeeded",
        }
        assert result["robots"]["alice"]["goal_id"] == goal.goals["alice"]
        assert result["robots"]["alice"]["final_positions"] == pytest.approx(ALICE, abs=0.01)
        assert published == [CellKeys(CELL).goal_result(goal.goal_id)]
        # a late query is answered with the same result, signed
        late = await client.query_replies(CellKeys(CELL).goal_result(goal.goal_id))
        assert len(late) == 1
        assert late[0].key == CellKeys(CELL).goal_result(goal.goal_id)
        assert signing.verify(goal.result_key, late[0].key, late[0].payload, late[0].attachment)
        assert json.loads(late[0].payload)["status"] == "succeeded"


async def test_one_part_refused_starts_none(monkeypatch: pytest.MonkeyPatch) -> None:
    async with _cell(monkeypatch) as (daemon, client, published):
        before = list(daemon.runtimes[0].state.positions)
        far = [10.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]  # beyond bob's first joint's limit
        with pytest.raises(GoalRejected) as refused:
            await send_cell_trajectory(client, CELL, {"alice": _points(ALICE, 1.0), "bob": _points(far, 1.0)})
        assert refused.value.reason.startswith("bob: "), refused.value.reason
        for runtime in daemon.runtimes:
            assert runtime.controller.statistics().goals_accepted == 0, runtime.robot.name
            assert runtime.controller.mode == "idle"
        assert list(daemon.runtimes[0].state.positions) == before, "alice did not move"
        tokens = {name: await (await client.robot(name)).ensure_lease() for name in ("alice", "bob")}
        carol = await client.request(  # with the leases the client holds, as send_cell_trajectory sends
            CellKeys(CELL).goal_trajectory,
            {"robots": {"carol": {"points": _points(ALICE, 1.0)}}},
            attachment=json.dumps(tokens).encode(),
        )
        assert carol["accepted"] is False
        assert carol["reason"] == "carol: no robot 'carol' in cell 'testcell'; its robots: alice, bob"
        passthrough = {"points": _points(BOB, 1.0), "passthrough": True}
        with pytest.raises(GoalRejected, match=r"^bob: passthrough is not supported in a cell goal"):
            await send_cell_trajectory(client, CELL, {"alice": _points(ALICE, 1.0), "bob": passthrough})
        assert all(rt.controller.statistics().goals_accepted == 0 for rt in daemon.runtimes)
        assert published == []


async def test_alice_aborting_stops_bob_and_the_cell_goal_ends_aborted_once(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    async with _cell(monkeypatch) as (daemon, client, published):
        goal = await _long_goal(client)
        assert _part(daemon, "bob") == goal.goals["bob"]
        alice = await client.robot("alice")
        assert (await alice.stop())["ok"] is True  # alice's part ends aborted, "stop requested"
        result = await goal.result(timeout=20.0)
        assert result["status"] == "aborted", result
        assert result["reason"] == "robot 'alice' ended aborted: stop requested"
        assert result["robots"]["alice"]["status"] == "aborted"
        bob = result["robots"]["bob"]
        assert bob["status"] == "aborted"
        assert bob["reason"] == f"cell goal {goal.goal_id}: robot 'alice' ended aborted: stop requested"
        assert _part(daemon, "bob") is None
        assert published == [CellKeys(CELL).goal_result(goal.goal_id)], "one result, once"


async def test_continue_leaves_bob_running(monkeypatch: pytest.MonkeyPatch) -> None:
    async with _cell(monkeypatch) as (daemon, client, published):
        goal = await _long_goal(client, on_abort="continue")
        alice = await client.robot("alice")
        await alice.stop()
        bob = await client.robot("bob")
        status = await bob.status()  # a status published after alice's stop was handled
        assert status["active_goal"] == goal.goals["bob"], status
        assert _part(daemon, "bob") == goal.goals["bob"]
        assert published == [], "no cell result while bob's part runs"
        await bob.stop()
        result = await goal.result(timeout=20.0)
        assert result["status"] == "aborted"
        assert result["robots"]["bob"]["reason"] == "stop requested"
        assert published == [CellKeys(CELL).goal_result(goal.goal_id)]


async def test_cancel_cancels_every_part(monkeypatch: pytest.MonkeyPatch) -> None:
    async with _cell(monkeypatch) as (daemon, client, published):
        assert all(rt.controller.active_goal_id is None for rt in daemon.runtimes)
        goal = await _long_goal(client)
        reply = await goal.cancel()
        assert reply["canceled"] is True, reply
        result = await goal.result(timeout=20.0)
        assert result["status"] == "canceled"
        assert {r: m["status"] for r, m in result["robots"].items()} == {
            "alice": "canceled",
            "bob": "canceled",
        }
        again = await goal.cancel()
        assert again["canceled"] is False
        assert again["reason"] == f"cell goal {goal.goal_id} is not active"
        assert published == [CellKeys(CELL).goal_result(goal.goal_id)]


async def test_a_forged_cell_result_is_never_returned(monkeypatch: pytest.MonkeyPatch) -> None:
    async with _cell(monkeypatch) as (_, client, _published):
        goal = await _long_goal(client)
        key = CellKeys(CELL).goal_result(goal.goal_id)
        watch = client.subscribe(key)
        # anyone on the network can publish on the key (the lease guards commands, not state); only
        # the daemon can sign with the key the accepting reply gave this client
        forged = {"v": 1, "goal_id": goal.goal_id, "status": "succeeded", "robots": {}, "reason": "forged"}
        client.session.put(key, json.dumps(forged).encode(), attachment=b"0" * 64)
        client.session.put(key, json.dumps(forged).encode())
        for _ in range(2):
            seen = await watch.get_json(timeout=10.0)  # it reached this client's session
            assert seen["reason"] == "forged"
        await goal.cancel()
        result = await goal.result(timeout=20.0)
        assert result["status"] == "canceled", result
        assert goal.ignored == 2


async def test_bad_requests_are_refused_naming_what_is_wrong(monkeypatch: pytest.MonkeyPatch) -> None:
    async with _cell(monkeypatch) as (_, client, _published):
        key = CellKeys(CELL).goal_trajectory
        # sent with a lease token, as a client sends them: what is wrong is the body
        tokens = json.dumps({"alice": await (await client.robot("alice")).ensure_lease()}).encode()
        cases = {
            b"[]": "cell goal: not valid JSON: expected a JSON object",
            b'{"robots": {}}': "cell goal.robots: expected an object naming at least one",
            b'{"robots": {"alice": {"points": []}}, "on_abort": "maybe"}': "cell goal.on_abort",
            b'{"robots": {"alice": {"points": []}}, "speed": 1}': "cell goal: unknown field(s) speed",
        }
        for body, reason in cases.items():
            answer = json.loads((await _ask(client, key, body, tokens))[0])
            assert answer["accepted"] is False
            assert answer["reason"].startswith(reason), (body, answer)
        cancel = json.loads((await _ask(client, CellKeys(CELL).goal_cancel, b"{}"))[0])
        assert cancel == {
            "v": 1,
            "canceled": False,
            "reason": "cell cancel.goal_id: required (the cell goal's id)",
        }


async def _ask(client: Client, key: str, body: bytes, attachment: bytes | None = None) -> list[bytes]:
    def ask() -> list[bytes]:
        replies = client.session.get(key, payload=body, attachment=attachment, timeout=10.0)
        return [r.ok.payload.to_bytes() for r in replies if r.ok]

    return await asyncio.get_running_loop().run_in_executor(None, ask)


def _record_planner_marks(monkeypatch: pytest.MonkeyPatch) -> list[bool]:
    """Every value the cell goal planner's busy mark (``CellGoals._planning``) is set to, in order."""
    marks: list[bool] = []

    def mark(self: CellGoals, value: bool) -> None:
        marks.append(value)
        self.__dict__["_planning_recorded"] = value

    def busy(self: CellGoals) -> bool:
        return bool(self.__dict__["_planning_recorded"])

    monkeypatch.setattr(CellGoals, "_planning", property(busy, mark), raising=False)
    return marks


async def test_a_session_without_leases_never_makes_the_cell_planner_busy(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Review 16, M3 (repro test_r_cellbusy): a session holding no lease sent 2 MiB cell goals back to
    back; the tokens were checked only once the request was split, so the planner stayed busy and the
    lease holder's cell goals were refused "busy" (5 of 5). Now a goal whose tokens could never let it
    start is refused at once naming what is wrong with them, before the planner is marked busy."""
    marks = _record_planner_marks(monkeypatch)
    async with _cell(monkeypatch) as (daemon, client, _published):
        await (await client.robot("alice")).ensure_lease()
        stranger = await Client.connect(daemon.listen_endpoints[0])
        try:
            body = json.dumps({"robots": {"alice": swing_trajectory(2500, HOME)}}).encode()
            assert len(body) > 100_000  # many turns of the loop to split and plan
            none = "lease: a cell goal needs each of its robots' command lease tokens as its attachment"
            wrong = {
                None: none,
                b"{}": none,
                b'{"alice": "' + b"0" * 32 + b'"}': "alice: lease: robot 'alice' is held by ",
                '{"alice": "\u00e9"}'.encode(): "alice: lease: robot 'alice' is held by ",
                b'{"bob": "' + b"0" * 32 + b'"}': "bob: lease: robot 'bob' needs its command lease",
                b'{"carol": "' + b"0" * 32 + b'"}': "carol: no robot 'carol' in cell 'testcell'",
                b'["alice"]': "lease tokens: the attachment must be a JSON object",
                b"x" * (envelope.SMALL_MESSAGE_BYTES + 1): "lease tokens: attachment of 16385 bytes exceeds",
            }
            key = CellKeys(CELL).goal_trajectory
            for attachment, reason in [item for item in wrong.items() for _ in range(3)]:  # back to back
                answer = json.loads((await _ask(stranger, key, body, attachment))[0])
                assert answer["accepted"] is False
                assert answer["reason"].startswith(reason), (reason, answer)
            assert True not in marks, marks  # never busy for them
            goal = await send_cell_trajectory(client, CELL, {"alice": _points(ALICE, 30.0)})
            assert marks.count(True) == 1  # the holder's goal was planned
            assert (await goal.cancel())["canceled"] is True
        finally:
            await stranger.close()


async def test_every_robot_needs_its_lease_token(monkeypatch: pytest.MonkeyPatch) -> None:
    """The attachment names each robot's lease token; a robot whose token is missing or not its
    holder's refuses the whole cell goal (none starts); a cancel needs no token (it only stops)."""
    async with _cell(monkeypatch) as (daemon, client, published):
        alice_token = await (await client.robot("alice")).ensure_lease()
        other = await Client.connect(daemon.listen_endpoints[0])
        try:
            await (await other.robot("bob")).ensure_lease()  # another client holds bob's lease
            body = {
                "robots": {"alice": {"points": _points(ALICE, 30.0)}, "bob": {"points": _points(BOB, 30.0)}}
            }
            only_alice = json.dumps({"alice": alice_token}).encode()
            reply = await client.request(CellKeys(CELL).goal_trajectory, body, attachment=only_alice)
            assert reply["accepted"] is False
            assert reply["reason"].startswith("bob: lease: robot 'bob' is held by "), reply
            assert all(rt.controller.statistics().goals_accepted == 0 for rt in daemon.runtimes)
            forged = json.dumps({"alice": alice_token, "bob": "0" * 32}).encode()
            reply = await client.request(CellKeys(CELL).goal_trajectory, body, attachment=forged)
            assert reply["reason"].startswith("bob: lease: robot 'bob' is held by "), reply
            # bob's holder starts it (and takes alice's lease over for it)
            await (await other.robot("alice")).take_over("the cell goal needs both")
            goal = await _long_goal(other)
            # a client that holds neither lease cancels it: a cancel only makes the robots stop
            canceled = await client.request(CellKeys(CELL).goal_cancel, {"goal_id": goal.goal_id})
            assert (canceled["canceled"], canceled["goal_id"]) == (True, goal.goal_id), canceled
            assert (await goal.result(timeout=20.0))["status"] == "canceled"
        finally:
            await other.close()
        assert published == [CellKeys(CELL).goal_result(goal.goal_id)]


async def test_a_cell_goal_being_planned_at_shutdown_is_answered_once_and_starts_nothing() -> None:
    """Two 2 500-point parts take many turns of the loop to plan; the daemon stops meanwhile."""
    listen = f"tcp/127.0.0.1:{free_tcp_port()}"
    daemon = Daemon(parse_cell(TWO_MOCKS), listen=(listen,))
    stop = asyncio.Event()
    served = asyncio.create_task(daemon.run(stop))
    try:
        client = await Client.connect(listen, timeout=20.0)
        try:
            tokens = {
                name: await (await client.robot(name, timeout=10.0)).ensure_lease()
                for name in ("alice", "bob")
            }
            body = {"robots": {name: swing_trajectory(2500, HOME) for name in tokens}}
            asked = asyncio.create_task(
                client.query_replies(
                    CellKeys(CELL).goal_trajectory, body, attachment=json.dumps(tokens).encode(), timeout=20.0
                )
            )
            # checked on every turn of the loop, so planning's many turns cannot pass unseen (checked
            # once per joint-state sample, the whole planning fitted between two under load)
            async with asyncio.timeout(20.0):
                for _ in range(10_000_000):
                    if all(rt.motion.planning is not None for rt in daemon.runtimes) or asked.done():
                        break
                    await asyncio.sleep(0)
            assert not asked.done(), asked.result()
            stop.set()
            replies = await asked
        finally:
            await client.close()
    finally:
        stop.set()
        await asyncio.wait_for(served, 20.0)
    assert [json.loads(r.payload) for r in replies] == [
        {"v": 1, "accepted": False, "reason": "daemon shutting down"}
    ]
    assert all(rt.controller.statistics().goals_accepted == 0 for rt in daemon.runtimes)


def test_a_big_cell_goal_is_split_a_bounded_piece_at_a_time() -> None:
    """The request is split into its parts by counting brackets, at most ``_SCAN_TOKENS`` a step (a
    2 MiB request parsed whole would hold the loop for tens of milliseconds); brackets inside texts
    do not count, and each part is handed on as sent."""
    alice = swing_trajectory(2500, HOME)
    bob = {"points": _points(BOB, 1.0), "joint_names": ["a}]", 'b\\"{['] + [f"j{i}" for i in range(4)]}
    text = json.dumps({"robots": {"alice": alice, "bob": bob}, "on_abort": "continue"}, indent=1).encode()
    decoder = Stepped(cell_goal.CellGoalDecoder(text).steps())
    steps = 1
    while decoder.step():
        steps += 1
    split = decoder.result()
    assert split.on_abort == "continue"
    assert {name: json.loads(bytes(part)) for name, part in split.robots.items()} == {
        "alice": alice,
        "bob": bob,
    }
    brackets = 8 * 2500  # each point: an object and three lists
    assert steps >= brackets // cell_goal._SCAN_TOKENS, steps


@pytest.mark.parametrize("bad_key", ["", "AB" * 32, "0" * 62, None])
async def test_a_reply_without_a_valid_result_key_is_an_error_and_the_goal_is_canceled(
    monkeypatch: pytest.MonkeyPatch, bad_key: str | None
) -> None:
    """Contract 16b, decision 6: the client took ``result_key`` as ``str(reply.get("result_key") or
    "")``, so a reply without one gave an empty key, and an HMAC under an empty key is one anybody can
    make. Now such a reply is an error naming ``result_key``, and the goal it accepted (which nobody
    can follow) is canceled."""
    fake = types.SimpleNamespace(new_key=lambda: bad_key, sign=lambda *_: b"0" * 64)
    monkeypatch.setattr("urdaemon.runtime.cell_goals.signing", fake)
    async with _cell(monkeypatch) as (daemon, client, _published):
        with pytest.raises(UrDaemonError, match=r"without a valid 'result_key' \(64 hex characters\)"):
            await _long_goal(client)
        for runtime in daemon.runtimes:
            assert runtime.controller.statistics().goals_accepted == 1, runtime.robot.name
            assert runtime.controller.active_goal_id is None, runtime.robot.name  # canceled


async def test_a_signed_message_that_is_no_result_is_not_taken(monkeypatch: pytest.MonkeyPatch) -> None:
    """Contract 16b, decision 6: the client took as the result any signed dict with the goal's id; a
    result must carry a ``status`` too (signed with the goal's key for the result key: what only the
    daemon or this client could make)."""
    async with _cell(monkeypatch) as (_, client, _published):
        goal = await _long_goal(client)
        key = CellKeys(CELL).goal_result(goal.goal_id)
        watch = client.subscribe(key)
        for body in ({"goal_id": goal.goal_id, "robots": {}}, [goal.goal_id], "succeeded"):
            payload = json.dumps(body).encode()
            client.session.put(key, payload, attachment=signing.sign(goal.result_key, key, payload))
            assert (await watch.get_sample(timeout=10.0)).payload == payload  # it reached this client
        await goal.cancel()
        result = await goal.result(timeout=20.0)
        assert result["status"] == "canceled", result
        assert goal.ignored == 3
