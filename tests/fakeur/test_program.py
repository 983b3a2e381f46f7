"""The External Control executor: callback sockets, control modes, trajectories, script commands (§4, §5).

The pure parts (socket finding, spline and movej math, cycle sampling) are tested without sockets. For
the rest the test plays the daemon: three loopback servers on ephemeral ports speaking the DAEMON side
of the codecs, and a clock task that steps ``runner.step(dt); arm.step(dt)`` like the controller does.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import itertools
import math
import socket
import struct
from collections.abc import AsyncIterator, Callable, Iterator, Sequence
from dataclasses import dataclass

import pytest

from tests.helpers import free_tcp_port
from urdaemon.description.urmodels import load_ur_model
from urdaemon.errors import UrDaemonError
from urdaemon.fakeur.arm import FakeArm
from urdaemon.fakeur.program import (
    CONNECT_ATTEMPTS,
    CONNECT_RETRY_DELAY_S,
    EVENT_RUNTIME,
    POINT_READ_TIMEOUT_S,
    REASON_CLOSED,
    REASON_STOPPED,
    REASON_TIMED_OUT,
    REVERSE_TIMEOUT_MESSAGE,
    CallbackSockets,
    Endpoint,
    MotionSampler,
    ProgramError,
    ProgramRunner,
    cubic_segment,
    find_callback_sockets,
    joint_move,
    quintic_segment,
    speed_violation,
)
from urdaemon.protocols import script_command as sc
from urdaemon.protocols._buffer import Side
from urdaemon.protocols.reverse import (
    ControlMode,
    FreedriveAction,
    FreedriveControl,
    Idle,
    ReverseCommand,
    ReverseConnection,
    ServoJ,
    SpeedJ,
    Stopped,
    TrajectoryAction,
    TrajectoryControl,
)
from urdaemon.protocols.trajectory_point import (
    MotionPoint,
    MotionType,
    SplinePoint,
    TrajectoryPoint,
    TrajectoryPointConnection,
    TrajectoryResult,
    TrajectoryResultCode,
)

DT = 0.002
"""s: the e-Series controller cycle."""
HOME = (0.0, -1.57, 1.57, -1.57, -1.57, 0.0)
ZERO = (0.0,) * 6
WAIT_S = 5.0
"""s: bound on every real-time wait."""
FAST = 5.0
"""Simulated time runs this many times faster than real time in the trajectory tests."""
EXACT = 1e-9
"""rad: the arm reaches a commanded point exactly (up to float noise)."""
TRAJ, SCRIPT, REV = "trajectory_socket", "script_command_socket", "reverse_socket"
NAMES = (TRAJ, SCRIPT, REV)


def j0(offset: float) -> tuple[float, ...]:
    """HOME with joint 0 moved by ``offset``."""
    return (HOME[0] + offset, *HOME[1:])


def v0(value: float) -> tuple[float, ...]:
    """A joint vector that is ``value`` in joint 0 and zero elsewhere."""
    return (value, 0.0, 0.0, 0.0, 0.0, 0.0)


def make_arm() -> FakeArm:
    model = load_ur_model("ur10e")
    arm = FakeArm(model, model.dh, initial_positions=HOME, powered=True)
    assert arm.start_program() is None
    return arm


def program_text(ports: dict[str, int], host: str = "127.0.0.1") -> str:
    return "\n".join(
        [
            "def externalControl():",
            f'  socket_open("{host}", {ports[TRAJ]}, "trajectory_socket")',
            f'  socket_open("{host}", {ports[SCRIPT]}, "script_command_socket")',
            f'  socket_open("{host}", {ports[REV]}, "reverse_socket")',
            "end",
        ]
    )


# ---- the test's daemon, clock and event log --------------------------------------------------------------


class Daemon:
    """The daemon's three callback servers, speaking the daemon side of the codecs."""

    def __init__(self) -> None:
        self.accepted: list[str] = []
        self.connected = {name: asyncio.Event() for name in NAMES}
        self.closed = {name: asyncio.Event() for name in NAMES}
        self.writers: dict[str, asyncio.StreamWriter] = {}
        self.ports: dict[str, int] = {}
        self.reverse = ReverseConnection(Side.DAEMON)
        self.trajectory = TrajectoryPointConnection(Side.DAEMON)
        self.script = sc.ScriptCommandConnection(Side.DAEMON)
        self.results: asyncio.Queue[TrajectoryResultCode] = asyncio.Queue()
        self.greeting: dict[str, bytes] = {}
        """Bytes written to a socket the moment it is accepted."""
        self.tool_contact: asyncio.Queue[sc.ToolContactResultCode] = asyncio.Queue()
        self._servers: list[asyncio.Server] = []

    async def serve(self, name: str, sock: socket.socket | None = None) -> None:
        handler = functools.partial(self._handle, name)
        if sock is None:
            server = await asyncio.start_server(handler, "127.0.0.1", 0)
        else:
            server = await asyncio.start_server(handler, sock=sock)
        self.ports[name] = server.sockets[0].getsockname()[1]
        self._servers.append(server)

    async def _handle(self, name: str, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self.accepted.append(name)
        self.writers[name] = writer
        if name in self.greeting:
            writer.write(self.greeting[name])
        self.connected[name].set()
        try:
            while data := await reader.read(65536):
                if name == TRAJ:
                    for event in self.trajectory.receive_data(data):
                        assert isinstance(event, TrajectoryResult)
                        self.results.put_nowait(event.result)
                elif name == SCRIPT:
                    for reply in self.script.receive_data(data):
                        assert isinstance(reply, sc.ToolContactResult)
                        self.tool_contact.put_nowait(reply.code)
                else:
                    self.reverse.receive_data(data)
        except ConnectionError:
            pass
        finally:
            self.closed[name].set()

    def send(self, message: ReverseCommand) -> None:
        self.reverse.send(message)
        self.writers[REV].write(self.reverse.data_to_send())

    def send_points(self, *points: TrajectoryPoint) -> None:
        for point in points:
            self.trajectory.send(point)
        self.writers[TRAJ].write(self.trajectory.data_to_send())

    def send_command(self, command: sc.ScriptCommand) -> None:
        self.script.send(command)
        self.writers[SCRIPT].write(self.script.data_to_send())

    async def next_result(self) -> TrajectoryResultCode:
        async with asyncio.timeout(WAIT_S):
            return await self.results.get()

    async def all_closed(self) -> None:
        async with asyncio.timeout(WAIT_S):
            for name in self.writers:
                await self.closed[name].wait()

    async def close(self) -> None:
        for writer in self.writers.values():
            writer.close()
        for server in self._servers:
            server.close()


_READING = {"poll": False}
"""How this test's programs read the reverse socket (the fixture below runs every test both ways)."""


@pytest.fixture(autouse=True, params=["reverse-awaited", "reverse-polled"])
def _reverse_reading(request: pytest.FixtureRequest) -> Iterator[None]:
    """Every test twice: the program waking for each reverse frame, and reading it in the cycle."""
    _READING["poll"] = request.param == "reverse-polled"
    yield
    _READING["poll"] = False


class Clock:
    """The controller's cycle: ``runner.step(DT)`` then ``arm.step(DT)``, ``speedup`` × real time."""

    def __init__(self, runner: ProgramRunner, arm: FakeArm, *, speedup: float) -> None:
        self.runner = runner
        self.arm = arm
        self.speedup = speedup
        self.batch = 1 if speedup <= 1 else 5
        """Cycles run back to back between two yields: in real time every cycle waits its turn, like a
        controller's; faster, a few at a time keep the event loop's overhead down."""
        self.cycles = 0
        self.history: list[list[float]] = []
        """``history[k]``: the arm's joints after cycle k + 1."""
        self._waiters: list[tuple[Callable[[], bool], asyncio.Future[int]]] = []
        self._task: asyncio.Task[None] | None = None

    def start(self) -> None:
        self._task = asyncio.get_running_loop().create_task(self._run())

    async def stop(self) -> None:
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task

    async def _run(self) -> None:
        while True:
            for _ in range(self.batch):
                if self.runner.polls_reverse:  # as the fake controller does: read, let the program
                    self.runner.poll()  # apply what it read, then the cycle
                    await asyncio.sleep(0)
                self.runner.step(DT)
                self.arm.step(DT)
                self.cycles += 1
                self.history.append(list(self.arm.q))
                if self._waiters:
                    self._wake()
            await asyncio.sleep(self.batch * DT / self.speedup)

    def _wake(self) -> None:
        pending = []
        for predicate, future in self._waiters:
            if future.done():
                continue
            if predicate():
                future.set_result(self.cycles)
            else:
                pending.append((predicate, future))
        self._waiters = pending

    async def until(self, predicate: Callable[[], bool], timeout: float = WAIT_S) -> int:
        """Wait until ``predicate()`` holds after a cycle; returns that cycle's number."""
        if predicate():
            return self.cycles
        future: asyncio.Future[int] = asyncio.get_running_loop().create_future()
        self._waiters.append((predicate, future))
        async with asyncio.timeout(timeout):
            return await future


class Events:
    """The runner's ``on_event`` reports, awaitable by substring."""

    def __init__(self) -> None:
        self.items: list[tuple[str, str]] = []
        self._waiters: list[tuple[str, asyncio.Future[tuple[str, str]]]] = []

    def __call__(self, kind: str, text: str) -> None:
        self.items.append((kind, text))
        for needle, future in self._waiters:
            if needle in text and not future.done():
                future.set_result((kind, text))

    def texts(self) -> list[str]:
        return [text for _, text in self.items]

    async def wait(self, needle: str, timeout: float = WAIT_S) -> tuple[str, str]:
        for item in self.items:
            if needle in item[1]:
                return item
        future: asyncio.Future[tuple[str, str]] = asyncio.get_running_loop().create_future()
        self._waiters.append((needle, future))
        async with asyncio.timeout(timeout):
            return await future


@dataclass
class Rig:
    daemon: Daemon
    arm: FakeArm
    runner: ProgramRunner
    run: asyncio.Task[str]
    clock: Clock
    events: Events

    async def result(self) -> str:
        async with asyncio.timeout(WAIT_S):
            return await self.run

    def reached(self, target: Sequence[float], after: int = 0) -> int:
        """Index in ``clock.history`` of the first cycle (from ``after``) with the arm at ``target``."""
        for index in range(after, len(self.clock.history)):
            if max(abs(a - b) for a, b in zip(self.clock.history[index], target, strict=True)) < EXACT:
                return index
        raise AssertionError(f"the arm never reached {target}")

    def first_motion(self, after: int = 0) -> int:
        """Index in ``clock.history`` of the first cycle (from ``after``) in which the arm moved."""
        history = self.clock.history
        for index in range(max(after, 1), len(history)):
            if history[index] != history[index - 1]:
                return index
        raise AssertionError("the arm never moved")


@contextlib.asynccontextmanager
async def running_program(*, speedup: float = FAST, reverse_greeting: bytes = b"") -> AsyncIterator[Rig]:
    """A connected program with its clock running; cancels and closes everything afterwards."""
    daemon = Daemon()
    if reverse_greeting:
        daemon.greeting[REV] = reverse_greeting
    for name in NAMES:
        await daemon.serve(name)
    arm = make_arm()
    events = Events()
    runner = ProgramRunner(
        arm, program_text(daemon.ports), step_time=DT, on_event=events, poll_reverse=_READING["poll"]
    )
    run = asyncio.get_running_loop().create_task(runner.run())
    clock = Clock(runner, arm, speedup=speedup)
    try:
        async with asyncio.timeout(WAIT_S):
            for name in NAMES:
                await daemon.connected[name].wait()
            await events.wait("External control active")
        clock.start()
        yield Rig(daemon, arm, runner, run, clock, events)
    finally:
        run.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await run
        await clock.stop()
        await daemon.close()


async def run_trajectory(rig: Rig, *points: TrajectoryPoint) -> TrajectoryResultCode:
    """START(n) as urcl does it (START first, then the points); the trajectory's result."""
    rig.daemon.send(TrajectoryControl(TrajectoryAction.START, len(points), timeout=0.0))
    rig.daemon.send_points(*points)
    return await rig.daemon.next_result()


# ---- finding the callback sockets ------------------------------------------------------------------------


def test_find_callback_sockets_reads_each_socket_open_call() -> None:
    text = """
    # socket_open("10.9.9.9", 1234, "reverse_socket")   (a comment: never executed)
    def externalControl():
      socket_open( '192.168.1.5' , 50003 , 'trajectory_socket' )
      textmsg("# not a comment")
      connect_socket_with_retry("daemon-pc.local", 50004, "script_command_socket")
      socket_open("192.168.1.5",50001,"reverse_socket")
    end
    """
    assert find_callback_sockets(text) == CallbackSockets(
        reverse=Endpoint("192.168.1.5", 50001),
        trajectory=Endpoint("192.168.1.5", 50003),
        script_command=Endpoint("daemon-pc.local", 50004),
    )


def test_find_callback_sockets_names_the_missing_sockets() -> None:
    with pytest.raises(ProgramError, match="does not open reverse_socket, script_command_socket") as info:
        find_callback_sockets('socket_open("127.0.0.1", 50003, "trajectory_socket")')
    assert isinstance(info.value, UrDaemonError)
    assert "reverse_socket" in info.value.reason


def test_find_callback_sockets_names_unfilled_placeholders() -> None:
    text = (
        'socket_open("{{SERVER_IP_REPLACE}}", {{SERVER_PORT_REPLACE}}, "reverse_socket")\n'
        "{% if ROBOT_SOFTWARE_VERSION >= v5.23.0 %}\n"
    )
    with pytest.raises(ProgramError) as info:
        find_callback_sockets(text)
    assert "{{SERVER_IP_REPLACE}}" in info.value.reason
    assert "{{SERVER_PORT_REPLACE}}" in info.value.reason
    assert "{% if ROBOT_SOFTWARE_VERSION >= v5.23.0 %}" in info.value.reason


def test_find_callback_sockets_rejects_a_port_that_is_not_a_port() -> None:
    with pytest.raises(ProgramError, match="reverse_socket: port '70000'"):
        find_callback_sockets('socket_open("127.0.0.1", 70000, "reverse_socket")')


# ---- motion math -----------------------------------------------------------------------------------------


def test_cubic_segment_meets_its_end_conditions() -> None:
    start, start_v = [0.1, -0.2, 0.3, 0.0, 1.0, -1.0], [0.5, 0.0, -0.1, 0.0, 0.2, 0.0]
    end, end_v = [0.4, -0.1, 0.0, 0.0, 1.2, -0.5], [0.0, 0.3, 0.0, 0.0, -0.2, 0.1]
    segment = cubic_segment(start, start_v, end, end_v, 0.4)
    assert segment.position(0.0) == pytest.approx(start)
    assert segment.velocity(0.0) == pytest.approx(start_v)
    assert segment.position(0.4) == pytest.approx(end)
    assert segment.velocity(0.4) == pytest.approx(end_v)
    assert not segment.quintic


def test_quintic_segment_meets_its_end_conditions() -> None:
    start, start_v, start_a = [0.0] * 6, [0.2] * 6, [1.0, 0.0, -1.0, 0.5, 0.0, 0.0]
    end, end_v, end_a = [0.3, -0.3, 0.1, 0.0, 0.2, 0.5], [0.0] * 6, [0.0, 0.5, 0.0, 0.0, -1.0, 0.0]
    segment = quintic_segment(start, start_v, start_a, end, end_v, end_a, 0.5)
    for t, q, qd, qdd in ((0.0, start, start_v, start_a), (0.5, end, end_v, end_a)):
        assert segment.position(t) == pytest.approx(q, abs=1e-12)
        assert segment.velocity(t) == pytest.approx(qd, abs=1e-12)
        assert segment.acceleration(t) == pytest.approx(qdd, abs=1e-12)


def test_joint_move_keeps_the_leading_joint_within_v_and_a_and_synchronises_the_rest() -> None:
    start = [0.0] * 6
    target = [1.0, -0.5, 0.0, 0.25, 0.0, 0.0]
    move = joint_move(start, target, velocity=1.0, acceleration=2.0)
    assert move.duration == pytest.approx(1.0 / 1.0 + 1.0 / 2.0)  # D/v + v/a
    dt = 0.001
    samples = [move.position(k * dt) for k in range(round(move.duration / dt) + 1)]
    speeds = [(b[0] - a[0]) / dt for a, b in itertools.pairwise(samples)]
    assert max(abs(s) for s in speeds) <= 1.0 + 1e-9
    assert max(abs(b - a) / dt for a, b in itertools.pairwise(speeds)) <= 2.0 + 1e-6
    assert move.position(move.duration) == pytest.approx(target)
    halfway = move.position(move.duration / 2)
    assert halfway[1] == pytest.approx(-0.5 * halfway[0])  # every joint on the same profile
    # too short to reach v: a triangle at acceleration a
    short = joint_move(start, [0.1, 0, 0, 0, 0, 0], velocity=1.0, acceleration=2.0)
    assert short.duration == pytest.approx(2 * math.sqrt(0.1 / 2.0))
    # a duration overrides the speed
    timed = joint_move(start, target, velocity=1.0, acceleration=2.0, duration=3.0)
    assert timed.duration == pytest.approx(3.0)
    assert timed.position(3.0) == pytest.approx(target)
    with pytest.raises(ValueError, match="a > 0 and v > 0"):
        joint_move(start, target, velocity=0.0, acceleration=2.0)


def test_sampler_advances_by_the_scaled_budget_and_ends_exactly_on_a_cycle() -> None:
    segment = cubic_segment(ZERO, ZERO, v0(0.1), ZERO, 0.1)
    for factor, cycles in ((1.0, 50), (0.5, 100), (0.25, 200)):
        sampler = MotionSampler(segment, DT)
        count = 0
        while not sampler.advance(DT * factor):
            count += 1
            assert count < 1000
        assert count + 1 == cycles
        assert sampler.positions == segment.position(0.1)
    frozen = MotionSampler(segment, DT)
    assert not frozen.advance(0.0)
    assert frozen.elapsed == 0.0


def test_last_segment_slows_down_when_it_would_end_too_fast() -> None:
    # ends at 6 rad/s: no way to stop within the 15 rad/s² budget, so the last segment slows down
    segment = cubic_segment(ZERO, v0(6.0), v0(1.2), v0(6.0), 0.2)
    plain = MotionSampler(segment, DT)
    plain_cycles = 1
    while not plain.advance(DT):
        plain_cycles += 1
        assert plain_cycles < 1000
    assert plain_cycles == 100
    assert plain.end_velocity() == pytest.approx(v0(6.0))
    slowed = MotionSampler(segment, DT, slow_down_at_end=True)
    cycles, last = 1, slowed.positions[0]
    steps = []
    while not slowed.advance(DT):
        steps.append(slowed.positions[0] - last)
        last = slowed.positions[0]
        cycles += 1
        assert cycles < 100_000
    assert cycles > plain_cycles
    assert slowed.positions == segment.position(0.2)  # still follows the path to its end
    assert slowed.end_velocity() == pytest.approx(ZERO)
    assert steps[-1] < steps[0] / 100  # creeping at the end


def test_speed_violation_names_the_first_joint_over_20_rad_per_s() -> None:
    violation = speed_violation(ZERO, (0.0, 0.0, 0.05, 0.1, 0.0, 0.0), DT)
    assert violation is not None
    assert violation[0] == 2
    assert violation[1] == pytest.approx(25.0)
    assert speed_violation(ZERO, (0.0, 0.039, 0.0, 0.0, 0.0, -0.039), DT) is None


# ---- connecting back -------------------------------------------------------------------------------------


async def test_connects_trajectory_then_script_command_then_reverse() -> None:
    async with running_program() as rig:
        assert rig.daemon.accepted == [TRAJ, SCRIPT, REV]
        assert rig.runner.control_mode == ControlMode.UNINITIALIZED
        rig.daemon.send(Stopped())
        assert await rig.result() == REASON_STOPPED


async def test_gives_up_after_five_attempts_and_closes_what_it_opened() -> None:
    daemon = Daemon()
    await daemon.serve(TRAJ)
    await daemon.serve(SCRIPT)
    daemon.ports[REV] = free_tcp_port()  # nobody listens there
    events = Events()
    runner = ProgramRunner(make_arm(), program_text(daemon.ports), step_time=DT, on_event=events)
    loop = asyncio.get_running_loop()
    started = loop.time()
    try:
        async with asyncio.timeout(WAIT_S):
            reason = await runner.run()
        assert loop.time() - started >= 0.9 * CONNECT_ATTEMPTS * CONNECT_RETRY_DELAY_S
        assert reason.startswith("could not connect")
        assert f"trajectory_socket (127.0.0.1:{daemon.ports[TRAJ]}) connected: True" in reason
        assert f"script_command_socket (127.0.0.1:{daemon.ports[SCRIPT]}) connected: True" in reason
        assert f"reverse_socket (127.0.0.1:{daemon.ports[REV]}) connected: False" in reason
        assert any("Error connecting to remote" in text for text in events.texts())
        await daemon.all_closed()
        assert daemon.accepted == [TRAJ, SCRIPT]
    finally:
        await daemon.close()


async def test_a_server_that_starts_late_is_reached_by_a_retry() -> None:
    daemon = Daemon()
    await daemon.serve(SCRIPT)
    await daemon.serve(REV)
    late = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    late.bind(("127.0.0.1", 0))  # bound but not listening: connections are refused
    daemon.ports[TRAJ] = late.getsockname()[1]
    runner = ProgramRunner(make_arm(), program_text(daemon.ports), step_time=DT)
    run = asyncio.get_running_loop().create_task(runner.run())
    try:
        # a deliberate pause: the runner must still be retrying the first socket, touching no other
        await asyncio.sleep(1.5 * CONNECT_RETRY_DELAY_S)
        assert daemon.accepted == []
        late.listen()
        await daemon.serve(TRAJ, sock=late)
        async with asyncio.timeout(WAIT_S):
            await daemon.connected[REV].wait()
        assert daemon.accepted == [TRAJ, SCRIPT, REV]
    finally:
        run.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await run
        await daemon.close()


async def test_a_program_without_callback_sockets_is_reported() -> None:
    events = Events()
    runner = ProgramRunner(make_arm(), "def prog():\n  textmsg(1)\nend", step_time=DT, on_event=events)
    reason = await runner.run()
    assert "does not open" in reason
    assert events.items == [(EVENT_RUNTIME, reason)]


# ---- realtime modes --------------------------------------------------------------------------------------


async def test_servoj_tracks_the_targets_and_ignores_an_impossible_one() -> None:
    async with running_program(speedup=1.0) as rig:
        step = 0.002  # rad per frame: 1 rad/s at 500 Hz
        for k in range(1, 51):
            rig.daemon.send(ServoJ(j0(step * k), timeout=0.1))
            await asyncio.sleep(DT)
        final = j0(step * 50)
        for _ in range(25):
            rig.daemon.send(ServoJ(final, timeout=0.1))
            await asyncio.sleep(DT)
        assert rig.runner.control_mode == ControlMode.SERVOJ
        # between frames the controller extrapolates, so allow one step of jitter
        assert rig.arm.q[0] == pytest.approx(final[0], abs=2 * step)
        assert rig.clock.history[-1][1:] == pytest.approx(list(HOME[1:]), abs=1e-12)
        # 0.5 rad in one 2 ms step needs 250 rad/s: the script ignores it and says so
        rig.daemon.send(ServoJ(j0(step * 50 + 0.5), timeout=0.1))
        await rig.events.wait("exceeding the joint velocity limits")
        rig.daemon.send(ServoJ(final, timeout=0.1))
        await rig.events.wait("Received valid command. Resuming execution.")
        assert rig.arm.q[0] == pytest.approx(final[0], abs=2 * step)
        rig.daemon.send(Stopped())
        assert await rig.result() == REASON_STOPPED


async def test_extrapolating_between_frames_never_outruns_the_joint_speed_limit() -> None:
    async with running_program(speedup=1.0) as rig:
        # two frames 0.03 rad apart: 15 rad/s, under the script's 20 rad/s check, over the joint's limit
        rig.daemon.send(ServoJ(j0(0.0), timeout=0.5))
        rig.daemon.send(ServoJ(j0(0.03), timeout=0.5))
        start = len(rig.clock.history)
        await rig.clock.until(lambda: rig.runner._servo_q[0] >= HOME[0] + 0.03)
        setpoint = rig.runner._servo_q
        frozen = setpoint[0]
        await rig.clock.until(lambda: len(rig.clock.history) >= start + 25)  # cycles with no frame
        cycles = len(rig.clock.history) - start
        limit = rig.arm.max_velocity[0]
        assert 0.0 < setpoint[0] - frozen <= cycles * limit * DT + 1e-9, "extrapolated at most at the limit"
        assert setpoint[0] - frozen < 0.5 * cycles * 0.03, "not at the frames' 15 rad/s"
        rig.daemon.send(Stopped())
        assert await rig.result() == REASON_STOPPED


def test_a_frame_that_corrects_an_extrapolation_is_not_taken_for_the_arms_speed() -> None:
    """Frames bunched by a late daemon: the rate is the stream's, frame to frame over the cycles between."""
    runner = ProgramRunner(make_arm(), "def p():\nend", step_time=DT)
    speed = 0.5
    runner._set_servo_setpoint(j0(0.0))
    runner._servo_step(DT)
    runner._set_servo_setpoint(j0(speed * DT))
    runner._servo_step(DT)
    for _ in range(10):  # no frame: the setpoint goes on at the stream's 0.5 rad/s
        runner._servo_step(DT)
    assert runner._servo_q[0] == pytest.approx(HOME[0] + 11 * speed * DT, abs=1e-12)
    # the next frame, 11 cycles on, says the trajectory stopped where the last frame was
    runner._set_servo_setpoint(j0(speed * DT))
    runner._servo_step(DT)
    assert runner._servo_q[0] == pytest.approx(HOME[0] + speed * DT, abs=1e-12)
    for _ in range(20):  # and no frame again: the stream's rate over those 11 cycles was zero
        runner._servo_step(DT)
    assert runner._servo_q[0] == pytest.approx(HOME[0] + speed * DT, abs=1e-12), "no drift"
    # a frame after a gap that continues a moving stream: its rate is the distance over the gap
    runner._set_servo_setpoint(j0(speed * DT + 21 * 0.25 * DT))
    for _ in range(4):
        runner._servo_step(DT)
    assert runner._servo_q[0] == pytest.approx(HOME[0] + speed * DT + 24 * 0.25 * DT, abs=1e-12)


async def test_a_frame_sent_the_moment_the_reverse_socket_connects_is_not_lost() -> None:
    """The daemon may write before the program's first read (and, polled, before reading is paused)."""
    codec = ReverseConnection(Side.DAEMON)
    codec.send(SpeedJ(v0(0.25), timeout=5.0))
    async with running_program(speedup=1.0, reverse_greeting=codec.data_to_send()) as rig:
        await rig.clock.until(lambda: rig.arm.qd[0] == pytest.approx(0.25))
        assert rig.runner.control_mode == ControlMode.SPEEDJ


async def test_polling_starts_with_the_bytes_the_stream_reader_already_holds() -> None:
    """Poll mode takes over a reverse socket whose transport may already have read a frame."""
    from urdaemon.fakeur.program import _Link

    ours, theirs = socket.socketpair()
    reader, writer = await asyncio.open_connection(sock=ours)
    codec = ReverseConnection(Side.DAEMON)
    codec.send(SpeedJ(v0(0.1), timeout=1.0))
    early = codec.data_to_send()
    codec.send(Idle(timeout=1.0))
    late = codec.data_to_send()
    try:
        reader.feed_data(early)  # what the transport read before reading was paused
        runner = ProgramRunner(make_arm(), "def p():\nend", step_time=DT, poll_reverse=True)
        runner._start_polling(_Link(reader, writer))
        theirs.sendall(late)  # what arrives afterwards waits in the socket for the cycle's poll
        runner.poll()
        assert [type(e) for e in runner._reverse_events] == [SpeedJ, Idle]
        theirs.close()  # the daemon hangs up: the next poll sees the end of the stream
        runner.poll()
        assert runner._reverse_eof is True
    finally:
        writer.close()
        theirs.close()


async def test_speedj_drives_joint_velocities_and_idle_stops_them() -> None:
    async with running_program(speedup=1.0) as rig:
        for _ in range(60):
            rig.daemon.send(SpeedJ(v0(0.5), timeout=0.1))
            await asyncio.sleep(DT)
        assert rig.arm.qd[0] == pytest.approx(0.5)
        assert rig.arm.q[0] > HOME[0] + 0.02
        rig.daemon.send(Idle(timeout=0.0))
        stopped_at = await rig.clock.until(lambda: rig.arm.qd[0] == 0.0)
        assert rig.runner.control_mode == ControlMode.IDLE
        assert stopped_at > 0
        moved = rig.arm.q[0]
        await rig.clock.until(lambda: rig.clock.cycles > stopped_at + 50)
        assert rig.arm.q[0] == moved  # IDLE: the arm holds


async def test_idle_keepalives_keep_it_running_and_silence_halts_it() -> None:
    async with running_program(speedup=1.0) as rig:
        for _ in range(8):
            rig.daemon.send(Idle(timeout=0.1))
            await asyncio.sleep(0.03)
        assert not rig.run.done()
        assert rig.runner.control_mode == ControlMode.IDLE
        for _ in range(5):
            rig.daemon.send(SpeedJ(v0(0.3), timeout=0.1))
            await asyncio.sleep(0.02)
        # now the daemon falls silent: the read times out, the program halts and the arm stops
        assert await rig.result() == REASON_TIMED_OUT
        assert (EVENT_RUNTIME, REVERSE_TIMEOUT_MESSAGE) in rig.events.items
        await rig.clock.until(lambda: rig.arm.qd[0] == 0.0)
        await rig.daemon.all_closed()


async def test_stopped_ends_the_program_cleanly_and_closes_the_sockets() -> None:
    async with running_program() as rig:
        rig.daemon.send(Idle(timeout=1.0))
        rig.daemon.send(Stopped())
        assert await rig.result() == REASON_STOPPED
        assert "ExternalControl: Stopping communication and control" in rig.events.texts()
        assert not any(kind == EVENT_RUNTIME for kind, _ in rig.events.items)
        await rig.daemon.all_closed()


async def test_the_daemon_closing_the_reverse_socket_halts_the_program() -> None:
    async with running_program() as rig:
        rig.daemon.send(Idle(timeout=0.0))
        rig.daemon.writers[REV].close()
        assert await rig.result() == REASON_CLOSED
        assert (EVENT_RUNTIME, REVERSE_TIMEOUT_MESSAGE) in rig.events.items


async def test_freedrive_starts_and_ends_with_the_mode() -> None:
    async with running_program() as rig:
        rig.daemon.send(FreedriveControl(FreedriveAction.START, timeout=0.0))
        await rig.clock.until(lambda: rig.arm.freedrive)
        rig.daemon.send(Idle(timeout=0.0))
        await rig.clock.until(lambda: not rig.arm.freedrive)
        assert "Leaving freedrive mode" in rig.events.texts()


async def test_cancelling_run_closes_every_socket() -> None:
    async with running_program() as rig:
        rig.run.cancel()
        with pytest.raises(asyncio.CancelledError):
            await rig.run
        await rig.daemon.all_closed()


# ---- trajectories ----------------------------------------------------------------------------------------

CUBIC_POINTS = (
    SplinePoint(j0(0.05), v0(0.4), None, 0.2),
    SplinePoint(j0(0.12), v0(0.2), None, 0.2),
    SplinePoint(j0(0.15), v0(0.0), None, 0.1),
)


async def test_a_cubic_trajectory_reaches_each_point_at_its_time() -> None:
    async with running_program() as rig:
        assert await run_trajectory(rig, *CUBIC_POINTS) is TrajectoryResultCode.SUCCESS
        first = rig.first_motion()
        elapsed = 0.0
        for point in CUBIC_POINTS:
            elapsed += point.segment_time
            at = rig.clock.history[first - 1 + round(elapsed / DT)]
            assert at == pytest.approx(list(point.positions), abs=EXACT)
        await rig.events.wait("Trajectory finished with result SUCCESS")
        assert not rig.runner.trajectory_running


async def test_a_quintic_trajectory_reaches_each_point_at_its_time() -> None:
    points = (
        SplinePoint(j0(-0.04), v0(-0.3), v0(0.0), 0.2),
        SplinePoint(j0(-0.10), v0(-0.2), v0(1.0), 0.25),
        SplinePoint(j0(-0.12), v0(0.0), v0(0.0), 0.15),
    )
    async with running_program() as rig:
        assert await run_trajectory(rig, *points) is TrajectoryResultCode.SUCCESS
        first = rig.first_motion()
        elapsed = 0.0
        for point in points:
            elapsed += point.segment_time
            at = rig.clock.history[first - 1 + round(elapsed / DT)]
            assert at == pytest.approx(list(point.positions), abs=EXACT)


async def test_the_speed_slider_at_half_doubles_the_execution_time() -> None:
    total = sum(p.segment_time for p in CUBIC_POINTS)
    back = tuple(SplinePoint(j0(0.0), ZERO, None, total) for _ in range(1))
    async with running_program() as rig:
        assert await run_trajectory(rig, *CUBIC_POINTS) is TrajectoryResultCode.SUCCESS
        start = rig.first_motion()
        full_speed = rig.reached(CUBIC_POINTS[-1].positions, start) - start + 1
        assert full_speed == round(total / DT)
        await rig.clock.until(lambda: rig.arm.qd == [0.0] * 6)
        rig.arm.speed_slider = 0.5
        mark = len(rig.clock.history)
        assert await run_trajectory(rig, *back) is TrajectoryResultCode.SUCCESS
        start = rig.first_motion(mark)
        half_speed = rig.reached(back[-1].positions, start) - start + 1
        assert half_speed == 2 * full_speed


async def test_cancel_mid_trajectory_answers_canceled_and_stops() -> None:
    async with running_program() as rig:
        rig.daemon.send(TrajectoryControl(TrajectoryAction.START, 1, timeout=0.0))
        rig.daemon.send_points(SplinePoint(j0(0.5), ZERO, None, 2.0))
        await rig.clock.until(lambda: rig.arm.q[0] > HOME[0] + 0.05)
        rig.daemon.send(TrajectoryControl(TrajectoryAction.CANCEL, timeout=0.0))
        assert await rig.daemon.next_result() is TrajectoryResultCode.CANCELED
        await rig.clock.until(lambda: rig.arm.qd == [0.0] * 6)
        assert rig.arm.q[0] < HOME[0] + 0.4
        assert "cancel received" in rig.events.texts()
        assert not rig.runner.trajectory_running


async def test_leaving_forward_with_points_due_drains_them_and_answers_canceled() -> None:
    async with running_program() as rig:
        rig.daemon.send(TrajectoryControl(TrajectoryAction.START, 2, timeout=0.0))
        rig.daemon.send_points(SplinePoint(j0(0.2), ZERO, None, 1.0))  # the second point never comes
        await rig.clock.until(lambda: rig.arm.q[0] > HOME[0] + 0.01)
        rig.daemon.send(Idle(timeout=0.0))
        assert await rig.daemon.next_result() is TrajectoryResultCode.CANCELED
        assert "No more trajectory points in the buffer" in " ".join(rig.events.texts())
        await rig.clock.until(lambda: rig.arm.qd == [0.0] * 6)
        assert rig.runner.control_mode == ControlMode.IDLE


async def test_a_paused_program_freezes_the_trajectory_until_resumed() -> None:
    target = j0(0.1)
    async with running_program() as rig:
        rig.daemon.send(TrajectoryControl(TrajectoryAction.START, 1, timeout=0.0))
        rig.daemon.send_points(SplinePoint(target, ZERO, None, 0.4))
        await rig.clock.until(lambda: rig.arm.q[0] > HOME[0] + 0.02)
        rig.arm.pause_program()
        paused_at = await rig.clock.until(lambda: rig.arm.qd == [0.0] * 6)
        frozen = rig.arm.q[0]
        await rig.clock.until(lambda: rig.clock.cycles > paused_at + 100)
        assert rig.arm.q[0] == frozen
        assert rig.runner.trajectory_running
        assert rig.arm.resume_program() is None
        assert await rig.daemon.next_result() is TrajectoryResultCode.SUCCESS
        rig.reached(target)


async def test_a_missing_point_fails_the_trajectory() -> None:
    async with running_program() as rig:
        rig.daemon.send(TrajectoryControl(TrajectoryAction.START, 3, timeout=0.0))
        rig.daemon.send_points(*CUBIC_POINTS[:2])  # the third never comes
        assert await rig.daemon.next_result() is TrajectoryResultCode.FAILURE
        assert "Receiving trajectory point failed!" in rig.events.texts()
        await rig.clock.until(lambda: rig.arm.qd == [0.0] * 6)


async def test_no_point_at_all_fails_after_the_read_timeout() -> None:
    async with running_program() as rig:
        loop = asyncio.get_running_loop()
        started = loop.time()
        rig.daemon.send(TrajectoryControl(TrajectoryAction.START, 1, timeout=0.0))
        assert await rig.daemon.next_result() is TrajectoryResultCode.FAILURE
        assert loop.time() - started >= 0.9 * POINT_READ_TIMEOUT_S


async def test_a_streamed_trajectory_runs_until_stream_end() -> None:
    points = [SplinePoint(j0(0.03 * k), v0(0.15 if k < 4 else 0.0), None, 0.2) for k in range(1, 5)]
    async with running_program() as rig:
        rig.daemon.send(TrajectoryControl(TrajectoryAction.STREAM_START, timeout=0.0))
        rig.daemon.send_points(*points[:2])
        await rig.clock.until(lambda: rig.arm.q[0] >= points[0].positions[0] - EXACT)
        rig.daemon.send_points(*points[2:])  # the producer keeps ahead of the robot …
        rig.daemon.send(TrajectoryControl(TrajectoryAction.STREAM_END, 4, timeout=0.0))  # … then ends
        assert await rig.daemon.next_result() is TrajectoryResultCode.SUCCESS
        rig.reached(points[-1].positions)
        assert rig.runner.trajectory_running is False


async def test_movej_points_run_and_pose_targets_fail() -> None:
    async with running_program() as rig:
        move = MotionPoint(MotionType.MOVEJ, j0(0.3), velocity=1.0, acceleration=2.0)
        assert await run_trajectory(rig, move) is TrajectoryResultCode.SUCCESS
        start = rig.first_motion()
        cycles = rig.reached(move.target, start) - start + 1
        assert cycles == math.ceil(2 * math.sqrt(0.3 / 2.0) / DT - 1e-9)  # a triangle profile
        history = rig.clock.history[start - 1 : start + cycles]
        assert max(b[0] - a[0] for a, b in itertools.pairwise(history)) <= 1.0 * DT + 1e-12
        pose = MotionPoint(MotionType.MOVEL, (0.5, 0.1, 0.4, 0.0, 3.14, 0.0))
        assert await run_trajectory(rig, pose) is TrajectoryResultCode.FAILURE
        assert any("MOVEL needs inverse kinematics" in text for text in rig.events.texts())


# ---- script commands -------------------------------------------------------------------------------------


async def test_script_commands_set_the_arm_state() -> None:
    async with running_program() as rig:
        force = sc.StartForceMode(ZERO, (0, 0, 1, 0, 0, 0), (0.0, 0.0, 5.0, 0.0, 0.0, 0.0), 2, (0.1,) * 6)
        for command in (
            sc.SetPayload(2.5, (0.0, 0.01, 0.05)),
            sc.SetToolVoltage(24),
            sc.SetTcpOffset((0.0, 0.0, 0.15, 0.0, 0.0, 0.0)),
            sc.SetGravity((0.0, 9.82, 0.0)),
            force,
            sc.SetFrictionScales((0.5,) * 6, (0.25,) * 6),
            sc.ZeroFtSensor(),
        ):
            rig.daemon.send_command(command)
        await rig.clock.until(lambda: rig.runner.ft_sensor_zeroed == 1)  # commands run in order
        arm = rig.arm
        assert arm.payload_mass == 2.5
        assert arm.payload_cog == [0.0, 0.01, 0.05]
        assert arm.io.tool_voltage == 24
        assert arm.tcp_offset == [0.0, 0.0, 0.15, 0.0, 0.0, 0.0]
        assert arm.gravity == [0.0, 9.82, 0.0]
        assert arm.force_mode
        assert rig.runner.force_mode_parameters == force
        assert rig.runner.viscous_scale == [0.5] * 6
        rig.daemon.send_command(sc.SetTargetPayload(1.0, (0.0, 0.0, 0.1), (0.01,) * 3 + (0.0,) * 3, 0.5))
        rig.daemon.send_command(sc.EndForceMode())
        await rig.clock.until(lambda: not rig.arm.force_mode)
        assert arm.payload_mass == 1.0
        assert arm.payload_inertia == [0.01, 0.01, 0.01, 0.0, 0.0, 0.0]


async def test_end_tool_contact_answers_canceled() -> None:
    async with running_program() as rig:
        rig.daemon.send_command(sc.StartToolContact())
        await rig.clock.until(lambda: rig.runner.tool_contact_armed)
        rig.daemon.send_command(sc.EndToolContact())
        async with asyncio.timeout(WAIT_S):
            assert await rig.daemon.tool_contact.get() is sc.ToolContactResultCode.CANCELED
        assert not rig.runner.tool_contact_armed


async def test_an_unknown_script_command_is_reported_and_ignored() -> None:
    async with running_program() as rig:
        rig.daemon.writers[SCRIPT].write(struct.pack(">28i", 99, *([0] * 27)))
        await rig.events.wait("unknown script command 99")
        rig.daemon.send_command(sc.SetToolVoltage(12))  # the stream is still in step
        await rig.clock.until(lambda: rig.arm.io.tool_voltage == 12)
