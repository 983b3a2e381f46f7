"""Issue 13, finding 1: services, goals and commands act on their exact key only.

A cell of two mock robots; every service of both is wrapped to count its calls. Waits are on goal
results and query replies, each bounded.
"""

from __future__ import annotations

import asyncio
import json
from collections import Counter
from collections.abc import AsyncIterator, Awaitable, Callable
from typing import Any

import pytest

from tests.integration.conftest import TWO_MOCKS, running_daemon
from urdaemon.client import Client
from urdaemon.daemon import Daemon

pytestmark = pytest.mark.timeout(120)

HOME = [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]
TARGET = [0.2, -1.4, 1.4, -1.5, -1.6, 0.1]
SPIED = (
    "startup",
    "resend_program",
    "hand_back_control",
    "zero_ft_sensor",
    "set_io",
    "set_payload",
    "set_speed_slider",
    "set_tool_voltage",
    "force_mode",
    "tool_contact",
    "dashboard",
)


def _spy(daemon: Daemon, calls: Counter[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """Count every call of a service's backend method, per robot (then do what it did)."""
    for runtime in daemon.runtimes:
        backend = runtime.backend
        for name in SPIED:
            original: Callable[..., Awaitable[Any]] = getattr(backend, name)

            def counted(*args: Any, _o: Any = original, _k: str = f"{runtime.robot.name}.{name}") -> Any:
                calls[_k] += 1
                return _o(*args)

            monkeypatch.setattr(backend, name, counted)
        controller = runtime.controller
        for name in ("stop", "cancel", "accept_move", "accept_trajectory", "stream_positions"):
            original_c: Callable[..., Any] = getattr(controller, name)

            def counted_c(
                *args: Any, _o: Any = original_c, _k: str = f"{runtime.robot.name}.{name}", **kw: Any
            ) -> Any:
                calls[_k] += 1
                return _o(*args, **kw)

            monkeypatch.setattr(controller, name, counted_c)


@pytest.fixture
async def spied(monkeypatch: pytest.MonkeyPatch) -> AsyncIterator[tuple[Daemon, Client, Counter[str]]]:
    async with running_daemon(TWO_MOCKS) as (daemon, client):
        calls: Counter[str] = Counter()
        _spy(daemon, calls, monkeypatch)
        yield daemon, client, calls


async def _get(
    client: Client, key: str, body: dict[str, Any] | None = None, attachment: bytes | None = None
) -> tuple[list[bytes], list[bytes]]:
    """(ok payloads, error payloads) of every reply to a raw Zenoh get on ``key``."""
    payload = None if body is None else json.dumps(body).encode()

    def ask() -> tuple[list[bytes], list[bytes]]:
        ok, err = [], []
        for reply in client.session.get(key, payload=payload, attachment=attachment, timeout=5.0):
            if reply.ok is not None:
                ok.append(reply.ok.payload.to_bytes())
            else:
                err.append(reply.err.payload.to_bytes())
        return ok, err

    return await asyncio.get_running_loop().run_in_executor(None, ask)


async def test_wildcard_queries_and_puts_never_act_on_any_robot(
    spied: tuple[Daemon, Client, Counter[str]],
) -> None:
    """Reproduction: with a goal running on each robot, `get testcell/**`, `get **`,
    `get testcell/*/goal/move` (a valid move), `get testcell/*/service/stop` and the like, and a put of
    a valid joint_position command on `testcell/*/command/joint_position`. Before the fix they cancelled
    and stopped both goals, fired every service of both robots and started goals on both.

    The test's session holds both robots' command leases; each wildcard is sent once with each
    robot's token, so only the wildcard check can refuse it, never the lease."""
    daemon, client, calls = spied
    alice, bob = await client.robot("alice"), await client.robot("bob")
    goal_a = await alice.move(TARGET, duration=2.0)
    goal_b = await bob.move(TARGET, duration=2.0)
    calls.clear()  # the two accepted moves above
    tokens = [(await robot.ensure_lease()).encode() for robot in (alice, bob)]

    move = {"positions": HOME, "duration": 0.5, "preempt": True}
    refusals: list[bytes] = []
    for key, body in (
        ("testcell/**", None),
        ("**", None),
        ("testcell/*/goal/move", move),
        ("testcell/**", move),
        ("*/alice/goal/move", move),
        ("testcell/*/goal/cancel", None),
        (
            "testcell/*/goal/trajectory",
            {"points": [{"positions": HOME, "time_from_start": 1.0}], "preempt": True},
        ),
        ("testcell/*/service/stop", None),
        ("testcell/alice/service/*", {}),
        ("testcell/*/service/resend_program", {}),
        ("testcell/bob/**", {"fraction": 0.1}),
    ):
        for token in tokens:
            ok, err = await _get(client, key, body, token)
            # nothing answers "ok"/"accepted" (the URDF, read-only, may answer a wildcard)
            for payload in ok:
                if payload.startswith(b"{"):
                    reply = json.loads(payload)
                    assert reply.get("ok") is not True, (key, reply)
                    assert reply.get("accepted") is not True, (key, reply)
            refusals += err
    for token in tokens:
        position = json.dumps({"positions": HOME}).encode()
        client.session.put("testcell/*/command/joint_position", position, attachment=token)
        client.session.put("testcell/**", position, attachment=token)

    # both goals run to the end: nothing canceled, stopped or preempted them
    result_a, result_b = await goal_a.result(timeout=20), await goal_b.result(timeout=20)
    assert result_a["status"] == "succeeded", result_a
    assert result_b["status"] == "succeeded", result_b
    assert result_a["final_positions"] == pytest.approx(TARGET, abs=1e-3)
    assert not calls, calls  # no service fired, no goal accepted, nothing canceled, no stream
    for runtime in daemon.runtimes:
        status = runtime.status_message()
        assert status["active_goal"] is None, status
    # the refusals name the exact key to ask
    reasons = [json.loads(p)["reason"] for p in refusals]
    assert any("ask testcell/alice/goal/move" in r for r in reasons), reasons
    assert any("ask testcell/bob/service/stop" in r for r in reasons), reasons
    # and the wildcard puts were reported as rejected commands, not executed
    assert all(rt.status_message()["rejected_stream_commands"] >= 1 for rt in daemon.runtimes)


async def test_goal_results_answer_a_concrete_goal_id_only(
    spied: tuple[Daemon, Client, Counter[str]],
) -> None:
    """Reproduction: `get testcell/*/goal/<id>/result` or `get testcell/alice/goal/<id>/*` (wildcard
    queries that cover a kept result) were answered with it; only the exact key is."""
    _, client, _ = spied
    alice = await client.robot("alice")
    goal = await alice.move(TARGET, duration=0.8)
    assert (await goal.result(timeout=20))["status"] == "succeeded"
    for key in (
        "testcell/alice/goal/*/result",
        f"testcell/*/goal/{goal.goal_id}/result",
        f"testcell/alice/goal/{goal.goal_id}/*",
        f"testcell/alice/goal/{goal.goal_id}/**",
    ):
        ok, err = await _get(client, key)
        assert (ok, err) == ([], []), key
    ok, _ = await _get(client, f"testcell/alice/goal/{goal.goal_id}/result")
    assert [json.loads(p)["goal_id"] for p in ok] == [goal.goal_id]


async def test_unknown_robot_or_service_is_answered_naming_what_exists(
    spied: tuple[Daemon, Client, Counter[str]],
) -> None:
    """Reproduction: `get testcell/carol/service/stop` (no robot carol) and
    `get testcell/alice/service/stpo` got no reply at all: the client waited its whole timeout."""
    _, client, calls = spied
    reply = await client.request("testcell/carol/service/stop", timeout=5.0)
    assert reply["ok"] is False
    assert reply["reason"] == "no robot 'carol' in cell 'testcell'; its robots: alice, bob"
    reply = await client.request("testcell/carol/goal/move", {"positions": HOME}, timeout=5.0)
    assert reply["accepted"] is False
    reply = await client.request("testcell/alice/service/stpo", timeout=5.0)
    assert reply["ok"] is False
    assert reply["reason"].startswith("robot 'alice' has no service 'stpo'; its services: ")
    assert "resend_program" in reply["reason"]
    # a known key still has exactly one answer, the robot's own
    ok, _ = await _get(client, "testcell/alice/service/cycle_stats")
    assert len(ok) == 1
    assert json.loads(ok[0])["ok"] is True
    ok, _ = await _get(client, "testcell/robot_description")
    assert len(ok) == 1
    assert ok[0].startswith(b"<")
    assert not calls
