"""Goals beside CPU burners: the fake-controller cell on a busy PC (issue 32, "What it must show").

    python benchmarks/hiccups.py                          # 2 burners, 50 goals, a 60 s stream
    python benchmarks/hiccups.py --burners 0              # the same on a quiet machine
    python benchmarks/hiccups.py --goals 2 --seconds 2 --burners 0   # the smoke run of the tests

Every process is separate, as in benchmarks/control_loop.py: N CPU burners (``python -c 'while 1:
pass'``, nice 0, for the whole run), the fake controllers of a two-robot cell (alice, a UR10e, and
bob, a UR3e; ``urdaemon fake-robot``, at addresses of a random 127.a.b.0/24) and the daemon
(``urdaemon serve``, Zenoh on 127.0.0.1 at an OS-given port); this process is the client.

Printed, with the machine and its load:
1. ``--goals`` point-to-point move goals, alternating alice and bob, one after the other: how many
   succeeded, were aborted, ended otherwise or gave no result; each failure's reason.
2. a ``--seconds`` servoj stream on alice (a trajectory goal, streamed by the daemon with servoj every
   cycle, as control_loop.py does): its result, and the stale-command figures:
   - the daemon's side: missed and late cycles and the worst turnaround (``cycle_stats``), and the
     biggest gap between two consecutive ``joint_states`` of alice (their ``host_time_ns``, stamped by
     the daemon when the state arrived; a frame leaves in every cycle that publishes, so this is the
     longest the robot went without a fresh frame, or a message lost on the way here: an upper bound);
   - the robot's side: the **deviation** of the arm from the commanded path, max over joints of
     |desired − actual| in the goal's feedback (100 Hz, and in the first cycle after any gap):
     ``desired`` is the daemon's setpoint for that controller time, ``actual`` the fake's RTDE
     ``actual_q``. Its median is servoj's ordinary tracking lag; its maximum, when it stands above the
     median, is the worst motion on stale commands (the arm extrapolating or stopping while the daemon
     was late); the control program's own words for a hold are counted in the fake's log.
3. the same stream goal with alice's program killed mid-goal (the daemon's ``dashboard`` service,
   ``stop``) and, headless, sent again by the daemon: how many results the goal got (one), what it
   says, the time until alice was ready again, and a move goal after that.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import importlib.util
import os
import shutil
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import Any

from urdaemon.client import GoalHandle, RobotClient
from urdaemon.errors import UrDaemonError

ROOT = Path(__file__).resolve().parents[1]
CELL = "hiccups"
UR_PORTS = (29999, 30001, 30002, 30003, 30004)
"""The controller's fixed ports a fake listens on at its own address."""
HOME = [0.0, -1.57, 1.57, -1.57, -1.57, 0.0]
MOVE_OFFSET = 0.3
"""rad, every joint: the move goals go out to HOME ± this and back."""
RESULT_TIMEOUT_S = 60.0
"""A goal without a result after this long is counted as lost (no goal lasts that long here)."""
KILL_AFTER_S = 3.0
FEEDBACK_RATE_HZ = 100.0
HOLD_WORDS = ("no command for", "caught up with the commands")
"""What the control program says when it holds or stops on stale commands, and when it caught up."""


def _control_loop() -> ModuleType:
    """benchmarks/control_loop.py: its process handling, machine description and trajectories."""
    spec = importlib.util.spec_from_file_location(
        "bench_control_loop", ROOT / "benchmarks" / "control_loop.py"
    )
    assert spec is not None
    assert spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


CL = _control_loop()


@dataclass
class Goals:
    """Part 1: the move goals."""

    sent: int = 0
    statuses: dict[str, int] = field(default_factory=dict)
    failures: list[str] = field(default_factory=list)
    lost: int = 0
    cycles: dict[str, dict[str, Any]] = field(default_factory=dict)

    def count(self, status: str) -> int:
        return self.statuses.get(status, 0)


@dataclass
class Stream:
    """Part 2: the servoj stream."""

    status: str
    reason: str
    duration: float
    cycles: dict[str, Any]
    gaps: Gaps
    deviation_median: float
    deviation_p99: float
    deviation_max: float
    deviation_at: float
    feedback: int
    holds: dict[str, int]


@dataclass
class Killed:
    """Part 3: the stream goal with the program killed mid-goal."""

    result: str
    """What the goal handle's result says."""
    published: list[str]
    """Every result message of the goal seen on its result key."""
    ready_again_s: float | None
    after: str


# ---- the cell and the processes ------------------------------------------------------------------


def _ports_free(address: str) -> bool:
    """Whether a fake could listen on all of UR's ports at ``address`` right now."""
    with contextlib.ExitStack() as stack:
        for port in UR_PORTS:
            sock = stack.enter_context(socket.socket(socket.AF_INET, socket.SOCK_STREAM))
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            try:
                sock.bind((address, port))
            except OSError:
                return False
    return True


def addresses() -> tuple[str, str]:
    """Two fake addresses in a random 127.a.b.0/24 (never 127.0.0.x, where other runs sit)."""
    for _ in range(100):
        a, b = (1 + x % 254 for x in os.urandom(2))
        pair = (f"127.{a}.{b}.5", f"127.{a}.{b}.6")
        if all(_ports_free(address) for address in pair):
            return pair
    raise RuntimeError("no free pair of fake addresses in 100 tries")


def cell_yaml(alice: str, bob: str) -> str:
    """The fake-controller cell (configs/dual_robot_fake.yaml's robots) at ``alice`` and ``bob``, with
    OS-given callback ports and goal feedback at FEEDBACK_RATE_HZ."""
    lines = [f"cell: {CELL}", "zenoh: {mode: peer, multicast_scouting: false}", "robots:"]
    for i, (name, model, address) in enumerate((("alice", "ur10e", alice), ("bob", "ur3e", bob))):
        p = [CL.free_port() for _ in range(4)]
        lines += [
            f"  - name: {name}",
            f"    model: {model}",
            "    backend: ur",
            f"    address: {address}",
            "    headless: true",
            f"    ports: {{reverse: {p[0]}, script_sender: {p[1]}, trajectory: {p[2]}, "
            f"script_command: {p[3]}}}",
            f"    pose: {{parent: world, xyz: [{0.5 - i:.1f}, 0.0, 0.0], rpy: [0.0, 0.0, 0.0]}}",
            f"    motion: {{feedback_rate_hz: {FEEDBACK_RATE_HZ:g}}}",
            "    ur: {startup: true, listen_address: 127.0.0.1}",
        ]
    return "\n".join(lines) + "\n"


def start_burners(count: int) -> list[subprocess.Popen[bytes]]:
    """``count`` CPU burners at nice 0, each in its own session."""
    argv = [sys.executable, "-c", "while 1: pass"]
    return [subprocess.Popen(argv, start_new_session=True) for _ in range(count)]


def stop_burners(burners: list[subprocess.Popen[bytes]]) -> None:
    for proc in burners:
        with contextlib.suppress(ProcessLookupError):
            proc.kill()
        proc.wait(10.0)


@contextlib.contextmanager
def running_cell(keep: Path | None, pair: tuple[str, str] | None = None) -> Iterator[tuple[Any, str]]:
    """The fakes and the daemon in their own processes (the fakes at ``pair``, or at ``addresses()``);
    yields (processes, Zenoh endpoint)."""
    with tempfile.TemporaryDirectory(prefix="urdaemon-hiccups-") as tmp:
        procs = CL.Processes(Path(tmp))
        config = procs.logs / "cell.yaml"
        config.write_text(cell_yaml(*(pair or addresses())))
        endpoint = f"tcp/127.0.0.1:{CL.free_port()}"
        try:
            procs.start("fake", CL.urdaemon("fake-robot", "--config", str(config), "--powered"))
            procs.start("daemon", CL.urdaemon("serve", "--config", str(config), "--listen", endpoint))
            yield procs, endpoint
        finally:
            procs.stop_all()
            if keep is not None:
                run = keep / time.strftime("%H%M%S")
                shutil.copytree(procs.logs, run, dirs_exist_ok=True)
                print(f"logs: {run}", file=sys.stderr)


# ---- the parts ---------------------------------------------------------------------------------------


async def ending(goal: GoalHandle) -> tuple[str, str]:
    """(status, reason) of the goal's one result; ("lost", why) without one within RESULT_TIMEOUT_S."""
    try:
        result = await goal.result(timeout=RESULT_TIMEOUT_S)
    except UrDaemonError as err:
        return "lost", str(err)
    return str(result["status"]), str(result.get("reason", ""))


async def ready(robot: RobotClient, procs: Any) -> None:
    await CL.wait_status(robot, procs, lambda s: s["ready"], "ready")


async def stats_window(robots: list[RobotClient]) -> dict[str, dict[str, Any]]:
    """Start a new turnaround window on every robot; their cycle counters now (they only grow: the
    reset starts a new turnaround window only, as control_loop.py knows)."""
    return {robot.name: await robot.cycle_stats(reset=True) for robot in robots}


async def stats(robot: RobotClient, before: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """Cycles, missed and late since ``before``, and the window's worst turnaround."""
    reply, start = await robot.cycle_stats(), before[robot.name]
    return {
        "missed": reply["missed_cycles"] - start["missed_cycles"],
        "late": reply["late_cycles"] - start["late_cycles"],
        "cycles": reply["cycles"] - start["cycles"],
        "max_us": reply["turnaround"]["max_us"],
    }


async def move_goals(robots: list[RobotClient], goals: int, procs: Any) -> Goals:
    """``goals`` moves, alternating robots, each out to HOME ± MOVE_OFFSET and back."""
    out = Goals()
    before = await stats_window(robots)
    for i in range(goals):
        robot = robots[i % len(robots)]
        sign = 1.0 if (i // len(robots)) % 2 == 0 else -1.0
        target = [q + sign * MOVE_OFFSET for q in HOME]
        procs.check()
        try:
            goal = await robot.move(target, velocity_scale=0.5, acceleration_scale=0.5)
        except UrDaemonError as err:
            out.statuses["refused"] = out.count("refused") + 1
            out.failures.append(f"goal {i} on {robot.name}: refused: {err}")
            continue
        out.sent += 1
        status, reason = await ending(goal)
        out.statuses[status] = out.count(status) + 1
        if status != "succeeded":
            out.failures.append(f"goal {i} on {robot.name}: {status}: {reason}")
            with contextlib.suppress(RuntimeError):
                await ready(robot, procs)
    out.lost = out.count("lost")
    for robot in robots:
        out.cycles[robot.name] = await stats(robot, before)
    return out


@dataclass
class Gaps:
    """Gaps between consecutive ``joint_states`` of a robot, in ms, each with the other clock's gap."""

    host: tuple[float, float] = (0.0, 0.0)
    """The biggest gap of ``host_time_ns`` (the daemon's clock), with ``controller_time``'s there."""
    controller: tuple[float, float] = (0.0, 0.0)
    """The biggest gap of ``controller_time`` (the robot's clock), with ``host_time_ns``'s there."""
    states: int = 0
    dropped: int = 0

    def add(self, host_ms: float, controller_ms: float) -> None:
        self.host = max(self.host, (host_ms, controller_ms))
        self.controller = max(self.controller, (controller_ms, host_ms))


async def follow_states(robot: RobotClient, stop: asyncio.Event) -> Gaps:
    """The gaps between consecutive joint_states of ``robot`` until ``stop``."""
    sub = robot.joint_states(5000)
    gaps, last = Gaps(), None
    try:
        while not stop.is_set():
            with contextlib.suppress(UrDaemonError):
                state = await sub.get_json(timeout=0.5)
                now = (int(state["host_time_ns"]) / 1e6, float(state["controller_time"]) * 1e3)
                if last is not None:
                    gaps.add(now[0] - last[0], now[1] - last[1])
                last, gaps.states = now, gaps.states + 1
        gaps.dropped = sub.dropped
        return gaps
    finally:
        sub.close()


def deviation(feedback: dict[str, Any]) -> float:
    """max over joints of |desired − actual| (rad)."""
    return max(abs(float(d) - float(a)) for d, a in zip(feedback["desired"], feedback["actual"], strict=True))


def count_holds(procs: Any) -> dict[str, int]:
    """How often the control program said each of HOLD_WORDS so far (its messages, in the daemon's log)."""
    text = (procs.logs / "daemon.log").read_text(errors="replace")
    return {words: text.count(words) for words in HOLD_WORDS}


async def stream(robot: RobotClient, seconds: float, procs: Any) -> Stream:
    """A servoj stream of ``seconds`` (at least one 5 s period) on ``robot``, measured."""
    await ready(robot, procs)
    before, said = await stats_window([robot]), count_holds(procs)
    stop = asyncio.Event()
    states = asyncio.ensure_future(follow_states(robot, stop))
    goal = await robot.send_trajectory(CL.sinusoid(await CL.first_position(robot), seconds))
    devs: list[tuple[float, float]] = []
    with contextlib.suppress(UrDaemonError):
        async for fb in goal.feedback():
            devs.append((deviation(fb), float(fb["time_from_start"])))
    status, reason = await ending(goal)
    stop.set()
    gaps = await states
    cycles = await stats(robot, before)
    values = sorted(d for d, _ in devs) or [float("nan")]
    worst = max(devs, default=(float("nan"), float("nan")))
    duration = float((await goal.result(timeout=5.0)).get("duration", 0.0)) if status != "lost" else 0.0
    return Stream(
        status=status,
        reason=reason,
        duration=duration,
        cycles=cycles,
        gaps=gaps,
        deviation_median=statistics.median(values),
        deviation_p99=values[min(len(values) - 1, int(0.99 * len(values)))],
        deviation_max=worst[0],
        deviation_at=worst[1],
        feedback=len(devs),
        holds={words: n - said[words] for words, n in count_holds(procs).items()},
    )


async def killed(robot: RobotClient, seconds: float, procs: Any) -> Killed:
    """The stream goal with the program killed after KILL_AFTER_S (or half the goal); every result of
    the goal on its result key is counted, until the robot is ready again and a move has ended."""
    await ready(robot, procs)
    goal = await robot.send_trajectory(CL.sinusoid(await CL.first_position(robot), seconds))
    results = robot.client.subscribe(robot.keys.goal_result(goal.goal_id), 10)
    try:
        await asyncio.sleep(min(KILL_AFTER_S, seconds / 2.0))
        reply = await robot.dashboard("stop")
        killed_at = time.monotonic()
        if not reply.get("ok", False):
            raise RuntimeError(f"dashboard stop refused: {reply}")
        status, reason = await ending(goal)
        again: float | None = None
        with contextlib.suppress(RuntimeError):
            await ready(robot, procs)
            again = time.monotonic() - killed_at
        after = "not ready again"
        if again is not None:
            move = await robot.move(HOME, velocity_scale=0.5, acceleration_scale=0.5)
            after = ": ".join(await ending(move))
        published = []  # every result message of the goal on its key (the daemon publishes one)
        while True:
            try:
                message = await results.get_json(timeout=1.0)
            except UrDaemonError:
                break
            published.append(f"{message.get('status')}: {message.get('reason', '')}")
        return Killed(f"{status}: {reason}", published, again, after)
    finally:
        robot.client.unsubscribe(results)


async def measure(endpoint: str, procs: Any, goals: int, seconds: float) -> tuple[Goals, Stream, Killed]:
    async with CL.daemon_client(endpoint, procs) as client:
        robots: list[RobotClient] = [await client.robot(n, cell=CELL, timeout=30.0) for n in ("alice", "bob")]
        for robot in robots:
            await ready(robot, procs)
        print(f"{goals} move goals …", file=sys.stderr)
        part1 = await move_goals(robots, goals, procs)
        print(f"a {seconds:g} s servoj stream …", file=sys.stderr)
        part2 = await stream(robots[0], seconds, procs)
        print("the stream with the program killed mid-goal …", file=sys.stderr)
        part3 = await killed(robots[0], seconds, procs)
        return part1, part2, part3


# ---- output ------------------------------------------------------------------------------------------


def load() -> str:
    one, five, fifteen = os.getloadavg()
    return f"load average {one:.2f} / {five:.2f} / {fifteen:.2f} (1 / 5 / 15 min)"


def _cycles(c: dict[str, Any]) -> str:
    turnaround = c["max_us"] / 1e3
    return (
        f"{c['missed']} missed, {c['late']} late of {c['cycles']} cycles, max turnaround {turnaround:.1f} ms"
    )


def goals_table(g: Goals) -> str:
    others = {k: v for k, v in g.statuses.items() if k not in ("succeeded", "aborted")}
    lines = [
        f"## 1. {g.sent} move goals, alternating alice and bob",
        "",
        f"succeeded {g.count('succeeded')}, aborted {g.count('aborted')}, "
        f"other {sum(others.values())} {others or ''}, lost (no result) {g.lost}".rstrip(),
    ]
    lines += [f"- {name}: {_cycles(c)}" for name, c in g.cycles.items()]
    lines += [f"- failure: {f}" for f in g.failures]
    return "\n".join(lines)


def stream_table(s: Stream, seconds: float) -> str:
    holds = ", ".join(f'"{w}" ×{n}' for w, n in s.holds.items())
    stale, g = s.deviation_max - s.deviation_median, s.gaps
    return "\n".join(
        [
            f"## 2. servoj stream on alice, {seconds:g} s asked ({s.duration:.1f} s goal)",
            "",
            f"result: {s.status}{': ' + s.reason if s.reason else ''}",
            f"daemon: {_cycles(s.cycles)}",
            f"gaps between consecutive joint_states of alice ({g.states} states, {g.dropped} dropped by "
            f"this client): biggest on the daemon's clock (host_time_ns) {g.host[0]:.1f} ms "
            f"(the robot's clock moved {g.host[1]:.1f} ms meanwhile); biggest on the robot's clock "
            f"(controller_time) {g.controller[0]:.1f} ms (the daemon's clock moved {g.controller[1]:.1f} ms)",
            f"deviation from the commanded path, max_j |desired - actual| over {s.feedback} feedback "
            f"messages: median {s.deviation_median * 1e3:.2f} mrad (servoj's tracking lag), "
            f"p99 {s.deviation_p99 * 1e3:.2f} mrad, max {s.deviation_max * 1e3:.2f} mrad "
            f"(at t = {s.deviation_at:.2f} s)",
            f"worst stale-command motion (max - median): {stale * 1e3:.2f} mrad",
            f"the control program on stale commands (its messages in the daemon's log, during the "
            f"stream): {holds}",
        ]
    )


def killed_table(k: Killed) -> str:
    again = "never" if k.ready_again_s is None else f"{k.ready_again_s:.1f} s after the kill"
    return "\n".join(
        [
            "## 3. the stream with alice's program killed mid-goal (dashboard stop)",
            "",
            f"the goal's result: {k.result}",
            f"result messages published for the goal: {len(k.published)} ({'; '.join(k.published)})",
            f"alice ready again (program sent again): {again}; a move after that: {k.after}",
        ]
    )


def run(
    burners: int, goals: int, seconds: float, logs: Path | None = None, pair: tuple[str, str] | None = None
) -> tuple[Goals, Stream, Killed]:
    """Burners, fakes and daemon; the three parts; everything stopped again."""
    burning = start_burners(burners)
    try:
        with running_cell(logs, pair) as (procs, endpoint):
            parts: tuple[Goals, Stream, Killed] = asyncio.run(measure(endpoint, procs, goals, seconds))
            return parts
    finally:
        stop_burners(burning)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0] if __doc__ else None)
    parser.add_argument("--burners", type=int, default=2, help="CPU burners beside the run (default 2)")
    parser.add_argument("--goals", type=int, default=50, help="move goals, alternating robots (default 50)")
    parser.add_argument("--seconds", type=float, default=60.0, help="the servoj stream's length (default 60)")
    parser.add_argument("--logs", type=Path, help="copy the fakes' and the daemon's logs into PATH")
    args = parser.parse_args()
    if not 0 <= args.burners <= 16 or not 1 <= args.goals <= 1000 or not 0 < args.seconds <= 600:
        parser.error("--burners 0..16, --goals 1..1000, --seconds 0..600")
    print(f"machine: {CL.machine()}")
    print(f"burners: {args.burners}; before the run: {load()}\n")
    goals, stream_, kill = run(args.burners, args.goals, args.seconds, args.logs)
    print(goals_table(goals) + "\n")
    print(stream_table(stream_, args.seconds) + "\n")
    print(killed_table(kill) + "\n")
    print(f"after the run: {load()}")


if __name__ == "__main__":
    main()
