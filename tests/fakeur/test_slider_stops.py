"""A stop never gets longer because the speed slider is low (issue 32's hostile probe: at slider 0.1 a
0.3 rad/s joint stream took 7.2-7.4 s and ~1.1 rad to stop, against 0.16-0.34 s at 1.0).

The slider slows a motion's progress (movej, a trajectory's speedj steps, speedj); it neither slows
servoj's tracking of the daemon's setpoints nor weakens a stop's braking (stopj, stopl). Both were
played on the program's time, ``dt × slider`` a cycle, so at slider 0.1 a servo stream lagged 10×
further behind its setpoint and the control script's ``stopj(4)`` braked at 0.04 rad/s². Everything
runs on the rig's controller clock; the arm is judged by cycles counted, never by wall time.
"""

from __future__ import annotations

from collections.abc import Callable, Generator
from typing import Any

from tests.fakeur.control_rig import DT, HOME, Rig, running_script
from urdaemon.description.urmodels import load_ur_model
from urdaemon.fakeur.fake_arm import FakeArm
from urdaemon.fakeur.urscript import lib_motion
from urdaemon.fakeur.urscript.runtime import UrList
from urdaemon.fakeur.urscript.script_host import ScriptHost
from urdaemon.protocols.reverse import Idle, ServoJ

STREAM_SPEED = 0.3
"""rad/s of joint 0: the probe's stream."""
STREAM_CYCLES = 500
DAEMON_STOP_DECELERATION = 3.0
"""rad/s²: the daemon's stop ramp of the setpoint (about what its jerk-limited stop does)."""
REST = 1e-3
"""rad/s: at rest."""


async def _stream_then_stop(rig: Rig, slider: float, *, ramp: bool) -> tuple[int, float]:
    """A servoj stream at ``STREAM_SPEED`` at ``slider``, then the daemon's stop (the setpoint ramped to
    rest if ``ramp``, then IDLE, which ends the script's servo thread with its stopj): the cycles from
    the stop's start until the arm rests, and how far it went meanwhile (rad)."""
    rig.arm.speed_slider = slider
    setpoint = HOME[0]
    for _ in range(STREAM_CYCLES):
        setpoint += STREAM_SPEED * DT
        rig.daemon.send(ServoJ((setpoint, *HOME[1:]), timeout=0.1))
        await rig.step(1)
    assert abs(rig.arm.qd[0]) > 0.9 * STREAM_SPEED * slider, "the stream moves the arm"
    start, begun = rig.arm.q[0], rig.cycles
    speed = STREAM_SPEED if ramp else 0.0
    while speed > 0.0:
        speed = max(0.0, speed - DAEMON_STOP_DECELERATION * DT)
        setpoint += speed * DT
        rig.daemon.send(ServoJ((setpoint, *HOME[1:]), timeout=0.1))
        await rig.step(1)
    rig.daemon.send(Idle(timeout=0.0))
    rested = await rig.until(lambda: max(abs(v) for v in rig.arm.qd) < REST, 20_000)
    return rested - begun, abs(rig.arm.q[0] - start)


async def test_a_stream_stops_no_later_and_no_further_at_slider_0_1_than_at_1() -> None:
    for ramp in (True, False):
        stops = {}
        for slider in (1.0, 0.1):
            async with running_script() as rig:
                stops[slider] = await _stream_then_stop(rig, slider, ramp=ramp)
        (full_cycles, full_distance), (low_cycles, low_distance) = stops[1.0], stops[0.1]
        assert low_cycles <= full_cycles, (ramp, stops)
        assert low_distance <= full_distance + 1e-6, (ramp, stops)


def test_stopj_and_stopl_brake_no_later_at_slider_0_1_than_at_1() -> None:
    """speedj (which the slider slows), then stopj(4) or stopl(1): the stop's cycles, at 0.1 no more
    than at 1.0 (played on the program's time the stop braked at a × slider²: 100 times longer)."""
    stops: tuple[Callable[[ScriptHost], Generator[None, None, Any]], ...] = (
        lambda host: lib_motion.stopj(host, 4.0),
        lambda host: lib_motion.stopl(host, 1.0, None),
    )
    for stop in stops:
        taken = {}
        for slider in (1.0, 0.1):
            model = load_ur_model("ur10e")
            arm = FakeArm(model, model.dh, initial_positions=HOME, powered=True)
            arm.start_program()
            arm.speed_slider = slider
            host = ScriptHost(arm, step_time=DT)
            _run(host, lib_motion.speedj(host, UrList([STREAM_SPEED, 0.0, 0.0, 0.0, 0.0, 0.0]), 10.0, 0.4))
            assert arm.qd[0] > 0.9 * STREAM_SPEED * slider
            taken[slider] = _run(host, stop(host))
            assert max(abs(v) for v in arm.qd) < REST
        assert taken[0.1] <= taken[1.0], taken


def _run(host: ScriptHost, gen: Generator[None, None, Any]) -> int:
    """Cycles until the builtin returns: each resumes it once, then steps the arm (controller order)."""
    for cycle in range(20_000):
        try:
            next(gen)
        except StopIteration:
            return cycle
        host.arm.step(DT)
    raise AssertionError("the builtin never returned")
