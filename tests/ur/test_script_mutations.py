"""Corrupted copies of our control script are refused by the fake at compile time, as a controller does.

Each mutation corrupts the script the ``ur`` backend renders (``urdaemon.urscript.render_control_script``,
which the backend calls for every program it sends: the test swaps it for one that corrupts the
rendering) and sends it as the backend does (headless: ``stop program`` and a tab-indented
``def externalControl():``). The fake must refuse the program before it starts: a
RuntimeExceptionMessage naming the line and column of the fault (in the program as sent, ``def`` line
= 1, a tab before every line of ours), no callback connection ever, and the daemon publishes the
controller's words as a ``robot_message`` event and says why the robot is not ready.

Reproduction on the code before issue 14: the fake's stand-in only pulled the ``socket_open`` calls out
of the text, so every corrupted copy here "ran" and connected back (the links came up, the robot was
ready).
"""

from __future__ import annotations

import asyncio
import contextlib
import re
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass
from typing import Any

import pytest

import urdaemon.urscript
from tests.helpers import fake_address, free_tcp_port
from tests.integration.conftest import running_daemon
from tests.ur.test_links_harness import JOINTS, UrRun, program_is_running, ur_run
from urdaemon.backends.ur.backend import UrBackend
from urdaemon.cell.load import parse_cell
from urdaemon.errors import UrDaemonError
from urdaemon.fakeur.controller import FakeController
from urdaemon.protocols import primary as prim
from urdaemon.protocols._buffer import Side

pytestmark = pytest.mark.timeout(120)

HOME = (0.0, -1.57, 1.57, -1.57, -1.57, 0.0)
_EXCEPTION = re.compile(r"runtime exception at (\d+):(\d+): (.+)", re.DOTALL)


@dataclass(frozen=True)
class Where:
    """Where the controller must place the fault, in the program as sent: a line range and, on the
    first line of that range, a column range (``None``: any column)."""

    lines: tuple[int, int]
    columns: tuple[int, int] | None = None

    def matches(self, line: int, column: int) -> bool:
        if not self.lines[0] <= line <= self.lines[1]:
            return False
        if self.columns is None or line != self.lines[0]:
            return column >= 1
        return self.columns[0] <= column <= self.columns[1]


@dataclass(frozen=True)
class Mutation:
    """Replace the one occurrence of ``old`` in the rendered script by ``new``; the fault lies at
    ``new[start:end]`` (on that line), or anywhere from there to ``lines_after`` lines further."""

    name: str
    old: str
    new: str
    fault: str
    """The text of ``new`` the controller must point at (its first occurrence in ``new``)."""
    lines_after: int = 0
    """The fault may be reported this many lines later (a missing token is seen at the next one)."""
    any_column: bool = False
    anywhere: bool = False
    """Any line will do: where a missing ``end`` shows depends on how the parser pairs the others."""

    def apply(self, script: str) -> tuple[str, Where]:
        """The corrupted script and where its fault lies in the program the backend sends."""
        assert script.count(self.old) == 1, f"{self.name}: {self.old!r} occurs {script.count(self.old)} times"
        at = script.index(self.old) + self.new.index(self.fault)
        corrupted = script.replace(self.old, self.new)
        line = corrupted.count("\n", 0, at) + 1
        column = at - (corrupted.rfind("\n", 0, at) + 1) + 1
        # as sent: "def externalControl():" is line 1 and every line of ours starts with a tab
        first = line + 1
        if self.anywhere:
            return corrupted, Where((1, corrupted.count("\n") + 3))
        if self.any_column:
            return corrupted, Where((first, first + self.lines_after))
        columns = (column + 1, column + len(self.fault))
        return corrupted, Where((first, first + self.lines_after), columns)


MUTATIONS = [
    Mutation(
        "missing end",
        "raw[first + 2] / UD_MULT]\nend\n",
        "raw[first + 2] / UD_MULT]\n# end\n",
        "# end",
        # blocks nest and indentation means nothing: each later `end` closes the wrong block, and
        # the one left open may be reported (the program's own `def`, line 1) as well as the place
        # where the pairing breaks
        anywhere=True,
    ),
    Mutation("unknown builtin", "UD_STEP = get_steptime()", "UD_STEP = get_steptiem()", "get_steptiem"),
    Mutation(
        "wrong argument count",
        "UD_VIOLATION_LOG_EVERY = floor(5.0 / UD_STEP)",
        "UD_VIOLATION_LOG_EVERY = floor(5.0 / UD_STEP, 2)",
        "floor(5.0 / UD_STEP, 2)",
    ),
    Mutation(
        "unknown keyword argument",
        'popup(why, title="urdaemon speed check", warning=True, blocking=False)',
        'popup(why, title="urdaemon speed check", warnings=True, blocking=False)',
        'popup(why, title="urdaemon speed check", warnings=True, blocking=False)',
    ),
    Mutation(
        "undefined variable",
        "return floor(scaled / UD_MULT + 0.5)",
        "return floor(scaled / UD_MULTT + 0.5)",
        "UD_MULTT",
    ),
    Mutation(
        "wrong socket name",
        'socket_read_binary_integer(UD_COMMAND_INTS, "script_command_socket", 0)',
        'socket_read_binary_integer(UD_COMMAND_INTS, "script_comand_socket", 0)',
        'socket_read_binary_integer(UD_COMMAND_INTS, "script_comand_socket", 0)',
    ),
    Mutation(
        "misspelled servoj",
        "servoj(q, t=UD_STEP, lookahead_time=UD_SERVO_LOOKAHEAD, gain=UD_SERVO_GAIN)",
        "sevroj(q, t=UD_STEP, lookahead_time=UD_SERVO_LOOKAHEAD, gain=UD_SERVO_GAIN)",
        "sevroj",
    ),
    Mutation(
        "unclosed bracket",
        "ud_speed_qd = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]\n    ud_speed_age",
        "ud_speed_qd = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0\n    ud_speed_age",
        "\n",
        lines_after=1,  # the next token shows the list is not closed
        any_column=True,
    ),
    Mutation(
        "stray elif",
        "  end\n  stopj(UD_STOPJ_ACCEL)\nend\n\nthread ud_speed_loop",
        "  end\n  elif ud_mode == 0:\n  stopj(UD_STOPJ_ACCEL)\nend\n\nthread ud_speed_loop",
        "elif",
    ),
    Mutation(
        "missing colon",
        "while attempt < UD_CONNECT_ATTEMPTS:",
        "while attempt < UD_CONNECT_ATTEMPTS",
        "UD_CONNECT_ATTEMPTS",
        lines_after=1,  # the next token shows the colon is missing
        any_column=True,
    ),
    Mutation(
        "thread with arguments",
        "thread ud_servo_loop():",
        "thread ud_servo_loop(q):",
        "thread ud_servo_loop(q):",
    ),
    Mutation(
        "unterminated string",
        'textmsg("urdaemon: trajectory canceled")',
        'textmsg("urdaemon: trajectory canceled)',
        '"urdaemon: trajectory canceled)',
        any_column=True,
    ),
]


def wrapped_block(script: str) -> str:
    """The program block the fake compiles: what ``headless_program`` sends after ``stop program``."""
    return prim.def_program("externalControl", script, indent="\t")


def corrupting(mutation: Mutation, seen: list[Where]) -> Callable[..., str]:
    """A stand-in for ``render_control_script`` that corrupts the real rendering by ``mutation``."""
    render = urdaemon.urscript.render_control_script

    def corrupted(params: Any) -> str:
        text, where = mutation.apply(render(params))
        seen.append(where)
        return text

    return corrupted


def _exceptions(run: UrRun) -> list[tuple[int, int, str]]:
    found = []
    for kind, text in run.notices:
        match = _EXCEPTION.fullmatch(text)
        if kind == "robot_message" and match:
            found.append((int(match[1]), int(match[2]), match[3]))
    return found


def _count_links(run: UrRun) -> list[str]:
    """The names of the callback links that ever connected while the test watched."""
    links: list[str] = []
    on_link = run.backend.on_link

    def counting(name: str, connected: bool, reason: str) -> None:
        if connected:
            links.append(name)
        on_link(name, connected, reason)

    run.backend.on_link = counting  # type: ignore[method-assign]
    return links


RESTARTS = 5
"""How often a test starts the backend's ``run`` again after a lost link, as the daemon's runtime does."""


async def _until(run: UrRun, predicate: Callable[[], bool], what: str, restarts: list[str]) -> None:
    """Wait until ``predicate()`` holds. ``run`` raises when a link drops (on a busy machine the RTDE
    link may miss its watchdog); like the daemon's runtime, start it again (at most ``RESTARTS`` times)
    and say so in ``restarts``: the program the backend sends then is still the corrupted one."""
    for _ in range(RESTARTS + 1):
        assert run.task is not None
        backend = run.task
        waiter = asyncio.create_task(run.until(predicate, timeout=60.0, what=what))
        await asyncio.wait({waiter, backend}, return_when=asyncio.FIRST_COMPLETED)
        if waiter.done() and (waiter.cancelled() or waiter.exception() is None or not backend.done()):
            waiter.result()
            return
        # the backend ended: ``until`` may have seen it first and raised the backend's own error
        waiter.cancel()
        with contextlib.suppress(BaseException):
            await waiter
        error = backend.exception()
        if not isinstance(error, UrDaemonError):
            raise AssertionError(f"the backend's run ended before {what}: {error!r}")
        restarts.append(repr(error))
        run.start()
    raise AssertionError(f"the backend lost a link {RESTARTS + 1} times before {what}: {restarts}")


@pytest.mark.parametrize("mutation", MUTATIONS, ids=[m.name for m in MUTATIONS])
async def test_a_corrupted_control_script_is_refused_with_line_and_column(
    mutation: Mutation, monkeypatch: pytest.MonkeyPatch
) -> None:
    seen: list[Where] = []
    monkeypatch.setattr(urdaemon.urscript, "render_control_script", corrupting(mutation, seen))
    async with ur_run(start=False) as run:
        connected = _count_links(run)
        run.start()
        # the backend sends the program again after PROGRAM_RESEND_S: two refusals leave seconds in
        # which a program that had started would have connected back
        restarts: list[str] = []
        await _until(run, lambda: len(_exceptions(run)) >= 2, "two refusals of the program", restarts)
        assert seen, "the backend rendered the control script through render_control_script"
        where = seen[0]
        line, column, text = _exceptions(run)[0]
        assert where.matches(line, column), (
            f"{mutation.name}: the fault is at {where}, the fake said {line}:{column}"
        )
        assert text.strip(), "the controller's message says what is wrong"
        assert connected == [], f"the refused program connected back: {connected}"
        assert not run.ready
        reason = run.backend.state.lifecycle_reason
        assert f"runtime exception at {line}:{column}" in reason, f"status reason: {reason!r}"
        assert not run.fake.arm.program_running


CB3_MUTATIONS = [
    MUTATIONS[1],  # unknown builtin
    MUTATIONS[5],  # wrong socket name
    Mutation(
        "a builtin this controller does not have",
        "local steps_back = 0",
        "local steps_back = 0\n  direct_torque([0.0, 0.0, 0.0, 0.0, 0.0, 0.0])",
        "direct_torque",
    ),
]
"""Corruptions of the CB3 rendering (controller 3.15): direct_torque came with e-Series 5.23. (Not
tool_contact: CB3 3.14 compiles urcl's script, which names it behind a version check.)"""


@contextlib.asynccontextmanager
async def cb3_run() -> AsyncIterator[UrRun]:
    """A CB3 UR10 fake (controller 3.15, 125 Hz) and a ``UrBackend`` for it, not started."""
    address = fake_address()
    ports = [free_tcp_port() for _ in range(4)]
    robot = parse_cell(
        f"""
cell: cb3
robots:
  - name: alice
    model: ur10
    backend: ur
    address: {address}
    ports:
      {{reverse: {ports[0]}, script_sender: {ports[1]}, trajectory: {ports[2]}, script_command: {ports[3]}}}
    ur: {{startup: true, listen_address: 127.0.0.1}}
"""
    ).robots[0]
    fake = FakeController(
        "ur10", address=address, initial_positions=HOME, powered=True, controller_version=(3, 15, 7, 0)
    )
    await fake.start()
    run = UrRun(UrBackend(robot, JOINTS, expected_hash=None), fake)
    try:
        yield run
    finally:
        await run.stop()
        await fake.close()


@pytest.mark.parametrize("mutation", CB3_MUTATIONS, ids=[m.name for m in CB3_MUTATIONS])
async def test_a_corrupted_cb3_control_script_is_refused_with_line_and_column(
    mutation: Mutation, monkeypatch: pytest.MonkeyPatch
) -> None:
    seen: list[Where] = []
    monkeypatch.setattr(urdaemon.urscript, "render_control_script", corrupting(mutation, seen))
    async with cb3_run() as run:
        connected = _count_links(run)
        run.start()
        restarts: list[str] = []
        await _until(run, lambda: len(_exceptions(run)) >= 2, "two refusals of the program", restarts)
        line, column, _ = _exceptions(run)[0]
        assert seen[0].matches(line, column), (
            f"{mutation.name}: the fault is at {seen[0]}, the fake said {line}:{column}"
        )
        assert connected == [], f"the refused program connected back: {connected}"
        assert f"runtime exception at {line}:{column}" in run.backend.state.lifecycle_reason


async def test_the_uncorrupted_script_runs_and_connects_back(monkeypatch: pytest.MonkeyPatch) -> None:
    """The harness above can see a program start: the same path with the rendering left intact."""
    seen: list[Where] = []
    intact = Mutation("intact", "UD_STEP = get_steptime()", "UD_STEP = get_steptime()", "get_steptime")
    monkeypatch.setattr(urdaemon.urscript, "render_control_script", corrupting(intact, seen))
    async with ur_run(start=False) as run:
        connected = _count_links(run)
        run.start()
        await _until(run, lambda: program_is_running(run), "the program connects back", [])
        assert seen
        assert sorted(set(connected)) == ["reverse", "script_command", "trajectory"]
        assert _exceptions(run) == []


async def _primary_messages(address: str, script: bytes, count: int) -> list[Any]:
    """Send raw ``script`` bytes on the fake's primary interface; the first ``count`` robot messages."""
    reader, writer = await asyncio.open_connection(address, 30001)
    conn = prim.PrimaryConnection(Side.DAEMON)
    messages: list[Any] = []
    try:
        writer.write(script)
        await writer.drain()
        async with asyncio.timeout(20.0):
            while len(messages) < count:
                data = await reader.read(65536)
                assert data, f"the fake closed the primary connection; it said: {messages}"
                messages.extend(
                    e
                    for e in conn.receive_data(data)
                    if not isinstance(e, prim.RobotState | prim.VersionMessage)
                )
    finally:
        writer.close()
    return messages


async def test_a_non_ascii_character_is_refused_with_its_line_and_column() -> None:
    """The daemon never sends one (its codec refuses non-ASCII text), so the corrupted copy goes to the
    fake's primary interface directly, as any client could send it."""
    script = urdaemon.urscript.render_control_script(
        urdaemon.urscript.ScriptParameters(server_ip="127.0.0.1")
    )
    old = 'textmsg("urdaemon: trajectory canceled")'
    assert script.count(old) == 1
    at = script.index(old) + len('textmsg("urdaemon: trajectory canc')
    corrupted = script.replace(old, 'textmsg("urdaemon: trajectory canc\u00e9led")')
    line = corrupted.count("\n", 0, at) + 2  # as sent: the def line first
    column = at - (corrupted.rfind("\n", 0, at) + 1) + 2  # and a tab
    sent = ("stop program\n" + wrapped_block(corrupted)).encode("utf-8")
    address = fake_address()
    async with FakeController("ur10e", address=address, initial_positions=HOME, powered=True) as fake:
        messages = await _primary_messages(address, sent, 1)
        exceptions = [m for m in messages if isinstance(m, prim.RuntimeExceptionMessage)]
        assert exceptions, f"no runtime exception message; the fake said {messages}"
        assert (exceptions[0].line, exceptions[0].column) == (line, column), exceptions[0]
        assert not fake.arm.program_running


def _cell(address: str) -> str:
    ports = [free_tcp_port() for _ in range(4)]
    return f"""
cell: mutations
robots:
  - name: alice
    model: ur10e
    backend: ur
    address: {address}
    ports:
      {{reverse: {ports[0]}, script_sender: {ports[1]}, trajectory: {ports[2]}, script_command: {ports[3]}}}
    ur: {{startup: true, listen_address: 127.0.0.1}}
"""


async def _first(sub: Any, predicate: Callable[[dict[str, Any]], bool], limit: int = 400) -> dict[str, Any]:
    for _ in range(limit):
        message: dict[str, Any] = await sub.get_json(timeout=20.0)
        if predicate(message):
            return message
    raise AssertionError("no matching message")


@pytest.fixture
async def corrupted_daemon(monkeypatch: pytest.MonkeyPatch) -> AsyncIterator[tuple[Any, list[Where]]]:
    seen: list[Where] = []
    mutation = MUTATIONS[1]  # unknown builtin
    monkeypatch.setattr(urdaemon.urscript, "render_control_script", corrupting(mutation, seen))
    address = fake_address()
    async with (
        FakeController("ur10e", address=address, initial_positions=HOME, powered=True),
        running_daemon(_cell(address)) as (_, client),
    ):
        yield client, seen


async def test_the_daemon_publishes_the_refusal_and_why_the_robot_is_not_ready(
    corrupted_daemon: tuple[Any, list[Where]],
) -> None:
    client, seen = corrupted_daemon
    alice = await client.robot("alice")
    events = client.subscribe(alice.keys.events, 100)
    status = client.subscribe(alice.keys.status, 100)
    try:
        event = await _first(
            events, lambda e: e["kind"] == "robot_message" and "runtime exception" in e["text"]
        )
        match = _EXCEPTION.fullmatch(event["text"])
        assert match, event
        assert seen[0].matches(int(match[1]), int(match[2])), (seen[0], event["text"])
        assert "get_steptiem" in match[3], "the controller names the unknown function"
        said = await _first(status, lambda s: f"runtime exception at {match[1]}:{match[2]}" in s["reason"])
        assert said["ready"] is False
    finally:
        client.unsubscribe(events)
        client.unsubscribe(status)
