"""Independent check: SDU's ur_rtde (a C++ client written by others) works against the fake controller.

These tests must not be weakened to pass: when they fail, the fake is wrong. The fake runs as
``urdaemon fake-robot`` in its own process, as users run it: ur_rtde's calls hold the GIL while they
block on the network, so a fake in the test's own process could never answer them.
"""

from __future__ import annotations

import asyncio
import itertools
import time
from collections.abc import Callable, Iterator
from typing import Any

import pytest

from tests.fakeur.judges import start_fake
from tests.helpers import rtde_sample
from urdaemon.model import RobotMode
from urdaemon.protocols import primary as prim
from urdaemon.protocols import reverse
from urdaemon.protocols._buffer import Side
from urdaemon.urscript import ScriptParameters, render_control_script

rtde_receive = pytest.importorskip("rtde_receive")
rtde_io = pytest.importorskip("rtde_io")
dashboard_client = pytest.importorskip("dashboard_client")

pytestmark = pytest.mark.timeout(120)


@pytest.fixture
def powered_fake() -> Iterator[str]:
    fake = start_fake("ur10e", "--powered")
    yield fake.address
    fake.close()


@pytest.fixture
def unpowered_fake() -> Iterator[str]:
    fake = start_fake("ur10e")
    yield fake.address
    fake.close()


async def _rtde_sample(address: str) -> dict[str, object]:
    """One output sample read with our own codec (a second, independent reader of the fake)."""
    names = ("timestamp", "actual_q", "actual_digital_output_bits", "target_speed_fraction", "robot_mode")
    return await rtde_sample(address, names)


def _poll(condition: Callable[[], bool], seconds: float) -> None:
    """Ask ``condition`` every 10 ms until true or ``seconds`` passed (the caller asserts afterwards)."""
    deadline = time.monotonic() + seconds
    for _ in range(int(seconds / 0.01) + 1):
        if condition() or time.monotonic() > deadline:
            return
        time.sleep(0.01)


STEP_S = 0.002
"""An e-Series controller's RTDE period (500 Hz): what the timestamps of consecutive packages differ by."""
CONSECUTIVE_WINDOW_S = 2.0
"""Robot time ``getTimestamp`` is read for, at most, until two consecutive packages were seen. The
reader (this thread and ur_rtde's receive thread) sees every package only while it is never
preempted; on a loaded machine packages come in bursts it reads only the last of, so it is given
many chances (1000 packages) rather than one short window."""


def _read_until_consecutive(receiver: Any) -> set[float]:
    """The timestamps read as fast as this thread can: until two in a row ``STEP_S`` apart (and 0.2 s of
    robot time), or ``CONSECUTIVE_WINDOW_S`` of robot time, or 30 s of real time."""
    first = last = receiver.getTimestamp()
    stamps = {first}
    consecutive = False
    deadline = time.monotonic() + 30.0  # a bound for a starved fake, not a measurement
    for _ in range(50_000_000):
        now = receiver.getTimestamp()
        if now != last:
            consecutive = consecutive or abs(now - last - STEP_S) < 1e-6
            stamps.add(now)
            last = now
            if (consecutive and now - first >= 0.2) or now - first >= CONSECUTIVE_WINDOW_S:
                break
        if time.monotonic() > deadline:
            break
    return stamps


def test_rtde_receive_reads_joint_positions_and_modes_at_500_hz(powered_fake: str) -> None:
    receiver = rtde_receive.RTDEReceiveInterface(powered_fake, 500.0)
    try:
        assert receiver.isConnected()
        ours = asyncio.run(_rtde_sample(powered_fake))
        assert receiver.getActualQ() == pytest.approx(ours["actual_q"], abs=1e-6)
        assert receiver.getRobotMode() == int(RobotMode.RUNNING)
        assert receiver.getSafetyMode() == 1
        stamps = _read_until_consecutive(receiver)
        assert max(stamps) - min(stamps) >= 0.2, "the fake's RTDE clock advanced"
        steps = sorted({round(b - a, 6) for a, b in itertools.pairwise(sorted(stamps))})
        assert steps[0] == pytest.approx(STEP_S), f"the fake's RTDE runs at 500 Hz, saw steps {steps[:5]}"
        off_grid = [step for step in steps if not round(step / STEP_S, 3).is_integer()]
        assert not off_grid, f"steps off the 2 ms grid: {off_grid}"
    finally:
        receiver.disconnect()


async def _move_the_fake(address: str, moved: Callable[[], bool], frames: int) -> None:
    """Play the daemon: send our control script headless, serve its reverse socket, stream SPEEDJ on
    joint 0 until ``moved()`` (at most ``frames`` frames)."""
    accepted: asyncio.Queue[tuple[asyncio.StreamReader, asyncio.StreamWriter]] = asyncio.Queue()

    async def on_connect(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        await accepted.put((reader, writer))

    servers = [await asyncio.start_server(on_connect, "127.0.0.1", 0) for _ in range(3)]
    ports = [s.sockets[0].getsockname()[1] for s in servers]
    program = render_control_script(
        ScriptParameters(
            "127.0.0.1", trajectory_port=ports[0], script_command_port=ports[1], reverse_port=ports[2]
        )
    )
    _, pwriter = await asyncio.open_connection(address, 30001)
    pconn = prim.PrimaryConnection(Side.DAEMON)
    pconn.send(prim.Script(prim.headless_program(program)))
    pwriter.write(pconn.data_to_send())
    links = [await asyncio.wait_for(accepted.get(), 10.0) for _ in range(3)]
    rev_writer = links[-1][1]
    conn = reverse.ReverseConnection(Side.DAEMON)
    for _ in range(frames):
        if moved():
            break
        # a generous read timeout: a busy machine may hold this client up for a while between frames
        conn.send(reverse.SpeedJ((0.5, 0.0, 0.0, 0.0, 0.0, 0.0), 1.0))
        rev_writer.write(conn.data_to_send())
        await asyncio.sleep(0.008)  # a client streaming at 125 Hz
    conn.send(reverse.Stopped())
    rev_writer.write(conn.data_to_send())
    await rev_writer.drain()
    for _, writer in links:
        writer.close()
    pwriter.close()
    for server in servers:
        server.close()


def test_rtde_receive_sees_the_fake_move(powered_fake: str) -> None:
    receiver = rtde_receive.RTDEReceiveInterface(powered_fake, 500.0)
    try:
        start = receiver.getActualQ()[0]
        asyncio.run(_move_the_fake(powered_fake, lambda: receiver.getActualQ()[0] > start + 0.1, 2500))
        moved = receiver.getActualQ()[0]
        assert moved > start + 0.1, f"ur_rtde saw joint 0 go from {start} to {moved}"
        assert receiver.getActualQ()[1:] == pytest.approx([-1.57, 1.57, -1.57, -1.57, 0.0], abs=1e-6)
    finally:
        receiver.disconnect()


def test_rtde_io_sets_a_digital_output_that_the_fake_reports(powered_fake: str) -> None:
    io = rtde_io.RTDEIOInterface(powered_fake)
    receiver = rtde_receive.RTDEReceiveInterface(powered_fake, 500.0)
    try:
        assert io.setStandardDigitalOut(5, True)
        assert io.setSpeedSlider(0.25)
        for _ in range(50):
            sample = asyncio.run(_rtde_sample(powered_fake))
            if sample["actual_digital_output_bits"] == 1 << 5 and sample["target_speed_fraction"] == 0.25:
                break
        assert sample["actual_digital_output_bits"] == 1 << 5, "our own RTDE reader sees the output"
        assert sample["target_speed_fraction"] == pytest.approx(0.25)
        assert receiver.getDigitalOutState(5)
        assert not receiver.getDigitalOutState(4)
    finally:
        io.disconnect()
        receiver.disconnect()


def test_dashboard_client_powers_on_releases_brakes_and_reads_the_robot_mode(unpowered_fake: str) -> None:
    client = dashboard_client.DashboardClient(unpowered_fake)
    client.connect()
    try:
        assert client.isConnected()
        assert "POWER_OFF" in client.robotmode()
        client.powerOn()
        _poll(
            lambda: "IDLE" in client.robotmode(), 30.0
        )  # the fake boots in 0.5 s; a dashboard can only poll
        assert "IDLE" in client.robotmode()
        client.brakeRelease()
        _poll(lambda: "RUNNING" in client.robotmode(), 30.0)
        assert "RUNNING" in client.robotmode()
        assert "5.15" in client.polyscopeVersion()
        assert asyncio.run(_rtde_sample(unpowered_fake))["robot_mode"] == int(RobotMode.RUNNING)
    finally:
        client.disconnect()
