"""The command lease over raw Zenoh sessions (no urdaemon client code): only the holder's session
commands a robot; the holder gone stops it and frees the lease; take-over, stop and state are open.

Issue 16 ("a command lease per robot"). Reproduction before it: a bare Zenoh session with no urdaemon
code moved alice, preempted and canceled another client's goals; there was no lease key at all.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import re
import secrets
import signal
import subprocess
import sys
import textwrap
import threading
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

import pytest
import zenoh

from tests.helpers import LeaseGrant, acquire_lease, free_tcp_port, wait_for_line, zenoh_ask
from tests.integration.conftest import ROOT, TWO_MOCKS
from urdaemon.cell import parse_cell
from urdaemon.daemon import Daemon
from urdaemon.model import fingerprint

pytestmark = pytest.mark.timeout(120)

HOME = [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]
TARGET = [0.3, -1.4, 1.4, -1.5, -1.6, 0.2]
LONG_MOVE_S = 30.0
"""Long enough that no move ends on its own while a test runs."""
WAIT_S = 20.0
"""Bound of every wait for a message (a busy machine is slow, never this slow)."""


def open_session(endpoint: str) -> Any:
    """A bare Zenoh client session to the daemon."""
    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(conf)


class Inbox:
    """Samples of a subscription, decoded, handed to the test's loop."""

    def __init__(self, session: Any, key: str) -> None:
        self._loop = asyncio.get_running_loop()
        self.queue: asyncio.Queue[dict[str, Any]] = asyncio.Queue()
        self._sub = session.declare_subscriber(key, self._on_sample)

    def _on_sample(self, sample: Any) -> None:
        body = json.loads(bytes(sample.payload.to_bytes()))
        with contextlib.suppress(RuntimeError):
            self._loop.call_soon_threadsafe(self.queue.put_nowait, body)

    async def next(self, match: Callable[[dict[str, Any]], bool]) -> dict[str, Any]:
        """The next message ``match`` accepts (at most 10 000 read, within ``WAIT_S``)."""
        async with asyncio.timeout(WAIT_S):
            for _ in range(10_000):
                body = await self.queue.get()
                if match(body):
                    return body
        raise AssertionError("no such message")


@asynccontextmanager
async def served(text: str = TWO_MOCKS) -> AsyncIterator[tuple[Daemon, str]]:
    """A daemon serving ``text`` in this loop; yields it and its endpoint once alice's lease answers."""
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    daemon = Daemon(parse_cell(text, base_dir=ROOT / "configs"), listen=(endpoint,))
    stop = asyncio.Event()
    task = asyncio.create_task(daemon.run(stop))
    for _ in range(1000):  # the daemon's first step opens its session and declares everything
        if daemon.node is not None or task.done():
            break
        await asyncio.sleep(0)
    if task.done():
        task.result()
    probe = await asyncio.to_thread(open_session, endpoint)
    try:
        (shown,) = await zenoh_ask(probe, "testcell/alice/lease", {"action": "show"})
        assert shown["ok"] is True, shown
        yield daemon, endpoint
    finally:
        probe.close()
        stop.set()
        await asyncio.wait_for(task, 20.0)


def runtime(daemon: Daemon, name: str = "alice") -> Any:
    return next(r for r in daemon.runtimes if r.robot.name == name)


def on_key(key: str) -> Callable[[dict[str, Any]], bool]:
    return lambda body: body.get("key") == key


def is_lease_event(action: str) -> Callable[[dict[str, Any]], bool]:
    return lambda body: body.get("kind") == "lease" and body.get("action") == action


async def move(session: Any, grant: LeaseGrant | None, positions: list[float] = TARGET) -> dict[str, Any]:
    body = {"positions": positions, "duration": LONG_MOVE_S}
    token = None if grant is None else grant.token
    (reply,) = await zenoh_ask(session, "testcell/alice/goal/move", body, attachment=token)
    return reply


async def test_a_second_session_commands_nothing_while_the_first_holds_the_lease() -> None:
    """Goals, streams, freedrive and a commanding service from a second session (no token, a
    wrong one) are refused naming the holder (a cancel, which only stops, is anyone's); the robot
    never moves; state stays readable."""
    async with served() as (daemon, endpoint):
        first, second = open_session(endpoint), open_session(endpoint)
        try:
            grant = await acquire_lease(first, "testcell", "alice", holder="first client")
            events = Inbox(second, "testcell/alice/events")
            states = Inbox(second, "testcell/alice/joint_states")
            statuses = Inbox(second, "testcell/alice/status")
            assert len((await states.next(lambda _: True))["position"]) == 6, "state is open to all"
            wrong = b"0" * 32
            trajectory = {"points": [{"positions": TARGET, "time_from_start": 2.0}]}
            asks: list[tuple[str, dict[str, Any], str]] = [
                ("goal/trajectory", trajectory, "accepted"),
                ("goal/move", {"positions": TARGET}, "accepted"),
                ("service/set_speed_slider", {"fraction": 0.5}, "ok"),
                ("service/start_tool_contact", {}, "ok"),
            ]
            puts: list[tuple[str, dict[str, Any]]] = [
                ("command/joint_position", {"positions": TARGET}),
                ("command/joint_velocity", {"velocities": [0.1] * 6}),
                ("command/freedrive", {"active": True}),
            ]
            for attachment in (None, wrong):
                for key, body, answer in asks:
                    (reply,) = await zenoh_ask(second, f"testcell/alice/{key}", body, attachment=attachment)
                    assert reply[answer] is False, (key, reply)
                    assert reply["reason"].startswith("lease: robot 'alice' is held by first client since"), (
                        reply
                    )
                for key, body in puts:
                    second.put(f"testcell/alice/{key}", json.dumps(body).encode(), attachment=attachment)
                    rejected = await events.next(on_key(f"testcell/alice/{key}"))
                    assert rejected["kind"] == "command_rejected"
                    assert rejected["reason"].startswith("lease: robot 'alice' is held by first client"), (
                        rejected
                    )
            # a cancel only stops: anyone may ask (issue 32); nothing runs, so nothing is canceled
            (canceled,) = await zenoh_ask(second, "testcell/alice/goal/cancel", {})
            assert (canceled["canceled"], canceled["reason"]) == (False, "no active goal"), canceled
            alice = runtime(daemon)
            assert alice.controller.mode == "idle"
            assert not alice.backend.freedrive_active
            assert alice.state.positions == pytest.approx(HOME, abs=1e-9)
            assert alice.backend.state.speed_slider == 1.0
            status = await statuses.next(lambda m: m.get("lease") is not None)
            assert status["lease"]["holder"] == "first client", "the status names the holder, to all"
            # the holder itself commands it
            reply = await move(first, grant)
            assert reply["accepted"] is True, reply
            (stopped,) = await zenoh_ask(first, "testcell/alice/service/stop", None)
            assert stopped["ok"] is True
        finally:
            first.close()
            second.close()


async def test_the_holders_session_closing_aborts_its_goal_and_frees_the_lease() -> None:
    async with served() as (daemon, endpoint):
        holder, other = open_session(endpoint), open_session(endpoint)
        try:
            events = Inbox(other, "testcell/alice/events")
            results = Inbox(other, "testcell/alice/goal/*/result")
            grant = await acquire_lease(holder, "testcell", "alice", holder="closing client")
            reply = await move(holder, grant)
            assert reply["accepted"] is True, reply
            holder.close()
            result = await results.next(lambda r: r["goal_id"] == reply["goal_id"])
            assert result["status"] == "aborted"
            assert result["reason"] == "lease holder closing client is gone"
            lost = await events.next(is_lease_event("lost"))
            assert lost["holder"] == "closing client"
            assert runtime(daemon).controller.mode in ("stopping", "idle")
            (shown,) = await zenoh_ask(other, "testcell/alice/lease", {"action": "show"})
            assert shown == {"v": 1, "ok": True, "lease": None}
            await acquire_lease(other, "testcell", "alice", holder="next client")
        finally:
            other.close()


HOLDER_SCRIPT = textwrap.dedent(
    """
    import json, secrets, sys, time, zenoh
    endpoint = sys.argv[1]
    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    session = zenoh.open(conf)
    zid = secrets.token_hex(16)
    token = session.liveliness().declare_token(f"testcell/alice/lease/{zid}")

    def ask(key, body, attachment=None):
        replies = session.get(key, payload=json.dumps(body).encode(), attachment=attachment, timeout=10.0)
        return [json.loads(bytes(r.ok.payload.to_bytes())) for r in replies if r.ok is not None][0]

    grant = ask("testcell/alice/lease", {"action": "acquire", "session": zid, "holder": "doomed"})
    goal = ask("testcell/alice/goal/move", {"positions": json.loads(sys.argv[2]), "duration": 30.0},
               grant["token"].encode())
    print("READY " + json.dumps(goal), file=sys.stderr, flush=True)
    time.sleep(120)
    """
)


async def test_a_killed_holder_process_stops_the_robot_and_frees_the_lease(tmp_path: Path) -> None:
    """The holder is SIGKILLed mid-goal: the goal ends aborted naming the holder gone, the lease is
    free (judged by the daemon's own messages, not by time)."""
    script = tmp_path / "holder.py"
    script.write_text(HOLDER_SCRIPT)
    async with served() as (daemon, endpoint):
        watcher = open_session(endpoint)
        proc = subprocess.Popen(
            [sys.executable, str(script), endpoint, json.dumps(TARGET)],
            stderr=subprocess.PIPE,
            text=True,
        )
        try:
            events = Inbox(watcher, "testcell/alice/events")
            results = Inbox(watcher, "testcell/alice/goal/*/result")
            lines = await wait_for_line(proc, "READY ", timeout=60.0)
            goal = json.loads(lines[-1].split("READY ", 1)[1])
            assert goal["accepted"] is True, goal
            assert runtime(daemon).controller.active_goal_id == goal["goal_id"]
            proc.send_signal(signal.SIGKILL)
            result = await results.next(lambda r: r["goal_id"] == goal["goal_id"])
            assert result["status"] == "aborted"
            assert result["reason"] == "lease holder doomed is gone"
            await events.next(is_lease_event("lost"))
            await acquire_lease(watcher, "testcell", "alice", holder="survivor")
        finally:
            proc.kill()
            proc.wait(10)
            watcher.close()


async def test_a_take_over_needs_force_and_a_reason_and_is_logged_and_published(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.INFO, logger="urdaemon.robot")
    async with served() as (daemon, endpoint):
        first, second = open_session(endpoint), open_session(endpoint)
        try:
            events = Inbox(second, "testcell/alice/events")
            old = await acquire_lease(first, "testcell", "alice", holder="stuck client")
            goal = await move(first, old)
            zid = secrets.token_hex(16)
            token = second.liveliness().declare_token(f"testcell/alice/lease/{zid}")
            ask: dict[str, Any] = {"action": "acquire", "session": zid, "holder": "rescuer"}
            (refused,) = await zenoh_ask(second, "testcell/alice/lease", ask)
            assert refused["ok"] is False
            assert "held by stuck client" in refused["reason"]
            assert refused["lease"]["holder"] == "stuck client"
            (no_reason,) = await zenoh_ask(second, "testcell/alice/lease", {**ask, "force": True})
            assert no_reason["ok"] is False
            assert "'reason'" in no_reason["reason"]
            assert runtime(daemon).controller.active_goal_id == goal["goal_id"], "nothing changed"
            (taken,) = await zenoh_ask(
                second, "testcell/alice/lease", {**ask, "force": True, "reason": "its operator went home"}
            )
            assert taken["ok"] is True, taken
            event = await events.next(is_lease_event("taken_over"))
            assert event["holder"] == "rescuer"
            assert event["previous"]["holder"] == "stuck client"
            assert event["reason"] == "its operator went home"
            assert any("its operator went home" in r.getMessage() for r in caplog.records), caplog.text
            for secret in (old.session_id, zid):  # logs name a lease by its fingerprint only
                assert secret not in caplog.text
            assert f"(lease {fingerprint(zid)})" in caplog.text
            assert runtime(daemon).controller.active_goal_id is None, "the take-over stopped the robot"
            refused_old = await move(first, old)
            assert refused_old["accepted"] is False
            assert refused_old["reason"].startswith("lease: robot 'alice' is held by rescuer")
            assert (await move(second, LeaseGrant(taken["token"].encode(), token, taken)))["accepted"] is True
        finally:
            first.close()
            second.close()


async def test_stop_works_from_any_session_without_a_lease() -> None:
    async with served() as (_, endpoint):
        holder, stranger = open_session(endpoint), open_session(endpoint)
        try:
            results = Inbox(stranger, "testcell/*/goal/*/result")
            grant = await acquire_lease(holder, "testcell", "alice")
            first = await move(holder, grant)
            (stopped,) = await zenoh_ask(stranger, "testcell/alice/service/stop", None)
            assert stopped["ok"] is True
            result = await results.next(lambda r: r["goal_id"] == first["goal_id"])
            assert (result["status"], result["reason"]) == ("aborted", "stop requested")
            second = await move(holder, grant)
            (cell_stop,) = await zenoh_ask(stranger, "testcell/service/stop", None)
            assert cell_stop["ok"] is True
            result = await results.next(lambda r: r["goal_id"] == second["goal_id"])
            assert (result["status"], result["reason"]) == ("aborted", "cell stop requested")
            (stats,) = await zenoh_ask(stranger, "testcell/alice/service/cycle_stats", None)
            assert stats["ok"] is True, "cycle_stats reads counters: open to all"
        finally:
            holder.close()
            stranger.close()


async def test_acquire_without_a_liveliness_token_is_refused_naming_the_key(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from urdaemon.runtime import lease_keeper  # here: the test runs (and fails) on code without it

    monkeypatch.setattr(lease_keeper, "LEASE_BIND_TIMEOUT_S", 1.0)
    async with served() as (_, endpoint):
        session = open_session(endpoint)
        try:
            zid = secrets.token_hex(16)
            ask = {"action": "acquire", "session": zid, "holder": "tokenless"}
            (refused,) = await zenoh_ask(session, "testcell/alice/lease", ask)
            assert refused["ok"] is False
            assert f"testcell/alice/lease/{zid}" in refused["reason"]
            grant = await acquire_lease(session, "testcell", "alice")
            again = await acquire_lease(session, "testcell", "alice", session_id=grant.session_id)
            assert again.token == grant.token, "acquiring again with the same secret is idempotent"
            (released,) = await zenoh_ask(session, "testcell/alice/lease", {"action": "release"})
            assert released["ok"] is False, "release needs the token"
            (released,) = await zenoh_ask(
                session, "testcell/alice/lease", {"action": "release"}, attachment=grant.token
            )
            assert released["ok"] is True
            assert (await move(session, grant))["accepted"] is False, "released: the token is void"
        finally:
            session.close()


async def test_without_command_lease_any_session_commands_the_robot() -> None:
    async with served(TWO_MOCKS.replace("cell: testcell", "cell: testcell\ncommand_lease: false")) as (
        _,
        endpoint,
    ):
        session = open_session(endpoint)
        try:
            reply = await move(session, None)
            assert reply["accepted"] is True, reply
            (shown,) = await zenoh_ask(session, "testcell/alice/lease", {"action": "show"})
            assert shown["lease"] is None
            grant = await acquire_lease(session, "testcell", "alice", holder="advisory")
            assert grant.reply["lease"]["holder"] == "advisory"
            (stopped,) = await zenoh_ask(session, "testcell/alice/service/stop", None)
            assert stopped["ok"] is True
        finally:
            session.close()


async def test_a_flood_of_puts_without_the_token_never_reaches_the_loop(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """200 joint_position commands from a session without the lease, then one from the holder: none
    of the 200 is decoded or takes the holder's place waiting for the loop (refused on Zenoh's thread,
    reported in bounded ``command_rejected`` events that count them all); the holder's is acted on."""
    from urdaemon.publish import stream_commands

    seen: list[bytes] = []
    decoded = asyncio.Event()
    original = stream_commands.decode_stream_position

    def counted(payload: bytes | None) -> Any:
        seen.append(b"" if payload is None else bytes(payload))
        decoded.set()
        return original(payload)

    monkeypatch.setattr(stream_commands, "decode_stream_position", counted)
    async with served() as (daemon, endpoint):
        holder, stranger = open_session(endpoint), open_session(endpoint)
        try:
            # subscribed before the lease is asked for on the same session: the daemon has the
            # subscription before it grants the lease, so before the flood (another session's puts
            # could otherwise overtake the declaration, and the refusals' one event be lost)
            events = Inbox(holder, "testcell/alice/events")
            grant = await acquire_lease(holder, "testcell", "alice", holder="streamer")
            key = "testcell/alice/command/joint_position"
            assert daemon.node is not None
            latest = daemon.node.latest[key]
            count = 200
            for i in range(count):
                body = {"positions": [HOME[0] + 0.2, *HOME[1:]], "velocities": [0.0] * 5 + [i * 1e-9]}
                stranger.put(key, json.dumps(body).encode(), congestion_control=zenoh.CongestionControl.BLOCK)
            mine = json.dumps({"positions": HOME}).encode()
            holder.put(key, mine, attachment=grant.token)
            refused = 0
            for _ in range(count):
                event = await events.next(lambda e: e.get("kind") == "command_rejected")
                reason = event["reason"]
                assert reason.startswith("lease: robot 'alice' is held by streamer"), reason
                more = re.search(r"\(and (\d+) more refused like it\)$", reason)
                refused += 1 + (int(more.group(1)) if more else 0)
                if refused >= count:
                    break
            assert refused == count
            await asyncio.wait_for(decoded.wait(), WAIT_S)  # the holder's command reaches the loop
            assert seen == [mine], "only the holder's command was decoded"
            assert latest.replaced_total == 0, "no refused sample took the holder's place"
        finally:
            holder.close()
            stranger.close()


async def test_an_acquire_waiting_for_its_token_holds_up_no_other_request(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """An acquire whose liveliness token is not there yet waits for it (here up to 60 s) in a task of
    its own: meanwhile other sessions' lease requests and goals are answered; once the token appears
    the waiting acquire is granted."""
    from urdaemon.runtime import lease_keeper  # here: the test runs (and fails) on code without it

    monkeypatch.setattr(lease_keeper, "LEASE_BIND_TIMEOUT_S", 60.0)
    async with served() as (_, endpoint):
        late, other = open_session(endpoint), open_session(endpoint)
        try:
            zid = secrets.token_hex(16)
            ask = {"action": "acquire", "session": zid, "holder": "late binder"}
            waiting = asyncio.create_task(zenoh_ask(late, "testcell/alice/lease", ask, timeout=90.0))
            bob = await acquire_lease(other, "testcell", "bob", holder="bob's client")
            (goal,) = await zenoh_ask(
                other, "testcell/bob/goal/move", {"positions": TARGET, "duration": 1.0}, attachment=bob.token
            )
            assert goal["accepted"] is True, goal
            (shown,) = await zenoh_ask(other, "testcell/alice/lease", {"action": "show"})
            assert shown["lease"] is None
            assert not waiting.done(), "the acquire still waits for its token"
            token = late.liveliness().declare_token(f"testcell/alice/lease/{zid}")
            (granted,) = await asyncio.wait_for(waiting, WAIT_S)
            assert granted["ok"] is True, granted
            assert granted["lease"]["holder"] == "late binder"
            token.undeclare()
        finally:
            late.close()
            other.close()


def _shown_texts(*messages: dict[str, Any] | None) -> set[str]:
    """Every text a session without the lease can read in shown leases (a lease dict, or a message
    holding one under ``lease``/``previous``) that could name a token key: what an attacker could
    name."""
    texts: set[str] = set()
    for message in messages:
        for part in (message, (message or {}).get("lease"), (message or {}).get("previous")):
            if isinstance(part, dict):
                texts.update(v for v in part.values() if isinstance(v, str))
    return {text for text in texts if re.fullmatch(r"[\w-]+", text)}


async def test_naming_the_holders_shown_fingerprint_or_a_guess_gets_no_token() -> None:
    """Review 16 H1 (tests/review test_r_hijack): the holder's session id was shown by ``show`` and
    in events, and an acquire naming it (with a liveliness token on that key) got the holder's
    token and moved the robot. Now every text ``show`` and the status show of the lease, and a
    guess, each named with its own token and no force, is refused naming the holder and gets no
    token; a second session's own acquire without force is refused; the holder still commands."""
    async with served() as (_, endpoint):
        holder, attacker = open_session(endpoint), open_session(endpoint)
        try:
            statuses = Inbox(attacker, "testcell/alice/status")
            grant = await acquire_lease(holder, "testcell", "alice", holder="holder")
            (shown,) = await zenoh_ask(attacker, "testcell/alice/lease", {"action": "show"})
            status = await statuses.next(lambda m: m.get("lease") is not None)
            named = _shown_texts(shown, status) | {secrets.token_hex(16)}
            tokens = [attacker.liveliness().declare_token(f"testcell/alice/lease/{n}") for n in named]
            for name in sorted(named):
                ask = {"action": "acquire", "session": name, "holder": "attacker"}
                (reply,) = await zenoh_ask(attacker, "testcell/alice/lease", ask)
                assert reply["ok"] is False, (name, reply)
                assert "token" not in reply, reply
            for named_token in tokens:
                named_token.undeclare()
            assert grant.session_id not in json.dumps([shown, status]), "the secret is never shown"
            assert fingerprint(grant.session_id) in named, "the lease is shown by its fingerprint"
            own = secrets.token_hex(16)
            token = attacker.liveliness().declare_token(f"testcell/alice/lease/{own}")
            ask = {"action": "acquire", "session": own, "holder": "attacker"}
            (refused,) = await zenoh_ask(attacker, "testcell/alice/lease", ask)
            assert refused["ok"] is False
            assert refused["reason"].startswith("lease: robot 'alice' is held by holder since"), refused
            assert refused["lease"] == shown["lease"]
            token.undeclare()
            assert (await move(holder, grant))["accepted"] is True, "the holder still commands"
        finally:
            holder.close()
            attacker.close()


async def _seen_by_the_daemon(session: Any, key: str) -> None:
    """Wait until the daemon's session knows the liveliness token ``key`` (its liveliness query,
    routed by the daemon, answers it): a bounded number of queries, no sleeps."""
    for _ in range(100):
        replies = await asyncio.to_thread(lambda: list(session.liveliness().get(key, timeout=2.0)))
        if any(r.ok is not None and str(r.ok.key_expr) == key for r in replies):
            return
    raise AssertionError(f"{key}: never seen")


async def test_copies_of_every_key_a_stranger_can_learn_do_not_keep_a_gone_holders_lease() -> None:
    """Review 16 H2 (tests/review test_r_dup): another session declaring a liveliness token on the
    holder's key (learnt from ``show``) kept the lease, and the goal running, after the holder's
    session closed. Now a second session declares tokens on every key it can learn (the shown lease's
    texts, the ``acquired`` event's); the holder closes: its goal ends aborted naming it gone, the
    lease is free (judged by the daemon's messages)."""
    async with served() as (daemon, endpoint):
        holder, other, watcher = open_session(endpoint), open_session(endpoint), open_session(endpoint)
        try:
            results = Inbox(watcher, "testcell/alice/goal/*/result")
            events = Inbox(watcher, "testcell/alice/events")
            await _seen_by_the_daemon(watcher, "testcell/alice/alive")  # the inboxes are routed by now
            grant = await acquire_lease(holder, "testcell", "alice", holder="holder")
            acquired = await events.next(is_lease_event("acquired"))
            goal = await move(holder, grant)
            assert goal["accepted"] is True, goal
            (shown,) = await zenoh_ask(other, "testcell/alice/lease", {"action": "show"})
            learnt = sorted(_shown_texts(shown, acquired))
            keys = [f"testcell/alice/lease/{text}" for text in learnt]
            copies = [other.liveliness().declare_token(key) for key in keys]
            for key in keys:
                await _seen_by_the_daemon(watcher, key)
            holder.close()
            result = await results.next(lambda r: r["goal_id"] == goal["goal_id"])
            assert (result["status"], result["reason"]) == ("aborted", "lease holder holder is gone")
            (after,) = await zenoh_ask(watcher, "testcell/alice/lease", {"action": "show"})
            assert after["lease"] is None
            assert runtime(daemon).controller.active_goal_id is None
            assert len(copies) == len(keys) >= 1
        finally:
            other.close()
            watcher.close()


async def test_a_flood_of_tokens_keeps_no_state_and_every_acquire_is_still_granted() -> None:
    """Review 16 M1 (tests/review test_r_flood): 4096 liveliness tokens under ``<cell>/*/lease/*``
    filled the daemon's set of tokens and no acquire could be granted after. Now 5000 tokens (under
    another robot's key and under alice's) keep nothing: the same session's next acquire (its token
    reaches the daemon after the flood's) and another session's are granted, and the watch drops
    every flood token as it comes (keeping state for the two holders' keys only)."""
    async with served() as (daemon, endpoint):
        attacker, client = open_session(endpoint), open_session(endpoint)
        try:
            flood = [
                attacker.liveliness().declare_token(f"testcell/{'alice' if i % 2 else 'zz'}/lease/s{i:05d}")
                for i in range(5000)
            ]
            bob = await acquire_lease(attacker, "testcell", "bob", holder="after the flood")
            alice = await acquire_lease(client, "testcell", "alice", holder="legit")
            assert bob.reply["ok"] is True
            assert alice.reply["ok"] is True
            watch = runtime(daemon).lease.watch
            assert watch is not None
            for _ in range(1000):  # the flood's samples, on Zenoh's threads, may still be arriving
                if watch.ignored >= len(flood):
                    break
                await asyncio.sleep(0.01)
            assert len(flood) == 5000
            assert watch.ignored >= len(flood), "every flood token dropped as it came: nothing kept"
            for robot, grant in (("bob", bob), ("alice", alice)):
                assert watch.alive(f"testcell/{robot}/lease/{grant.session_id}"), "the holders' kept"
        finally:
            attacker.close()
            client.close()


def _send(session: Any, key: str, body: dict[str, Any], attachment: bytes) -> asyncio.Future[dict[str, Any]]:
    """Send a query now (no await: the loop does not run) and give its first reply as a future."""
    loop = asyncio.get_running_loop()
    answer: asyncio.Future[dict[str, Any]] = loop.create_future()

    def settle(body: dict[str, Any]) -> None:
        if not answer.done():
            answer.set_result(body)

    def on_reply(reply: Any) -> None:
        body = json.loads(bytes(reply.ok.payload.to_bytes())) if reply.ok is not None else {"error": 1}
        loop.call_soon_threadsafe(settle, body)

    session.get(key, on_reply, payload=json.dumps(body).encode(), attachment=attachment, timeout=WAIT_S)
    return answer


class _FakeQuery:
    """A release query as the lease keeper reads it (handed straight to it, on the loop)."""

    def __init__(self, token: bytes) -> None:
        self.key_expr = "testcell/alice/lease"
        self.payload = zenoh.ZBytes(json.dumps({"action": "release"}).encode())
        self.attachment = zenoh.ZBytes(token)
        self.replies: list[dict[str, Any]] = []

    def reply(self, _key: str, body: bytes) -> None:
        self.replies.append(json.loads(body))

    def drop(self) -> None:
        pass


@pytest.mark.parametrize("message", ["goal", "stream"])
async def test_a_message_that_passed_the_check_before_the_lease_ended_is_refused_on_the_loop(
    message: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Review 16 M2 (tests/review test_r_race): a goal that passed the lease check on Zenoh's thread
    while its sender held the lease, and waited for the loop, was accepted after a take-over. Driven
    in order: the holder's move goal (or joint_position put) passes the check (the test holds the
    loop until it did), then the lease is released in the same loop turn; when the loop reaches the
    message it is refused naming the lease (the goal's reply, or a ``command_rejected`` event), and
    the robot never moves."""
    async with served() as (daemon, endpoint):
        holder, watcher = open_session(endpoint), open_session(endpoint)
        try:
            events = Inbox(watcher, "testcell/alice/events")
            await _seen_by_the_daemon(watcher, "testcell/alice/alive")
            grant = await acquire_lease(holder, "testcell", "alice", holder="old holder")
            alice = runtime(daemon)
            check = alice.lease.book.refusal
            passed = threading.Event()

            def spied(attachment: bytes | None) -> str | None:
                refusal: str | None = check(attachment)
                if refusal is None:
                    passed.set()
                return refusal

            monkeypatch.setattr(alice.lease.book, "refusal", spied)
            if message == "goal":
                body = {"positions": TARGET, "duration": 1.0}
                goal = _send(holder, "testcell/alice/goal/move", body, grant.token)
            else:
                stream = json.dumps({"positions": TARGET}).encode()
                holder.put("testcell/alice/command/joint_position", stream, attachment=grant.token)
            # the loop waits here until the message is past Zenoh's thread's check
            assert passed.wait(WAIT_S), "the holder's message never reached the check"
            release = _FakeQuery(grant.token)
            alice.lease.on_query(release)
            assert [r["ok"] for r in release.replies] == [True], release.replies
            if message == "goal":
                refused = await asyncio.wait_for(goal, WAIT_S)
                assert refused["accepted"] is False, refused
            else:
                refused = await events.next(on_key("testcell/alice/command/joint_position"))
                assert refused["kind"] == "command_rejected"
            assert refused["reason"].startswith("lease: robot 'alice' needs its command lease"), refused
            assert alice.controller.mode == "idle"
            assert alice.state.positions == pytest.approx(HOME, abs=1e-9)
        finally:
            holder.close()
            watcher.close()
