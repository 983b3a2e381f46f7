"""Issue 13, finding 4 (the daemon's side): every service checks its payload and every number its
range before anything acts; a running service refuses a second call of itself.

A cell of two mock robots; service calls are counted on the backend. Waits are on query replies.
The test's session holds alice's command lease (issue 16) and sends its token with every request,
so what is checked here is the service's own refusal, never the lease's.
"""

from __future__ import annotations

import asyncio
from collections import Counter
from collections.abc import AsyncIterator
from typing import Any

import pytest

from tests.helpers import LeaseGrant, acquire_lease, zenoh_ask
from tests.integration.conftest import TWO_MOCKS, running_daemon
from urdaemon.client import Client
from urdaemon.daemon import Daemon

pytestmark = pytest.mark.timeout(120)

HOME = [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]
ACTIONS = {
    "startup": "startup",
    "resend_program": "resend_program",
    "hand_back_control": "hand_back_control",
    "zero_ft_sensor": "zero_ft_sensor",
    "end_force_mode": "force_mode",
    "start_tool_contact": "tool_contact",
    "end_tool_contact": "tool_contact",
}
"""Payload-less service → the backend method it calls."""


@pytest.fixture
async def cell(monkeypatch: pytest.MonkeyPatch) -> AsyncIterator[tuple[Daemon, Client, Counter[str]]]:
    """The two mocks, every backend method a payload-less service calls counted (and then a no-op)."""
    async with running_daemon(TWO_MOCKS) as (daemon, client):
        calls: Counter[str] = Counter()
        for runtime in daemon.runtimes:
            for method in set(ACTIONS.values()):

                async def counted(*_: Any, _k: str = f"{runtime.robot.name}.{method}") -> None:
                    calls[_k] += 1

                monkeypatch.setattr(runtime.backend, method, counted)
        yield daemon, client, calls


@pytest.fixture
async def lease(cell: tuple[Daemon, Client, Counter[str]]) -> LeaseGrant:
    """alice's command lease, held by the client's session."""
    return await acquire_lease(cell[1].session, "testcell", "alice")


async def _ask(
    client: Client, key: str, payload: bytes | dict[str, Any] | None, lease: LeaseGrant
) -> dict[str, Any]:
    """The one reply to a query sent with the lease's token, as the client does (``"v": 1`` added to a
    dict, bytes sent as they are)."""
    body = {"v": 1, **payload} if isinstance(payload, dict) else payload
    replies = await zenoh_ask(client.session, key, body, attachment=lease.token, timeout=10.0)
    assert len(replies) == 1, (key, replies)
    return replies[0]


GARBAGE = [
    b"x",
    b"[]",
    b"null",
    b"0",
    b'"startup"',
    b'{"force": true}',
    b'{"v": 1, "now": 1}',
    b'{"v": 2}',
    b"\xff\xfe",
    b"{" * 5000,
    b'{"' + b"a" * 1000 + b'\\n2026 forged log line": 1}',
]


async def test_payloadless_services_refuse_any_payload_but_nothing_or_an_empty_object(
    cell: tuple[Daemon, Client, Counter[str]], lease: LeaseGrant
) -> None:
    """Reproduction: the payload-less services (startup, resend_program, hand_back_control,
    zero_ft_sensor, end_force_mode, start/end_tool_contact) ignored their payload, so every garbage
    payload acted (96/96 in the report); docs/keys.md promised a refusal."""
    _, client, calls = cell
    for name in ACTIONS:
        key = f"testcell/alice/service/{name}"
        for payload in GARBAGE:
            reply = await _ask(client, key, payload, lease)
            assert reply["ok"] is False, (name, payload, reply)
            reason = reply["reason"]
            assert reason.startswith(name), reason
            assert len(reason) < 200, reason  # client text is shortened
            assert "\n" not in reason, reason
        assert not calls, (name, calls)
        accepted: list[bytes | None] = [None, b"", b"{}", b'{"v": 1}', b' { "v" : 1 } ']
        for empty in accepted:
            reply = await _ask(client, key, empty, lease)
            assert reply == {"v": 1, "ok": True}, (name, empty, reply)
        assert calls[f"alice.{ACTIONS[name]}"] >= 5, (name, calls)
        calls.clear()
    reply = await _ask(client, "testcell/alice/service/startup", b'{"now": 1}', lease)
    assert reply["reason"] == "startup takes no arguments, but got: unknown field(s) now"


async def test_a_running_service_refuses_a_second_call_of_itself(
    cell: tuple[Daemon, Client, Counter[str]], lease: LeaseGrant, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Reproduction: 14 `resend_program` requests within a few ms each sent a program (14 programs)."""
    daemon, client, _ = cell
    release = asyncio.Event()
    sent = Counter[str]()

    async def resend_program() -> None:
        sent["programs"] += 1
        await release.wait()

    monkeypatch.setattr(daemon.runtimes[0].backend, "resend_program", resend_program)
    asks = [
        asyncio.create_task(_ask(client, "testcell/alice/service/resend_program", None, lease))
        for _ in range(14)
    ]
    # every request but the running one is answered at once: busy
    busy = []
    for _ in range(13):
        done, _pending = await asyncio.wait(asks, return_when=asyncio.FIRST_COMPLETED, timeout=10.0)
        assert done, "no reply"
        for task in done:
            asks.remove(task)
            busy.append(task.result())
        if len(busy) >= 13:
            break
    assert len(busy) == 13
    # refused as still running, or (the burst arriving faster than the loop reads it) as too many
    # in flight on the key (publish/node.py); either way nothing more acts
    reasons = Counter(r["reason"] for r in busy)
    assert all(r == {"v": 1, "ok": False, "reason": r["reason"]} for r in busy), busy
    assert set(reasons) <= {
        "busy: resend_program is still running; ask again once it answered",
        "busy: too many requests in flight on testcell/alice/service/resend_program (at most 4); ask again",
    }, reasons
    assert reasons["busy: resend_program is still running; ask again once it answered"] >= 1, reasons
    release.set()
    (last,) = asks
    assert (await last) == {"v": 1, "ok": True}
    assert sent["programs"] == 1
    # once it answered, the service runs again
    assert (await _ask(client, "testcell/alice/service/resend_program", None, lease))["ok"] is True
    assert sent["programs"] == 2


OUT_OF_RANGE = [
    ("set_payload", {"mass": 1e9}, "set_payload.mass (kg): must be within 0..35, got 1e+09"),
    (
        "set_payload",
        {"mass": 1.0, "cog": [0.0, 0.0, 1e6]},
        "set_payload.cog[2] (m): must be within -1..1, got 1e+06",
    ),
    (
        "start_force_mode",
        {
            "task_frame": [0, 0, 0, 0, 0, 0],
            "selection": [0, 0, 1, 0, 0, 0],
            "wrench": [0, 0, 1e9, 0, 0, 0],
            "limits": [0.1, 0.1, 0.1, 0.1, 0.1, 0.1],
        },
        "start_force_mode.wrench[2]: must be within -1000..1000, got 1e+09",
    ),
    (
        "start_force_mode",
        {
            "task_frame": [0, 0, 0, 0, 0, 0],
            "selection": [0, 0, 1, 0, 0, 0],
            "wrench": [0, 0, 10, 0, 0, 0],
            "limits": [0.1, 0.1, -1e9, 0.1, 0.1, 0.1],
        },
        "start_force_mode.limits[2]: must be within 0..10, got -1e+09",
    ),
]


@pytest.mark.parametrize(("service", "body", "reason"), OUT_OF_RANGE)
async def test_out_of_range_service_values_are_refused_with_the_range(
    cell: tuple[Daemon, Client, Counter[str]],
    lease: LeaseGrant,
    service: str,
    body: dict[str, Any],
    reason: str,
) -> None:
    """Reproduction: a payload mass of 1e9 or a cog of 1e6 was accepted (the mock stored it; a UR
    robot's script command gave an internal-error traceback), as was a force-mode wrench of 1e9."""
    daemon, client, _ = cell
    before = daemon.runtimes[0].backend.state.payload_mass
    reply = await _ask(client, f"testcell/alice/service/{service}", body, lease)
    assert reply == {"v": 1, "ok": False, "reason": reason}
    assert daemon.runtimes[0].backend.state.payload_mass == before


@pytest.mark.parametrize(
    ("tolerances", "reason"),
    [
        ({"path": 1e9}, "move goal.tolerances.path: must be > 0 and ≤ 6.28319, got 1e+09"),
        (
            {"goal": [0.1, 0.1, 0.1, 0.1, 0.1, 1e9]},
            "move goal.tolerances.goal[5]: must be > 0 and ≤ 6.28319, got 1e+09",
        ),
        ({"goal_time": 1e9}, "move goal.tolerances.goal_time: must be within 0..7200, got 1e+09"),
    ],
)
async def test_out_of_range_tolerances_are_refused(
    cell: tuple[Daemon, Client, Counter[str]], lease: LeaseGrant, tolerances: dict[str, Any], reason: str
) -> None:
    """Reproduction: tolerances of 1e9 were accepted (a check switched off by an absurd number)."""
    daemon, client, _ = cell
    body = {"positions": [0.1, -1.5, 1.5, -1.5, -1.5, 0.1], "tolerances": tolerances}
    reply = await _ask(client, "testcell/alice/goal/move", body, lease)
    assert reply == {"v": 1, "accepted": False, "reason": reason}
    assert daemon.runtimes[0].controller.active_goal_id is None


async def test_client_text_echoed_in_replies_is_short_and_has_no_control_characters(
    cell: tuple[Daemon, Client, Counter[str]], lease: LeaseGrant, caplog: pytest.LogCaptureFixture
) -> None:
    """Reproduction: an unknown field name of 1 KB came back (and went to the log) whole, and one with
    a newline forged a log line."""
    _, client, _ = cell
    name = "x" * 1000 + "\n2026-01-01 00:00:00 CRITICAL forged"
    reply = await _ask(client, "testcell/alice/goal/move", {"positions": HOME, name: 1}, lease)
    assert reply["accepted"] is False
    assert len(reply["reason"]) < 120, reply
    assert "\n" not in reply["reason"]
    assert "forged" not in reply["reason"]
    for record in caplog.records:
        message = record.getMessage()
        assert "\n" not in message, message
        assert len(message) < 400, message
