"""The mock backend: commands mirrored into state with one cycle of lag, via ``step()`` and ``run()``."""

from __future__ import annotations

import asyncio
import math

import pytest

from urdaemon.backends import MockBackend
from urdaemon.errors import BackendError
from urdaemon.model import IO_SIZES, CommandMode, Lifecycle, RobotMode, SafetyMode

JOINTS = ("a_j1", "a_j2", "a_j3")
RATE = 500.0
DT = 1.0 / RATE


def make(initial: list[float] | None = None, *, scaling: float = 1.0, rate: float = RATE) -> MockBackend:
    return MockBackend("a", JOINTS, rate, initial_positions=initial, speed_scaling=scaling)


# --- construction ---


def test_initial_state() -> None:
    backend = make([0.5, -1.0, 2.0])
    assert backend.kind == "mock"
    assert backend.name == "a"
    assert backend.rate_hz == RATE
    assert backend.period == DT
    state = backend.state
    assert state.joint_names == JOINTS
    assert state.positions == [0.5, -1.0, 2.0]
    assert state.velocities == [0.0, 0.0, 0.0]
    assert state.efforts == [0.0, 0.0, 0.0]
    assert state.lifecycle is Lifecycle.DISCONNECTED
    assert state.cycle == 0
    assert state.controller_time == 0.0
    # the idle command starts at the initial pose, so switching to POSITION without a write holds still
    assert backend.command.mode is CommandMode.IDLE
    assert backend.command.positions == [0.5, -1.0, 2.0]
    assert backend.command.positions is not state.positions


def test_initial_positions_default_to_zero() -> None:
    backend = make()
    assert backend.state.positions == [0.0, 0.0, 0.0]
    assert backend.command.positions == [0.0, 0.0, 0.0]


def test_initial_positions_are_copied_as_floats() -> None:
    given = [1, 2, 3]
    backend = MockBackend("a", JOINTS, RATE, initial_positions=given)
    assert all(type(v) is float for v in backend.state.positions)
    given[0] = 99
    assert backend.state.positions[0] == 1.0


def test_initial_positions_of_wrong_length_are_refused() -> None:
    with pytest.raises((ValueError, BackendError)):
        make([1.0, 2.0])


# --- step(): the simulated robot ---


def test_position_command_is_mirrored_on_the_next_step() -> None:
    backend = make([0.0, 0.0, 0.0])
    positions, velocities = backend.state.positions, backend.state.velocities
    backend.command.mode = CommandMode.POSITION
    backend.command.positions[:] = [0.1, 0.2, 0.3]
    backend.command.velocities[:] = [1.0, 2.0, 3.0]
    # nothing changes until the robot cycles: one cycle of lag
    assert backend.state.positions == [0.0, 0.0, 0.0]
    backend.step()
    assert backend.state.positions == [0.1, 0.2, 0.3]
    assert backend.state.velocities == [1.0, 2.0, 3.0]
    # the state lists are filled in place, never replaced
    assert backend.state.positions is positions
    assert backend.state.velocities is velocities
    # and they are copies, not the command's lists
    backend.command.positions[0] = 9.0
    assert backend.state.positions[0] == 0.1


def test_position_mode_holds_the_last_command() -> None:
    backend = make()
    backend.command.mode = CommandMode.POSITION
    backend.command.positions[:] = [1.0, 1.0, 1.0]
    for _ in range(5):
        backend.step()
    assert backend.state.positions == [1.0, 1.0, 1.0]


def test_velocity_command_is_integrated() -> None:
    backend = make([1.0, 0.0, -1.0])
    backend.command.mode = CommandMode.VELOCITY
    backend.command.velocities[:] = [0.5, -2.0, 0.0]
    backend.command.positions[:] = [100.0, 100.0, 100.0]  # ignored in VELOCITY mode
    backend.step()
    assert backend.state.positions == [1.0 + 0.5 * DT, 0.0 - 2.0 * DT, -1.0]
    assert backend.state.velocities == [0.5, -2.0, 0.0]
    expected = [1.0 + 0.5 * DT, -2.0 * DT, -1.0]
    for _ in range(99):
        backend.step()
        expected = [p + v * DT for p, v in zip(expected, [0.5, -2.0, 0.0], strict=True)]
    assert backend.state.positions == expected
    assert backend.state.positions == pytest.approx([1.0 + 0.5 * 100 * DT, -2.0 * 100 * DT, -1.0])


def test_idle_zeroes_velocities_and_holds_positions() -> None:
    backend = make()
    backend.command.mode = CommandMode.VELOCITY
    backend.command.velocities[:] = [1.0, 1.0, 1.0]
    backend.step()
    held = list(backend.state.positions)
    backend.command.mode = CommandMode.IDLE
    backend.command.positions[:] = [5.0, 5.0, 5.0]
    backend.step()
    assert backend.state.velocities == [0.0, 0.0, 0.0]
    assert backend.state.positions == held


def test_controller_time_and_cycle_advance_by_one_period() -> None:
    backend = make()
    stamps = []
    for n in range(1, 11):
        backend.step()
        assert backend.state.cycle == n
        assert backend.state.controller_time == pytest.approx(n * DT, abs=1e-12)
        stamps.append((backend.state.host_time_ns, backend.state.monotonic_ns))
    assert all(h > 0 and m > 0 for h, m in stamps)
    assert [m for _, m in stamps] == sorted(m for _, m in stamps)
    assert backend.statistics().cycles == 10


@pytest.mark.parametrize("rate", [125.0, 500.0, 1000.0])
def test_period_follows_the_rate(rate: float) -> None:
    backend = make(rate=rate)
    backend.step()
    backend.step()
    assert backend.state.controller_time == pytest.approx(2.0 / rate)


@pytest.mark.parametrize(("slider", "runtime"), [(1.0, 1.0), (0.5, 1.0), (1.0, 0.3), (0.5, 0.5), (0.0, 0.7)])
async def test_speed_scaling_is_slider_times_runtime_scaling(slider: float, runtime: float) -> None:
    backend = make(scaling=runtime)
    assert backend.runtime_scaling == runtime
    await backend.set_speed_slider(slider)
    assert backend.state.speed_slider == slider
    backend.step()
    assert backend.state.speed_scaling == slider * runtime


async def test_speed_slider_takes_effect_on_the_next_cycle() -> None:
    backend = make()
    backend.step()
    assert backend.state.speed_scaling == 1.0
    await backend.set_speed_slider(0.25)
    assert backend.state.speed_scaling == 1.0
    backend.step()
    assert backend.state.speed_scaling == 0.25


@pytest.mark.parametrize(
    "request_",
    ["slider 1.5", "slider -0.1", "slider nan", "mass -1", "mass nan", "cog nan"],
)
async def test_bad_slider_and_payload_requests_are_refused(request_: str) -> None:
    backend = make()
    what, text = request_.split()
    value = float(text)
    if what == "slider":
        with pytest.raises(BackendError):
            await backend.set_speed_slider(value)
    elif what == "mass":
        with pytest.raises(BackendError):
            await backend.set_payload(value, (0.0, 0.0, 0.0))
    else:
        with pytest.raises(BackendError):
            await backend.set_payload(1.0, (0.0, value, 0.0))


# --- IO and payload ---


@pytest.mark.parametrize(
    ("kind", "pin", "value", "attribute"),
    [
        ("digital", 0, True, "digital_out"),
        ("digital", 7, True, "digital_out"),
        ("configurable", 3, True, "configurable_out"),
        ("tool", 1, True, "tool_out"),
        ("analog", 0, 0.25, "analog_out"),
        ("analog", 1, 1, "analog_out"),
    ],
)
async def test_set_io_is_reflected_in_state(kind: str, pin: int, value: float | bool, attribute: str) -> None:
    backend = make()
    outputs = getattr(backend.state, attribute)
    before = list(outputs)
    await backend.set_io(kind, pin, value)
    after = getattr(backend.state, attribute)
    assert after is outputs
    assert after[pin] == value
    assert type(after[pin]) is type(before[pin])
    assert [v for i, v in enumerate(after) if i != pin] == [v for i, v in enumerate(before) if i != pin]
    if kind != "analog":
        await backend.set_io(kind, pin, False)
        assert getattr(backend.state, attribute)[pin] is False


async def test_set_io_does_not_touch_other_kinds() -> None:
    backend = make()
    await backend.set_io("digital", 2, True)
    assert backend.state.configurable_out == [False] * 8
    assert backend.state.tool_out == [False] * 2
    assert backend.state.digital_out == [False, False, True, False, False, False, False, False]


@pytest.mark.parametrize(
    ("kind", "pin", "value", "words"),
    [
        ("relay", 0, True, ("unknown IO kind 'relay'", "digital, configurable, tool, analog")),
        ("digital", 8, True, ("digital output pin 8 out of range 0..7",)),
        ("digital", -1, True, ("digital output pin -1 out of range 0..7",)),
        ("tool", 2, True, ("tool output pin 2 out of range 0..1",)),
        ("analog", 2, 0.5, ("analog output pin 2 out of range 0..1",)),
        ("configurable", 8, False, ("configurable output pin 8 out of range 0..7",)),
        ("analog", 0, 1.5, ("analog output value must be a number in 0..1, got 1.5",)),
        ("analog", 0, -0.1, ("analog output value must be a number in 0..1",)),
        ("analog", 0, math.nan, ("analog output value must be a number in 0..1, got nan",)),
        ("analog", 0, True, ("analog output value must be a number in 0..1, got True",)),
        ("digital", 0, 1, ("digital output value must be true or false, got 1",)),
        ("tool", 0, 0.0, ("tool output value must be true or false, got 0.0",)),
    ],
)
async def test_bad_io_requests_raise_backend_error(
    kind: str, pin: int, value: float | bool, words: tuple[str, ...]
) -> None:
    backend = make()
    before = (list(backend.state.digital_out), list(backend.state.tool_out), list(backend.state.analog_out))
    with pytest.raises(BackendError) as info:
        await backend.set_io(kind, pin, value)
    for word in words:
        assert word in str(info.value)
    assert (backend.state.digital_out, backend.state.tool_out, backend.state.analog_out) == before


async def test_set_payload_is_reflected_in_state() -> None:
    backend = make()
    await backend.set_payload(2, (0, 0.1, -0.05))
    assert backend.state.payload_mass == 2.0
    assert type(backend.state.payload_mass) is float
    assert backend.state.payload_cog == (0.0, 0.1, -0.05)
    assert all(type(c) is float for c in backend.state.payload_cog)


def test_mock_io_sizes_match_the_state() -> None:
    backend = make()
    assert len(backend.state.digital_out) == IO_SIZES["digital"]
    assert len(backend.state.configurable_out) == IO_SIZES["configurable"]
    assert len(backend.state.tool_out) == IO_SIZES["tool"]
    assert len(backend.state.analog_out) == IO_SIZES["analog"]


# --- run(): a real loop, bounded by cycle count ---

CYCLES = 25


async def test_run_cycles_and_reports_a_healthy_running_robot() -> None:
    backend = make([0.1, 0.2, 0.3], rate=1000.0)
    done = asyncio.Event()
    seen: list[tuple[Lifecycle, RobotMode, SafetyMode, bool, int]] = []

    def on_cycle() -> None:
        s = backend.state
        seen.append((s.lifecycle, s.robot_mode, s.safety_mode, s.program_running, s.cycle))
        if len(seen) >= CYCLES:
            done.set()

    task = asyncio.create_task(backend.run(on_cycle))
    try:
        await asyncio.wait_for(done.wait(), timeout=10.0)
    finally:
        task.cancel()
        with pytest.raises(asyncio.CancelledError):
            await task
    assert len(seen) >= CYCLES
    assert backend.state.cycle >= CYCLES
    assert backend.statistics().cycles == backend.state.cycle
    assert all(s[:4] == (Lifecycle.RUNNING, RobotMode.RUNNING, SafetyMode.NORMAL, True) for s in seen)
    assert [s[4] for s in seen] == list(range(1, len(seen) + 1))
    assert backend.state.ready_for_motion
    assert backend.state.not_ready_reason() == ""
    assert backend.state.controller_time == pytest.approx(backend.state.cycle / 1000.0)
    assert backend.state.positions == [0.1, 0.2, 0.3]


async def test_run_applies_a_command_written_in_on_cycle_one_cycle_later() -> None:
    backend = make(rate=1000.0)
    done = asyncio.Event()
    observed: list[tuple[int, float]] = []

    def on_cycle() -> None:
        cycle = backend.state.cycle
        observed.append((cycle, backend.state.positions[0]))
        backend.command.mode = CommandMode.POSITION
        backend.command.positions[:] = [float(cycle)] * 3
        if cycle >= CYCLES:
            done.set()

    task = asyncio.create_task(backend.run(on_cycle))
    try:
        await asyncio.wait_for(done.wait(), timeout=10.0)
    finally:
        task.cancel()
        with pytest.raises(asyncio.CancelledError):
            await task
    # the command written during cycle k is the measured state of cycle k + 1
    assert observed[0] == (1, 0.0)
    for cycle, position in observed[1:]:
        assert position == float(cycle - 1)


async def test_run_propagates_an_error_of_on_cycle() -> None:
    backend = make(rate=1000.0)

    def on_cycle() -> None:
        if backend.state.cycle == 3:
            raise RuntimeError("controller broke")

    with pytest.raises(RuntimeError, match="controller broke"):
        await asyncio.wait_for(backend.run(on_cycle), timeout=10.0)
    assert backend.state.cycle == 3
