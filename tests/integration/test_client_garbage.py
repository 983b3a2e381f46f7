"""Any client may send nonsense: every queryable still answers once, every stream rejection is reported,
and the daemon keeps serving both robots without losing a task, a setting or a cycle.

The test's session holds both robots' command leases (issue 16) and sends the token with every
message, so the garbage reaches the decoders behind the lease check.
"""

from __future__ import annotations

import asyncio
import json
import random
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import pytest
import zenoh

from tests.helpers import LeaseGrant, client_lease
from urdaemon.client import Client, RobotClient
from urdaemon.daemon import Daemon

pytestmark = pytest.mark.timeout(90)

HOME = [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]
SEED = 20_240_611
QUERY_TIMEOUT_S = 5.0
MEGABYTE = 1 << 20

FLAG_OF = {
    "goal/trajectory": "accepted",
    "goal/move": "accepted",
    "goal/cancel": "canceled",
    "service/set_io": "ok",
    "service/set_payload": "ok",
    "service/set_speed_slider": "ok",
    "service/stop": "ok",
}
"""Every JSON queryable of a robot and the boolean its reply carries."""

VALID: dict[str, dict[str, Any]] = {
    "goal/trajectory": {"points": [{"positions": HOME, "time_from_start": 1.0}]},
    "goal/move": {"positions": HOME, "duration": 1.0},
    "goal/cancel": {"goal_id": "x"},
    "service/set_io": {"kind": "digital", "pin": 1, "value": True},
    "service/set_payload": {"mass": 1.0, "cog": [0.0, 0.0, 0.0]},
    "service/set_speed_slider": {"fraction": 0.5},
    "service/stop": {},
    "command/joint_position": {"positions": HOME},
    "command/joint_velocity": {"velocities": [0.0] * 6},
}
"""Well-formed requests; only ever sent truncated (a strict prefix of a JSON object is never JSON)."""


def _deep(depth: int) -> bytes:
    return b'{"v":1,"positions":' + b"[" * depth + b"]" * depth + b"}"


def raw_garbage(rng: random.Random) -> list[bytes]:
    """Payloads no queryable or stream may accept, as raw bytes."""
    fixed = [
        b"",
        b"\x00",
        b"\xff\xfe\xfd",  # not UTF-8
        b'{"v":1,"positions":"\xc3\x28"}',  # invalid UTF-8 inside a JSON string
        b"\xef\xbb\xbf{}",  # a UTF-8 BOM
        b"{",
        b"}",
        b"{}}",
        b'{"v":1,',
        b"[]",
        b"[1, 2, 3]",
        b'[{"positions": [0, 0, 0, 0, 0, 0]}]',
        b"null",
        b"true",
        b"42",
        b"1e999",
        b'"a string"',
        b"NaN",
        _deep(100),
        _deep(2_000),  # beyond the JSON decoder's recursion limit
        b"[" * 200_000,
        b'{"v":1,"positions":[' + b"9" * 5_000 + b",0,0,0,0,0]}",  # an int beyond int-to-str limits
        b'{"v":1,"positions":[1e999,0,0,0,0,0],"velocities":[-1e999,0,0,0,0,0]}',
        b'{"v":1,"positions":[NaN,NaN,NaN,NaN,NaN,NaN]}',
        b'{"v":1,"fraction":NaN}',
        b'{"v":1,"kind":"analog","pin":0,"value":Infinity}',
        b"x" * MEGABYTE,
    ]
    randoms = [rng.randbytes(rng.randint(1, 512)) for _ in range(12)]
    truncated = []
    for body in VALID.values():
        text = json.dumps({"v": 1, **body}).encode()
        truncated += [text[: rng.randrange(1, len(text) - 1)] for _ in range(2)]
    return fixed + randoms + truncated


def dict_garbage() -> list[dict[str, Any]]:
    """JSON objects of the wrong shape, version or types, for ``Client.query`` (which adds ``"v": 1``)."""
    huge = 10**30
    return [
        {},
        {"v": 2},
        {"v": 2, **VALID["goal/move"]},
        {"v": "1"},
        {"v": True},
        {"v": None, "positions": HOME},
        {"v": [1]},
        {"bogus": 1},
        {"positions": "abc"},
        {"positions": {"a": 1}},
        {"positions": [True] * 6},
        {"positions": [[0.0]] * 6},
        {"positions": [None] * 6},
        {"positions": [huge] * 6, "duration": huge},
        {"positions": [1e308] * 6},
        {"points": "nope"},
        {"points": [None]},
        {"points": [{"positions": HOME}]},
        {"points": [{"positions": HOME, "time_from_start": "soon"}]},
        {"points": [{"positions": HOME, "time_from_start": 1.0, "extra": 1}]},
        {"joint_names": "alice_shoulder_pan_joint", "positions": HOME},
        {"tolerances": [1, 2], "positions": HOME},
        {"preempt": "yes", "positions": HOME},
        {"goal_id": 123},
        {"goal_id": ["a"]},
        {"kind": 5, "pin": "x", "value": "y"},
        {"kind": "digital", "pin": huge, "value": True},
        {"kind": "digital", "pin": -1, "value": True},
        {"kind": "digital", "pin": 1.5, "value": True},
        {"kind": "analog", "pin": 0, "value": 1e308},
        {"kind": "laser", "pin": 0, "value": True},
        {"mass": "heavy"},
        {"mass": -1.0},
        {"mass": 1e308, "cog": [1e308]},
        {"mass": 1.0, "cog": "up"},
        {"fraction": True},
        {"fraction": huge},
        {"fraction": -1e-300},
        {"fraction": [0.5]},
        {"positions": "x" * MEGABYTE},
        {"v": 1, "x" * 1000: 1},
    ]


@contextmanager
def loop_errors() -> Iterator[list[dict[str, Any]]]:
    """Collect what the loop's exception handler sees (a handler that raised in a callback) meanwhile."""
    loop = asyncio.get_running_loop()
    seen: list[dict[str, Any]] = []
    previous = loop.get_exception_handler()
    loop.set_exception_handler(lambda _loop, context: seen.append(context))
    try:
        yield seen
    finally:
        loop.set_exception_handler(previous)


async def ask_raw(
    client: Client, key: str, payload: bytes | None, attachment: bytes | None = None
) -> list[tuple[bool, bytes]]:
    """Every reply (ok?, payload) to a ``get`` on ``key`` carrying ``payload`` as it is."""

    def ask() -> list[tuple[bool, bytes]]:
        replies = client.session.get(key, payload=payload, attachment=attachment, timeout=QUERY_TIMEOUT_S)
        out = []
        for reply in replies:
            if reply.ok is not None:
                out.append((True, bytes(reply.ok.payload.to_bytes())))
            else:
                out.append((False, bytes(reply.err.payload.to_bytes())))
        return out

    return await asyncio.get_running_loop().run_in_executor(None, ask)


def _check_refusal(key: str, suffix: str, raw: bytes, sent: object) -> None:
    what = f"{key} <- {str(sent)[:120]!r}"
    reply = json.loads(raw)
    assert isinstance(reply, dict), what
    assert reply.get("v") == 1, what
    flag = FLAG_OF[suffix]
    assert isinstance(reply.get(flag), bool), f"{what}: no boolean {flag!r} in {reply}"
    if suffix == "service/stop":
        # stop is unconditional (a safety command); whatever it says, it says it once, as JSON
        if not reply["ok"]:
            assert isinstance(reply.get("reason"), str), what
            assert reply["reason"], what
        return
    assert reply[flag] is False, f"{what}: garbage was not refused: {reply}"
    assert isinstance(reply.get("reason"), str), f"{what}: no reason in {reply}"
    assert reply["reason"].strip(), f"{what}: empty reason"


async def _one_reply(
    client: Client, key: str, payload: bytes | None, attachment: bytes | None = None
) -> bytes:
    replies = await ask_raw(client, key, payload, attachment)
    sent = payload[:80] if payload is not None else None
    assert len(replies) == 1, f"{key} <- {sent!r}: {len(replies)} replies, expected exactly one"
    ok, body = replies[0]
    assert ok, f"{key} <- {sent!r}: error reply {body[:200]!r}"
    return body


def _snapshot(daemon: Daemon) -> list[tuple[Any, ...]]:
    """What garbage must not change: settings, IO, payload, position of every robot."""
    out = []
    for rt in daemon.runtimes:
        s = rt.backend.state
        out.append(
            (
                s.speed_slider,
                list(s.digital_out),
                list(s.configurable_out),
                list(s.tool_out),
                list(s.analog_out),
                s.payload_mass,
                tuple(s.payload_cog),
                list(s.positions),
                rt.controller.active_goal_id,
                rt.controller.mode,
            )
        )
    return out


async def assert_still_serving(daemon: Daemon, client: Client, errors: list[dict[str, Any]]) -> None:
    """Joint states flow for both robots, a move on each succeeds, no task died, nothing was lost."""
    robots = [await client.robot(rt.robot.name, cell=daemon.cell.cell) for rt in daemon.runtimes]
    subs = [robot.joint_states(1000) for robot in robots]
    for robot, sub in zip(robots, subs, strict=True):
        cycles = [(await sub.get_json(timeout=5.0))["cycle"] for _ in range(10)]
        assert cycles == sorted(cycles), f"{robot.name}: joint states out of order"
        assert cycles[-1] > cycles[0], f"{robot.name}: joint states stopped"
        sub.close()

    targets = {"alice": [0.4, -1.3, 1.3, -1.4, -1.5, 0.2], "bob": [-0.4, -1.4, 1.4, -1.6, -1.5, -0.2]}
    goals = await asyncio.gather(*(robot.move(targets[robot.name], duration=1.0) for robot in robots))
    results = await asyncio.gather(*(goal.result(timeout=20.0) for goal in goals))
    for robot, goal, result, rt in zip(robots, goals, results, daemon.runtimes, strict=True):
        assert result["status"] == "succeeded", result
        assert rt.backend.state.positions == pytest.approx(targets[robot.name], abs=1e-3)
        # a stored result still answers once, whatever the query carries
        for payload in (None, b"\xff\xfe", b"x" * 1000):
            body = await _one_reply(client, robot.keys.goal_result(goal.goal_id), payload)
            assert json.loads(body)["status"] == "succeeded"
            assert json.loads(body)["goal_id"] == goal.goal_id

    for rt in daemon.runtimes:
        status = rt.status_message()
        assert status["restarts"] == 0, f"{rt.robot.name}: its backend task died and was restarted"
        assert status["lifecycle"] == "running"
        assert status["ready"] is True
        assert status["active_goal"] is None
    assert not errors, f"a handler raised on the loop: {[str(c.get('exception')) for c in errors]}"


async def leases(daemon: Daemon, client: Client) -> dict[str, LeaseGrant]:
    """Every robot's command lease, held by the client."""
    return {rt.robot.name: await client_lease(client, rt.robot.name) for rt in daemon.runtimes}


async def test_every_queryable_answers_garbage_once_with_a_refusal_and_the_daemon_keeps_serving(
    cell: tuple[Daemon, Client],
) -> None:
    daemon, client = cell
    held = await leases(daemon, client)
    rng = random.Random(SEED)
    raws = raw_garbage(rng)
    dicts = dict_garbage()
    before = _snapshot(daemon)
    cycles_before = [rt.backend.statistics().cycles for rt in daemon.runtimes]
    description = daemon.description.urdf
    with loop_errors() as errors:
        for rt in daemon.runtimes:
            base = rt.keys.base
            token = held[rt.robot.name].token
            for suffix in FLAG_OF:
                key = f"{base}/{suffix}"
                for payload in [None, *raws]:
                    _check_refusal(key, suffix, await _one_reply(client, key, payload, token), payload)
                for body in dicts:
                    replies = await client.query(key, body, timeout=QUERY_TIMEOUT_S, attachment=token)
                    assert len(replies) == 1, f"{key} <- {str(body)[:120]}: {len(replies)} replies"
                    _check_refusal(key, suffix, replies[0], body)
            # results of goals that never existed: one error reply naming the id (issue 32), no harm
            for payload in (None, *raws[:8]):
                unknown = f"{rt.robot.name}-0000-1"
                (answer,) = await ask_raw(client, rt.keys.goal_result(unknown), payload)
                assert answer[0] is False, answer  # an error reply: never taken for a result
                assert f"goal '{unknown}': robot '{rt.robot.name}' has no such goal" in answer[1].decode()
        # the cell URDF, whatever the query carries
        for payload in (None, *raws[:10], b"x" * MEGABYTE):
            urdf = await _one_reply(client, f"{daemon.cell.cell}/robot_description", payload)
            assert urdf.decode() == description

        assert _snapshot(daemon) == before, "garbage changed a setting, an output or the pose"
        for rt, cycles in zip(daemon.runtimes, cycles_before, strict=True):
            assert rt.backend.statistics().cycles > cycles
        await assert_still_serving(daemon, client, errors)


async def _status_with(robot: RobotClient, client: Client, at_least: int) -> dict[str, Any]:
    sub = client.subscribe(robot.keys.status, 100)
    try:
        for _ in range(50):  # status goes out at 2 Hz and on change: a few seconds at most
            status = await sub.get_json(timeout=5.0)
            if status["rejected_stream_commands"] >= at_least:
                return status
        raise AssertionError(f"{robot.name}: status never counted {at_least} rejected commands")
    finally:
        sub.close()


async def test_garbage_stream_commands_are_each_reported_and_counted(cell: tuple[Daemon, Client]) -> None:
    daemon, client = cell
    held = await leases(daemon, client)
    rng = random.Random(SEED + 1)
    bad_commands = [
        *raw_garbage(rng),
        *(json.dumps({"v": 1, **body}).encode() for body in dict_garbage()),
        # well-formed but not executable
        json.dumps({"v": 1, "positions": HOME[:5]}).encode(),
        json.dumps({"v": 1, "positions": [0.0, -1.5708, 4.0, -1.5708, -1.5708, 0.0]}).encode(),
        json.dumps({"v": 1, "positions": HOME, "joint_names": ["a", "b", "c", "d", "e", "f"]}).encode(),
        json.dumps({"v": 1, "positions": HOME, "velocities": [100.0] * 6}).encode(),
        json.dumps({"v": 1, "velocities": [100.0] * 6}).encode(),
        json.dumps({"v": 1, "velocities": [0.0] * 7}).encode(),
    ]
    before = _snapshot(daemon)
    robots = [await client.robot(rt.robot.name, cell=daemon.cell.cell) for rt in daemon.runtimes]
    counted_before = [rt.status_message()["rejected_stream_commands"] for rt in daemon.runtimes]
    with loop_errors() as errors:
        for robot, rt, counted in zip(robots, daemon.runtimes, counted_before, strict=True):
            events = client.subscribe(robot.keys.events, 100)
            keys = (robot.keys.command_joint_position, robot.keys.command_joint_velocity)
            sent = 0
            for key in keys:
                for payload in bad_commands:
                    # one at a time: each bad command must come back as its own event
                    client.session.put(
                        key,
                        payload,
                        congestion_control=zenoh.CongestionControl.BLOCK,
                        attachment=held[robot.name].token,
                    )
                    sent += 1
                    event = await events.get_json(timeout=5.0)
                    what = f"{key} <- {payload[:80]!r}: {event}"
                    assert event["kind"] == "command_rejected", what
                    assert event["robot"] == robot.name, what
                    assert event["key"] == key, what
                    assert isinstance(event["reason"], str), what
                    assert event["reason"].strip(), what
                    assert rt.status_message()["rejected_stream_commands"] == counted + sent, what
            events.close()
            status = await _status_with(robot, client, counted + sent)
            assert status["rejected_stream_commands"] == counted + sent
            assert status["restarts"] == 0
        assert _snapshot(daemon) == before, "a rejected stream command moved a robot or changed it"
        await assert_still_serving(daemon, client, errors)


async def test_goals_beyond_the_planners_time_range_are_refused_with_a_reason(
    cell: tuple[Daemon, Client],
) -> None:
    daemon, client = cell
    alice = daemon.runtimes[0].keys
    lease = await client_lease(client, alice.robot)
    target = [0.2, *HOME[1:]]
    with loop_errors() as errors:
        for key, body in (
            (alice.goal_move, {"positions": target, "duration": 1e4}),
            (alice.goal_trajectory, {"points": [{"positions": target, "time_from_start": 1e4}]}),
        ):
            replies = await client.query(key, body, timeout=2.0, attachment=lease.token)
            assert len(replies) == 1, f"{key}: {len(replies)} replies to a 10 000 s goal"
            reply = json.loads(replies[0])
            assert reply["accepted"] is False
            assert reply["reason"]
            assert not reply["reason"].startswith("lease:"), reply  # refused for its time, not the lease
        assert not errors, [str(c.get("exception")) for c in errors]
