"""Issue 32, point 1: the control program rides through a host hiccup. For ``keepalive_cycles`` cycles
without a frame it goes on with the last command (a servoj stream extrapolated within the limits, a
speedj velocity, a trajectory); past them it stops the arm with ``stopj`` and waits, ready, until the
frame's read timeout (the window); a late frame is caught up with smoothly, never with a jump.

The rendered script runs in the fake's interpreter on controller time (``control_rig``): every cycle is
turned by the test, so a stall of the daemon is exactly N cycles without a frame."""

from __future__ import annotations

import contextlib
import itertools
from collections.abc import AsyncIterator

import pytest

from tests.fakeur.control_rig import (
    DT,
    HOME,
    NAMES,
    REV,
    SCRIPT,
    TRAJ,
    Daemon,
    Rig,
    connect,
    j0,
    make_arm,
    v0,
)
from urdaemon.protocols.reverse import ServoJ, SpeedJ, Stopped, TrajectoryAction, TrajectoryControl
from urdaemon.protocols.trajectory_point import SplinePoint, TrajectoryResultCode
from urdaemon.urscript import ScriptParameters, render_control_script

pytestmark = pytest.mark.timeout(120)

KEEPALIVE = 20
"""The rendered keepalive_cycles of these tests."""
WINDOW_S = 0.5
"""The read timeout every frame of these tests carries (the window), s."""
STOPJ_ACCEL = 4.0
"""The script's UD_STOPJ_ACCEL and UD_RESUME_ACCEL, rad/s²."""
STOPPING = "cycles: stopping, waiting for the daemon"
CAUGHT_UP = "urdaemon: caught up with the commands after a stop"
REVERSE_TIMEOUT = "Socket timed out waiting for command on reverse_socket"


@contextlib.asynccontextmanager
async def keepalive_script(keepalive: int = KEEPALIVE) -> AsyncIterator[Rig]:
    """The control script rendered with ``keepalive`` cycles, connected to a test daemon."""
    daemon = Daemon()
    for name in NAMES:
        await daemon.serve(name)
    params = ScriptParameters(
        "127.0.0.1",
        reverse_port=daemon.ports[REV],
        trajectory_port=daemon.ports[TRAJ],
        script_command_port=daemon.ports[SCRIPT],
        controller_version=(5, 15, 0),
        keepalive_cycles=keepalive,
    )
    rig = Rig(daemon, make_arm(), render_control_script(params))
    try:
        await connect(rig)
        yield rig
    finally:
        if not rig.run.done:
            rig.run.stop()
        rig.host.close()
        await daemon.close()


async def stream(rig: Rig, speed: float, frames: int, first: int = 0) -> None:
    """Servo frames of a stream at ``speed`` (joint 0), frame k at HOME + k·speed·DT, k from ``first``."""
    for k in range(first, first + frames):
        rig.daemon.send(ServoJ(j0(k * speed * DT), timeout=WINDOW_S))
        await rig.step(1)


def steps(values: list[float]) -> list[float]:
    return [b - a for a, b in itertools.pairwise(values)]


async def test_a_stall_within_the_keepalive_is_ridden_through_without_a_stop_or_a_jump() -> None:
    async with keepalive_script() as rig:
        speed = 0.5
        await stream(rig, speed, 250)
        assert rig.arm.qd[0] == pytest.approx(speed, rel=1e-3)
        stall = KEEPALIVE - 5
        before = len(rig.history)
        await rig.step(stall)  # the daemon is late: no frame for 15 cycles
        await stream(rig, speed, 50, first=250 + stall)  # then the stream goes on where it is now
        assert not rig.said(STOPPING)
        speeds = [d / DT for d in steps([h[0] for h in rig.history[before - 1 :]])]
        assert min(speeds) > 0.9 * speed, "no stop"
        assert max(speeds) < 1.1 * speed, "no jump"


async def test_past_the_keepalive_the_arm_stops_with_stopj_and_waits_ready_for_the_next_frame() -> None:
    """Before: the program held a stale servo setpoint after 25 cycles (an abrupt stop: servoj to a
    fixed point) and, with urcl's 0.1 s timeout, ended the whole program; a late frame after that was
    either refused (over 20 rad/s from the held setpoint) or followed with a jump."""
    async with keepalive_script() as rig:
        speed = 0.5
        await stream(rig, speed, 250)
        last = HOME[0] + 249 * speed * DT
        stall = KEEPALIVE + round(speed / STOPJ_ACCEL / DT) + 40  # the hold, the stop, and a rest
        setpoints = []
        for _ in range(stall):
            await rig.step(1)
            setpoints.append(rig.variable("ud_servo_q")[0])
        assert rig.count(STOPPING) == 1
        moves = steps([last, *setpoints])
        assert moves[:KEEPALIVE] == pytest.approx([speed * DT] * KEEPALIVE, rel=5e-3), "extrapolated"
        assert rig.at_rest(), "stopped within the window"
        assert not rig.done, "no halt: the program waits for the daemon"
        # the stale motion: the hold at the stream's speed, then stopj's stopping distance
        stale = rig.arm.q[0] - last
        bound = speed * KEEPALIVE * DT + speed * speed / (2 * STOPJ_ACCEL) + 0.03 * speed
        assert 0 < stale <= bound
        # the daemon comes back: its stream is far ahead of where the arm stopped
        resumed_at = len(rig.history)
        await stream(rig, speed, 600, first=250 + stall)
        assert rig.count(CAUGHT_UP) == 1, rig.texts()[-6:]
        arm = [h[0] for h in rig.history[resumed_at - 1 :]]
        velocities = [d / DT for d in steps(arm)]
        assert max(abs(v) for v in velocities) <= rig.arm.max_velocity[0] + 1e-9
        assert max(abs(a) for a in steps(velocities)) / DT < 60.0, "no jump: the arm speeds up smoothly"
        assert rig.arm.q[0] == pytest.approx(HOME[0] + (250 + stall + 599) * speed * DT, abs=0.03)
        rig.daemon.send(Stopped())
        await rig.until(lambda: rig.done, 200)
        assert not rig.said(REVERSE_TIMEOUT)


async def test_the_caught_up_setpoint_never_outruns_the_resume_limits() -> None:
    async with keepalive_script() as rig:
        await stream(rig, 0.5, 100)
        await rig.step(KEEPALIVE + 100)
        assert rig.at_rest()
        outs: list[float] = []
        for _ in range(300):
            rig.daemon.send(ServoJ(j0(0.3), timeout=WINDOW_S))  # a target 0.25 rad from the arm
            await rig.step(1)
            outs.append(rig.variable("ud_servo_out")[0])
        velocities = [d / DT for d in steps(outs)]
        accelerations = [d / DT for d in steps(velocities)]
        # UD_RESUME_ACCEL, give or take the last step onto the target (its rest comes within a cycle)
        assert max(abs(a) for a in accelerations) <= 1.25 * STOPJ_ACCEL
        assert outs[-1] == pytest.approx(HOME[0] + 0.3, abs=1e-9)


async def test_a_speedj_stream_past_the_keepalive_stops_and_the_next_velocity_resumes_it() -> None:
    async with keepalive_script() as rig:
        for _ in range(60):
            rig.daemon.send(SpeedJ(v0(0.4), timeout=WINDOW_S))
            await rig.step(1)
        assert rig.arm.qd[0] == pytest.approx(0.4)
        await rig.step(KEEPALIVE - 1)
        assert rig.arm.qd[0] == pytest.approx(0.4), "held through the keepalive"
        await rig.until(rig.at_rest, round(0.4 / STOPJ_ACCEL / DT) + 20)
        assert rig.count(STOPPING) == 1
        assert not rig.done
        for _ in range(60):
            rig.daemon.send(SpeedJ(v0(0.4), timeout=WINDOW_S))
            await rig.step(1)
        assert rig.arm.qd[0] == pytest.approx(0.4), "the same program goes on"


async def test_a_trajectory_goes_on_through_missed_keepalives_within_the_window() -> None:
    """Before, the daemon sent trajectory NOOPs with urcl's 0.2 s timeout: a 0.2 s hiccup during a
    passthrough goal ended the program and the goal."""
    async with keepalive_script() as rig:
        target = j0(0.2)
        point = SplinePoint(target, (0.0,) * 6, None, 0.3)
        rig.daemon.send(TrajectoryControl(TrajectoryAction.START, 1, timeout=WINDOW_S))
        rig.daemon.send_points(point)
        result = await rig.result(round(0.3 / DT) + 50)  # no NOOP meanwhile: 150 cycles > the keepalive
        assert result is TrajectoryResultCode.SUCCESS
        assert rig.arm.q[0] == pytest.approx(target[0], abs=1e-6)


async def test_past_the_window_the_program_still_ends() -> None:
    async with keepalive_script() as rig:
        await stream(rig, 0.5, 50)
        silent_from = rig.cycles
        ended = await rig.until(lambda: rig.done, round(WINDOW_S / DT) + 100)
        assert ended - silent_from >= WINDOW_S / DT - 5
        assert rig.said(REVERSE_TIMEOUT)
