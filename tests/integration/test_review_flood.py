"""Review of issue 13: a flood of messages, each within its size limit, cannot pile up on the loop.

A cell of two mock robots in this test's own event loop. To make a burst arrive all at once, the
test holds the loop (as a slow cycle would) while Zenoh's threads deliver it, waiting on replies or
samples counted on Zenoh's threads, never on a clock; then it lets the loop go and counts what
reached the robot's handler. Bob's goal runs meanwhile and must succeed.
"""

from __future__ import annotations

import asyncio
import json
import threading
import time
from collections.abc import AsyncIterator, Callable
from types import ModuleType
from typing import Any

import pytest
import zenoh

from tests.helpers import client_lease
from tests.integration.conftest import TWO_MOCKS, running_daemon
from urdaemon.client import Client
from urdaemon.daemon import Daemon
from urdaemon.publish import envelope, move_goal, stream_commands
from urdaemon.publish.admission import MAX_IN_FLIGHT

pytestmark = pytest.mark.timeout(120)

HOME = [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]
TARGET = [0.2, -1.4, 1.4, -1.5, -1.6, 0.1]
BURST = 40
HOLD_S = 20.0  # the most the loop is held waiting for a burst to be delivered


@pytest.fixture
async def cell() -> AsyncIterator[tuple[Daemon, Client]]:
    async with running_daemon(TWO_MOCKS) as pair:
        yield pair


def _counting(monkeypatch: pytest.MonkeyPatch, decoders: ModuleType, name: str, seen: list[bytes]) -> None:
    """Record every payload the robots' handlers pass to ``<decoders>.<name>`` (then decode as before)."""
    original: Callable[[bytes | None], Any] = getattr(decoders, name)

    def counted(payload: bytes | None) -> Any:
        seen.append(b"" if payload is None else bytes(payload))
        return original(payload)

    monkeypatch.setattr(decoders, name, counted)


class _Replies:
    """Replies to raw Zenoh gets, gathered on Zenoh's threads; ``wait`` for ``n`` of them."""

    def __init__(self) -> None:
        self.payloads: list[dict[str, Any]] = []
        self._lock = threading.Lock()
        self._enough = threading.Event()
        self._want = 1 << 30

    def on_reply(self, reply: Any) -> None:
        body = reply.ok if reply.ok is not None else reply.err
        with self._lock:
            self.payloads.append(json.loads(body.payload.to_bytes()))
            if len(self.payloads) >= self._want:
                self._enough.set()

    def wait(self, n: int) -> bool:
        with self._lock:
            self._want = n
            self._enough.clear()
            if len(self.payloads) >= n:
                return True
        return self._enough.wait(HOLD_S)


async def test_a_burst_of_queries_reaches_the_handler_at_most_cap_at_a_time(
    cell: tuple[Daemon, Client], monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    """Reproduction: 40 `goal/move` queries on alice, each a 15 KB garbage move (within the size
    limit), arrive while the loop is busy. Before the fix every one was queued on the loop (nothing
    bounded the messages handed over from Zenoh's threads), so a flood of them held up every robot's
    cycle; now at most MAX_IN_FLIGHT reach the handler, the rest are refused at once, "busy", and
    bob's goal succeeds."""
    _, client = cell
    bob = await client.robot("bob")
    goal_b = await bob.move(TARGET, duration=1.0)
    seen: list[bytes] = []
    _counting(monkeypatch, move_goal, "decode_move_goal", seen)
    garbage = b"[" + b"1," * 7_500 + b"1]"
    assert len(garbage) < envelope.SMALL_MESSAGE_BYTES
    replies = _Replies()
    key = "testcell/alice/goal/move"
    lease = await client_lease(client, "alice")  # the burst is the holder's own
    for _ in range(BURST):
        client.session.get(
            key, handler=replies.on_reply, payload=garbage, attachment=lease.token, timeout=30.0
        )
    # hold the loop until the burst was delivered: every query beyond the cap is answered on
    # Zenoh's thread, the others wait for the loop
    delivered = replies.wait(BURST - MAX_IN_FLIGHT)
    busy = [r for r in replies.payloads if r.get("reason", "").startswith("busy: too many requests")]
    assert delivered, f"only {len(replies.payloads)} replies while the loop was held: {replies.payloads[:3]}"
    assert len(busy) == BURST - MAX_IN_FLIGHT, [r for r in replies.payloads if r not in busy]
    assert all(r == {"v": 1, "accepted": False, "reason": busy[0]["reason"]} for r in busy), busy[:3]
    assert key in busy[0]["reason"]
    # the loop goes on: the ones in flight are handled (and refused as garbage), no more
    assert await asyncio.get_running_loop().run_in_executor(None, replies.wait, BURST)
    monkeypatch.undo()  # alice's own move below is not counted
    assert len(seen) == MAX_IN_FLIGHT
    assert all(payload == garbage for payload in seen)
    handled = [r for r in replies.payloads if r not in busy]
    assert len(handled) == MAX_IN_FLIGHT
    assert all(r["accepted"] is False for r in handled), handled
    assert all(not r["reason"].startswith("busy") for r in handled), handled
    # bob's cycles ran on: his goal succeeds, and alice serves the next query as usual
    result_b = await goal_b.result(timeout=20.0)
    assert result_b["status"] == "succeeded", result_b
    alice = await client.robot("alice")
    goal_a = await alice.move(TARGET, duration=1.0)
    assert (await goal_a.result(timeout=20.0))["status"] == "succeeded"
    # the daemon's count of refusals (one for each busy reply above, counted where it is refused) is
    # what its log says: at the 1st and 10th refusal, not at each
    floods = [r.getMessage() for r in caplog.records if "too many in flight" in r.getMessage()]
    assert floods == [
        f"{key}: 1 requests refused as too many in flight (a client floods it)",
        f"{key}: 10 requests refused as too many in flight (a client floods it)",
    ], floods


def _hold_the_loop_until(done: Callable[[], bool]) -> None:
    """Block the calling (event loop) thread, on purpose, until ``done()`` holds or HOLD_S passed."""
    for _ in range(int(HOLD_S / 0.001)):
        if done():
            return
        time.sleep(0.001)


async def test_a_burst_of_stream_commands_is_acted_on_only_by_its_newest(
    cell: tuple[Daemon, Client], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Reproduction: 200 joint_position commands put on alice while the loop is busy. Before the fix
    every one was queued on the loop and decoded in turn (a flood of them holds up every robot);
    now a newer sample replaces the one waiting, only the newest is acted on, and the replaced ones
    are counted in `command_rejected` events; bob's goal succeeds meanwhile."""
    daemon, client = cell
    bob = await client.robot("bob")
    goal_b = await bob.move(TARGET, duration=1.0)
    seen: list[bytes] = []
    _counting(monkeypatch, stream_commands, "decode_stream_position", seen)
    key = "testcell/alice/command/joint_position"
    events = client.subscribe("testcell/alice/events")
    assert daemon.node is not None
    latest = daemon.node.latest[key]
    count = 200
    payloads = [
        json.dumps({"positions": HOME, "velocities": [0.0] * 5 + [i * 1e-9]}).encode() for i in range(count)
    ]
    before = latest.replaced_total
    lease = await client_lease(client, "alice")  # the burst is the holder's own
    for payload in payloads:  # none dropped on the way: the test counts every one
        client.session.put(
            key, payload, congestion_control=zenoh.CongestionControl.BLOCK, attachment=lease.token
        )
    # the loop is held (this thread waits) until the node has taken every sample: the first waits for
    # the loop, each later one replaces the one waiting
    _hold_the_loop_until(lambda: latest.replaced_total - before >= count - 1)
    assert latest.replaced_total - before == count - 1
    # the loop goes on: only the newest sample is acted on
    result_b = await goal_b.result(timeout=20.0)
    assert result_b["status"] == "succeeded", result_b
    assert seen == [payloads[-1]]
    replaced = 0
    while replaced < count - len(seen):
        event = await events.get_json(timeout=10.0)
        reason = event.get("reason", "")
        if event.get("kind") == "command_rejected" and reason.startswith("busy: "):
            replaced += int(reason.split()[1])
    assert replaced == count - len(seen)
    assert daemon.node.latest[key].replaced_total == replaced
