"""The servo backend's run with device outputs: readiness follows the outputs, the safe state is
applied when the run ends, users hear of lost, restored and slow outputs, and the device checks
``check`` and ``serve`` make before starting."""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Sequence
from pathlib import Path

import pytest

from tests.cell.test_cli_check import error_lines, run_check
from tests.helpers import run_cli
from urdaemon.backends.servo import ServoBackend
from urdaemon.backends.servo.backend import PACE_AFTER_S, PaceWatch
from urdaemon.backends.servo.outputs import device_problems
from urdaemon.cell import load_cell
from urdaemon.cell.servo import ServoOptions
from urdaemon.model import CommandMode, Lifecycle

CONFIGS = Path(__file__).resolve().parents[2] / "configs"
WAIT_S = 10.0


class FakeLink:
    """A board link the test controls: opening fails while ``broken``; every call is recorded."""

    def __init__(self, label: str = "fake board") -> None:
        self.label = label
        self.broken = threading.Event()
        self.calls: list[str] = []
        self.frames: list[tuple[float, ...]] = []
        self.opened = threading.Event()
        self.wrote = threading.Event()
        self.closed = threading.Event()
        self.gate: threading.Event | None = None
        """When set, each write waits for it (a slow bus)."""

    def open(self) -> None:
        self.calls.append("open")
        if self.broken.is_set():
            raise OSError(19, "No such device")
        self.opened.set()

    def write(self, pulses: Sequence[float]) -> int:
        if self.gate is not None:
            self.gate.wait(WAIT_S)
        if self.broken.is_set():
            raise OSError(5, "Input/output error")
        self.frames.append(tuple(pulses))
        self.wrote.set()
        return 1

    def check(self) -> None:
        self.calls.append("check")
        if self.broken.is_set():
            raise OSError(121, "Remote I/O error")

    def off(self) -> None:
        self.calls.append("off")

    def close(self) -> None:
        self.calls.append("close")
        self.closed.set()


def servo_options(**extra: object) -> tuple[ServoOptions, tuple[str, ...], str]:
    robot = load_cell(CONFIGS / "servo_arm.yaml").robots[0]
    assert robot.servo is not None
    options = robot.servo.model_copy(update={"rate_hz": 200.0, **extra})
    return options, tuple(f"{robot.prefix}{j.name}" for j in options.joints), robot.prefix


def servo_backend(link: FakeLink, **extra: object) -> tuple[ServoBackend, list[tuple[str, str]]]:
    options, names, prefix = servo_options(**extra)
    backend = ServoBackend("arm", names, prefix, options, links=[link])
    notices: list[tuple[str, str]] = []
    backend.on_notice = lambda kind, text: notices.append((kind, text))
    return backend, notices


async def until(condition: object, what: str) -> None:
    """Wait (bounded) until ``condition()`` holds, checking once a cycle."""
    assert callable(condition)
    for _ in range(int(WAIT_S / 0.005)):
        if condition():
            return
        await asyncio.sleep(0.005)
    raise AssertionError(f"timed out waiting for {what}")


async def test_the_robot_is_ready_only_once_its_output_opened() -> None:
    link = FakeLink()
    link.broken.set()
    backend, notices = servo_backend(link)
    task = asyncio.create_task(backend.run(lambda: None))
    try:
        await until(
            lambda: "opening servo output fake board: No such device" in backend.state.lifecycle_reason,
            "reason",
        )
        assert backend.state.lifecycle is Lifecycle.CONNECTING
        assert not backend.state.ready_for_motion
        link.broken.clear()
        await until(lambda: backend.state.ready_for_motion, "ready")
        assert backend.state.lifecycle_reason == ""
        assert await asyncio.to_thread(link.wrote.wait, WAIT_S)
        assert link.frames[-1] == tuple(backend.mapping.pulses)
        assert notices == []  # never lost: it was not there yet
    finally:
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)


async def test_a_lost_output_makes_the_robot_not_ready_until_it_is_back() -> None:
    link = FakeLink()
    backend, notices = servo_backend(link)
    task = asyncio.create_task(backend.run(lambda: None))
    try:
        await until(lambda: backend.state.ready_for_motion, "ready")
        link.broken.set()
        backend.command.mode = CommandMode.POSITION
        backend.command.positions[:] = [0.3, 0.0, 0.0, 0.0]  # a new frame: the write fails
        await until(lambda: backend.state.lifecycle is Lifecycle.DISCONNECTED, "lost")
        assert (
            "servo output fake board failed: Input/output error (errno 5)" in backend.state.lifecycle_reason
        )
        assert not backend.state.ready_for_motion
        assert notices[0][0] == "servo_output_lost"
        report = backend.output_reports()
        assert report is not None
        assert (report[0]["state"], report[0]["failures"] >= 1) == ("lost", True)
        link.broken.clear()
        await until(lambda: backend.state.ready_for_motion, "back")
        assert [kind for kind, _ in notices] == ["servo_output_lost", "servo_output_back"]
        await until(lambda: link.frames and link.frames[-1][0] == backend.mapping.pulse_us(0, 0.3), "frame")
    finally:
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)


async def test_a_board_lost_while_the_arm_rests_is_found_without_a_motion() -> None:
    link = FakeLink()
    backend, notices = servo_backend(link)
    task = asyncio.create_task(backend.run(lambda: None))
    try:
        await until(lambda: backend.state.ready_for_motion, "ready")
        assert await asyncio.to_thread(link.wrote.wait, WAIT_S)  # the first frame is on the board
        link.broken.set()  # nothing moves: only the writer's probe can notice
        await until(lambda: backend.state.lifecycle is Lifecycle.DISCONNECTED, "lost at rest")
        assert "check" in link.calls
        assert "Remote I/O error (errno 121)" in backend.state.lifecycle_reason
        assert [kind for kind, _ in notices] == ["servo_output_lost"]
    finally:
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)


@pytest.mark.parametrize(("safe_state", "calls"), [("off", ["off", "close"]), ("hold", ["close"])])
async def test_the_safe_state_is_applied_when_the_run_ends(safe_state: str, calls: list[str]) -> None:
    link = FakeLink()
    backend, _ = servo_backend(link, safe_state=safe_state)
    task = asyncio.create_task(backend.run(lambda: None))
    await until(lambda: backend.state.ready_for_motion, "ready")
    task.cancel()
    await asyncio.gather(task, return_exceptions=True)
    assert link.calls[-len(calls) :] == calls
    assert link.calls.count("off") == calls.count("off")


async def test_a_resting_arm_sends_no_new_frames() -> None:
    link = FakeLink()
    backend, _ = servo_backend(link)
    cycles = 0

    def count() -> None:
        nonlocal cycles
        cycles += 1

    task = asyncio.create_task(backend.run(count))
    try:
        await until(lambda: link.wrote.is_set(), "first frame")
        seen = cycles
        await until(lambda: cycles >= seen + 20, "20 cycles")
        assert len(link.frames) == 1
        report = backend.output_reports()
        assert report is not None
        assert report[0]["frames"] == 1
    finally:
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)


async def test_a_slow_output_is_told_and_its_skipped_frames_counted() -> None:
    link = FakeLink()
    link.gate = threading.Event()
    backend, notices = servo_backend(link)
    task = asyncio.create_task(backend.run(lambda: None))
    try:
        await until(lambda: backend.state.ready_for_motion, "ready")
        backend.command.mode = CommandMode.VELOCITY
        backend.command.velocities[:] = [0.1, 0.0, 0.0, 0.0]  # a new frame every cycle; the bus hangs
        await until(lambda: any(kind == "servo_output_slow" for kind, _ in notices), "slow")
        assert "fake board skipped" in backend.state.lifecycle_reason
        assert backend.state.ready_for_motion  # slow is not lost: motion goes on
        report = backend.output_reports()
        assert report is not None
        assert report[0]["superseded"] > 0
    finally:
        link.gate.set()
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)


def test_pace_is_told_once_slow_and_once_again_after_quiet_seconds() -> None:
    pace = PaceWatch()
    said = [pace.second([("a", 0), ("b", 0)])]
    said.append(pace.second([("a", 3), ("b", 0)]))
    assert (
        pace.text
        == "servo output slow: a skipped 3 frame(s) in the last second (only the newest frame is written)"
    )
    said.append(pace.second([("a", 0), ("b", 1)]))  # still slow: not said again, the reason follows
    assert "b skipped 1 frame(s)" in pace.text
    for _ in range(PACE_AFTER_S - 1):
        said.append(pace.second([("a", 0), ("b", 0)]))
    assert pace.text  # not yet: a quiet second now and then is not pace
    said.append(pace.second([("a", 0), ("b", 0)]))
    assert pace.text == ""
    kinds = [s[0] for s in said if s is not None]
    assert kinds == ["servo_output_slow", "servo_output_pace"]
    assert [s is None for s in said[:3]] == [True, False, True]  # told when it began, not again


# --- what check and serve refuse before starting ---


def outputs(*items: dict[str, object]) -> ServoOptions:
    options, _, _ = servo_options()
    return ServoOptions.model_validate({**options.model_dump(exclude={"outputs"}), "outputs": items})


@pytest.mark.parametrize(
    ("output", "exists", "may_open", "expected"),
    [
        (
            {"kind": "i2c", "bus": 3},
            False,
            True,
            "arm: servo.outputs[0].bus: /dev/i2c-3 does not exist: enable I²C",
        ),
        (
            {"kind": "i2c", "bus": 3},
            True,
            False,
            "no permission to open /dev/i2c-3: add your user to the i2c group",
        ),
        (
            {"kind": "serial", "port": "/dev/ttyUSB7"},
            False,
            True,
            "serial port /dev/ttyUSB7 does not exist",
        ),
        ({"kind": "serial", "port": "/dev/ttyUSB7"}, True, False, "add your user to the dialout group"),
    ],
)
def test_device_problems_name_the_key_and_what_to_do(
    output: dict[str, object], exists: bool, may_open: bool, expected: str
) -> None:
    problems = device_problems(
        outputs(output), "arm: servo", exists=lambda _: exists, may_open=lambda _: may_open
    )
    assert len(problems) == 1
    assert expected in problems[0]


def test_device_problems_pass_devices_that_are_there_and_ignore_zenoh() -> None:
    options = outputs({"kind": "zenoh"}, {"kind": "i2c"}, {"kind": "serial", "port": "/dev/x"})
    assert device_problems(options, "arm: servo", exists=lambda _: True, may_open=lambda _: True) == []


def missing_devices_cell(tmp_path: Path) -> tuple[Path, Path]:
    """A servo-arm cell file whose outputs name a bus and a port that do not exist; (file, port)."""
    port = tmp_path / "no-such-port"
    text = (
        (CONFIGS / "servo_arm.yaml")
        .read_text()
        .replace(
            "      rate_hz: 50\n",
            f"      rate_hz: 50\n      outputs: [{{kind: i2c, bus: 254}}, {{kind: serial, port: {port}}}]\n",
        )
    )
    path = tmp_path / "servo.yaml"
    xacro = str(CONFIGS / "servo_arm/servo_arm.urdf.xacro")
    path.write_text(text.replace("servo_arm/servo_arm.urdf.xacro", xacro))
    return path, port


def test_serve_refuses_a_missing_device_at_once(tmp_path: Path) -> None:
    path, port = missing_devices_cell(tmp_path)
    run = run_cli("serve", "--config", str(path), "--listen", "tcp/127.0.0.1:0")
    assert run.code == 2, run.stderr
    assert "robot 'arm': servo.outputs[0].bus: /dev/i2c-254 does not exist" in run.stderr
    assert f"servo.outputs[1].port: serial port {port} does not exist" in run.stderr


def test_check_refuses_a_missing_bus_and_port(tmp_path: Path) -> None:
    path, port = missing_devices_cell(tmp_path)
    proc = run_check(path)
    assert proc.returncode == 2, proc.stderr
    lines = error_lines(proc.stderr)
    assert any("robot 'arm': servo.outputs[0].bus: /dev/i2c-254 does not exist" in line for line in lines), (
        lines
    )
    assert any(
        f"robot 'arm': servo.outputs[1].port: serial port {port} does not exist" in line for line in lines
    )


def test_check_can_leave_the_devices_to_the_machine_that_drives_them(tmp_path: Path) -> None:
    path, _ = missing_devices_cell(tmp_path)
    proc = run_check(path, extra=("--skip-devices",))
    assert proc.returncode == 0, proc.stderr
    assert "outputs=i2c bus 254 (0x40), serial " in proc.stdout
