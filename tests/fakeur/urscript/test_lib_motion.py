"""URScript motion builtins on the fake arm, driven cycle by cycle as the scheduler drives them."""

from __future__ import annotations

import itertools
import math
from collections.abc import Generator, Sequence
from typing import Any

import pytest

from urdaemon.description.urmodels import load_ur_model
from urdaemon.fakeur.fake_arm import FakeArm
from urdaemon.fakeur.joint_motion import ServoFilter
from urdaemon.fakeur.life import UNLOCK_WAIT_S
from urdaemon.fakeur.urscript import lib_motion, lib_state
from urdaemon.fakeur.urscript.runtime import ScriptRuntimeError, UrList, UrPose
from urdaemon.fakeur.urscript.script_host import ScriptHost
from urdaemon.fakeur.urscript.signatures import Computed
from urdaemon.model import SafetyMode

DT = 0.002
LIMIT = 20_000
"""Cycles any single motion in these tests may take (40 s of controller time)."""


def _host(slider: float = 1.0) -> ScriptHost:
    model = load_ur_model("ur10e")
    arm = FakeArm(model, model.dh, powered=True)
    arm.start_program()
    arm.speed_slider = slider
    return ScriptHost(arm, step_time=DT)


def _run(host: ScriptHost, gen: Generator[None, None, Any], probe: list[list[float]] | None = None) -> int:
    """Cycles until the builtin returns: each resumes it once, then steps the arm (controller order)."""
    for cycle in range(LIMIT):
        try:
            next(gen)
        except StopIteration:
            return cycle
        host.arm.step(DT)
        if probe is not None:
            probe.append(list(host.arm.q))
    raise AssertionError("the builtin never returned")


def _offset(q: Sequence[float], **changes: float) -> list[float]:
    out = list(q)
    for key, value in changes.items():
        out[int(key[1:])] += value
    return out


def test_movej_reaches_its_target_within_v_and_a() -> None:
    """movej: the target within 1e-3 rad, no joint faster than v, the profile's time at v and a."""
    host = _host()
    arm = host.arm
    target = _offset(arm.q, j0=1.0, j1=0.3)
    speeds: list[float] = []
    positions: list[list[float]] = []
    cycles = _run(host, lib_motion.movej(host, target, 1.4, 1.05, 0, 0), positions)
    for before, after in itertools.pairwise(positions):
        speeds.append(max(abs(b - a) for a, b in zip(before, after, strict=True)) / DT)
    assert max(abs(a - b) for a, b in zip(arm.q, target, strict=True)) < 1e-3
    assert max(speeds) <= 1.05 + 1e-9
    expected = 1.0 / 1.05 + 1.05 / 1.4  # the leading joint's trapezoid
    assert cycles == pytest.approx(expected / DT, abs=2)
    accelerations = [abs(b - a) / DT for a, b in itertools.pairwise(speeds)]
    assert max(accelerations) <= 1.4 * 1.01


def test_movej_to_a_pose_goes_to_the_ik_solution_nearest_the_arm() -> None:
    host = _host()
    arm = host.arm
    goal_joints = _offset(arm.q, j0=0.4, j2=-0.2)
    goal = UrPose(lib_motion.tcp_pose(arm, goal_joints))
    _run(host, lib_motion.movej(host, goal, 1.4, 1.05, 0, 0))
    assert max(abs(a - b) for a, b in zip(arm.q, goal_joints, strict=True)) < 1e-6


def test_movej_with_a_time_takes_that_time() -> None:
    host = _host()
    cycles = _run(host, lib_motion.movej(host, _offset(host.arm.q, j0=0.5), 1.4, 1.05, 2.0, 0))
    assert cycles == pytest.approx(2.0 / DT, abs=2)


def test_speed_slider_at_half_doubles_the_time_and_halves_the_speed() -> None:
    full, half = _host(), _host(0.5)
    target = _offset(full.arm.q, j0=1.0)
    fast = _run(full, lib_motion.movej(full, target, 1.4, 1.05, 0, 0))
    peak: list[list[float]] = []
    slow = _run(half, lib_motion.movej(half, target, 1.4, 1.05, 0, 0), peak)
    assert slow == pytest.approx(2 * fast, abs=2)
    top = max(abs(b[0] - a[0]) for a, b in itertools.pairwise(peak)) / DT
    assert top == pytest.approx(1.05 / 2, rel=1e-3)
    assert half.arm.q[0] == pytest.approx(target[0], abs=1e-9)


def test_movel_keeps_the_tcp_on_a_straight_line() -> None:
    """movel: every cycle's TCP within 0.1 mm of the line, the target within 1e-4 m."""
    host = _host()
    arm = host.arm
    arm.tcp_offset = [0.0, 0.0, 0.1, 0.0, 0.0, 0.0]
    start = lib_state.get_actual_tcp_pose(host)
    goal = UrPose([start[0] + 0.15, start[1] - 0.05, start[2] - 0.1, *start[3:]])
    cycles = 0
    gen = lib_motion.movel(host, goal, 1.2, 0.25, 0, 0)
    a, b = start[:3], goal[:3]
    length = math.dist(a, b)
    direction = [(y - x) / length for x, y in zip(a, b, strict=True)]
    worst = 0.0
    while cycles < LIMIT:
        try:
            next(gen)
        except StopIteration:
            break
        arm.step(DT)
        cycles += 1
        p = lib_state.get_actual_tcp_pose(host)[:3]
        rel = [x - y for x, y in zip(p, a, strict=True)]
        along = sum(r * d for r, d in zip(rel, direction, strict=True))
        worst = max(worst, math.dist(rel, [along * d for d in direction]))
    end = lib_state.get_actual_tcp_pose(host)
    assert worst < 1e-4
    assert math.dist(end[:3], goal[:3]) < 1e-4
    assert max(abs(x - y) for x, y in zip(end[3:], goal[3:], strict=True)) < 1e-4
    assert cycles == pytest.approx((length / 0.25 + 0.25 / 1.2) / DT, abs=2)


def test_servoj_returns_after_its_time_rounded_to_cycles_with_the_arm_on_its_way() -> None:
    """servoj blocks for ``t`` rounded to whole cycles; in that time the arm moves toward the target as
    the gain/lookahead model says, not onto it (f5f0e26 put it exactly on the target)."""
    host = _host()
    arm = host.arm
    start = list(arm.q)
    target = _offset(start, j0=0.004)
    assert _run(host, lib_motion.servoj(host, target, 0, 0, 0.008, 0.1, 300)) == 4
    model = ServoFilter(start, [0.0] * 6, target, 0.008, 300, 0.1).position(0.008)
    assert arm.q[0] == pytest.approx(model[0], abs=1e-12)
    assert start[0] < arm.q[0] < 0.5 * (start[0] + target[0])
    assert _run(host, lib_motion.servoj(host, _offset(target, j0=0.001), 0, 0, 0.0025, 0.1, 300)) == 1


@pytest.mark.parametrize(("gain", "lookahead"), [(300, 0.1), (2000, 0.03)])
def test_the_arm_converges_on_a_held_servoj_setpoint(gain: float, lookahead: float) -> None:
    """The same setpoint sent every cycle (a stream that stopped moving): the arm approaches it as the
    closed form of the model says and settles on it. On f5f0e26 it was there after one cycle."""
    host = _host()
    arm = host.arm
    start = list(arm.q)
    target = _offset(start, j0=0.05, j2=-0.03)
    model = ServoFilter(list(start), [0.0] * 6, target, 1.0, gain, lookahead)
    for k in range(1, 751):
        _run(host, lib_motion.servoj(host, target, 0, 0, DT, lookahead, gain))
        if k == 10:
            assert arm.q == pytest.approx(model.position(10 * DT), abs=1e-9)
            assert abs(arm.q[0] - target[0]) > 0.01
    assert arm.q == pytest.approx(target, abs=1e-9)
    assert max(abs(v) for v in arm.qd) < 1e-6


def test_a_servoj_stream_lags_by_the_lookahead_and_then_comes_to_rest_when_it_stops() -> None:
    """servoj every cycle along a sine: the arm (on the model's target_q) is behind each setpoint by
    lookahead × speed, plus (1/gain − lookahead²) × acceleration (the model's steady-state error to
    second order); no further servoj: it decelerates to rest. On f5f0e26 it was on every setpoint."""
    host = _host()
    arm = host.arm
    q0 = arm.q[0]
    lag = 0.0
    for k in range(1, 200):
        setpoint = _offset(arm.q, j0=0.0)
        setpoint[0] = q0 + 0.5 * math.sin(k * DT * 2.0)
        _run(host, lib_motion.servoj(host, setpoint, 0, 0, DT, 0.1, 300))
        assert arm.q[0] == pytest.approx(arm.target_q[0], abs=1e-12)
        lag = setpoint[0] - arm.q[0]
    t = 199 * DT
    speed, acceleration = math.cos(2.0 * t), -2.0 * math.sin(2.0 * t)
    assert lag == pytest.approx(0.1 * speed + (1 / 300 - 0.1**2) * acceleration, abs=2e-3)
    assert lag > 0.05
    moving = abs(arm.qd[0])
    assert moving > 0.1
    for _ in range(200):
        arm.step(DT)
    assert arm.qd == [0.0] * 6
    assert arm.steady


def test_speedj_ramps_at_a_and_returns_after_t_or_once_at_speed() -> None:
    host = _host()
    arm = host.arm
    assert _run(host, lib_motion.speedj(host, [0.5, 0, 0, 0, 0, 0], 2.0, 0.1)) == 50
    assert arm.target_qd[0] == pytest.approx(0.2)
    cycles = _run(host, lib_motion.speedj(host, [0.5, 0, 0, 0, 0, 0], 2.0, 0))
    assert cycles == pytest.approx(0.15 / DT, abs=1)
    assert arm.target_qd[0] == pytest.approx(0.5)
    assert _run(host, lib_motion.speedj(host, [0.5, 0, 0, 0, 0, 0], 2.0, 0)) == 1, "at speed: one cycle"


def test_speedj_with_no_acceleration_holds_the_speed_it_has_and_refuses_a_change() -> None:
    """urcl's spline follower ends a segment with speedj(zeros, 0, t) at rest: a hold, not an error."""
    host = _host()
    before = list(host.arm.q)
    assert _run(host, lib_motion.speedj(host, [0.0] * 6, 0.0, 1e-13)) == 1
    assert host.arm.q == pytest.approx(before, abs=1e-12)
    with pytest.raises(ScriptRuntimeError, match="acceleration must be > 0 to change speed"):
        _run(host, lib_motion.speedj(host, [0.1, 0, 0, 0, 0, 0], 0.0, 0.1))


def test_stopj_decelerates_the_leading_joint_at_a() -> None:
    host = _host()
    arm = host.arm
    _run(host, lib_motion.speedj(host, [1.0, -0.5, 0, 0, 0, 0], 4.0, 0))
    cycles = _run(host, lib_motion.stopj(host, 2.0))
    assert cycles == pytest.approx(1.0 / 2.0 / DT, abs=1)
    arm.step(DT)
    assert arm.qd == [0.0] * 6


def test_stopl_stops_the_tool_in_its_speed_over_a() -> None:
    host = _host()
    arm = host.arm
    _run(host, lib_motion.speedj(host, [0.3, 0.2, 0, 0, 0, 0], 4.0, 0))
    tool = lib_state.get_actual_tcp_speed(host)
    linear = math.sqrt(sum(v * v for v in tool[:3]))
    assert linear > 0.05
    cycles = _run(host, lib_motion.stopl(host, 0.5, Computed("param:a")))
    assert cycles * DT >= linear / 0.5 - DT
    arm.step(DT)
    assert arm.qd == [0.0] * 6


def test_a_blend_radius_returns_early_and_the_next_move_continues_smoothly() -> None:
    """movej r > 0 returns within r of its target while moving; the next movej starts at that speed."""
    host = _host()
    arm = host.arm
    via = _offset(arm.q, j0=0.8)
    end = _offset(via, j1=0.5)
    positions: list[list[float]] = []
    _run(host, lib_motion.movej(host, via, 1.4, 1.05, 0, 0.05), positions)
    assert any(abs(v) > 0.1 for v in arm.target_qd), "still moving at the blend"
    goal_tcp = lib_motion.tcp_pose(arm, via)[:3]
    assert math.dist(lib_motion.tcp_pose(arm, arm.q)[:3], goal_tcp) <= 0.05 + 1e-9
    _run(host, lib_motion.movej(host, end, 1.4, 1.05, 0, 0), positions)
    speeds = [[(b - a) / DT for a, b in zip(p, n, strict=True)] for p, n in itertools.pairwise(positions)]
    jumps = [max(abs(y - x) for x, y in zip(s, t, strict=True)) for s, t in itertools.pairwise(speeds)]
    assert max(jumps) < 1.4 * DT * 3, "no velocity jump at the blend"
    assert max(abs(a - b) for a, b in zip(arm.q, end, strict=True)) < 1e-3


def test_a_movej_target_outside_the_joint_limits_is_a_runtime_error() -> None:
    """A controller checks a joint move's target before it plans (urcl's
    ``unfeasible_movej_target_results_in_failure``): the program stops; before, a protective stop
    paused it."""
    host = _host()
    arm = host.arm
    target = _offset(arm.q, j0=0.0)
    target[2] = arm.max_position[2] + 0.1
    before = list(arm.q)
    with pytest.raises(ScriptRuntimeError, match="outside the joint limits"):
        _run(host, lib_motion.movej(host, target, 1.4, 1.05, 0, 0))
    assert arm.safety_mode is SafetyMode.NORMAL
    assert arm.q == before


def test_a_movel_target_outside_the_joint_limits_is_a_protective_stop_and_waits() -> None:
    host = _host()
    arm = host.arm
    target = _offset(arm.q, j0=0.0)
    target[2] = arm.max_position[2] + 0.1
    before = list(arm.q)
    gen = lib_motion.movel(host, UrList(target), 1.2, 0.25, 0, 0)
    for _ in range(10):
        next(gen)
        arm.step(DT)
    assert arm.safety_mode is SafetyMode.PROTECTIVE_STOP
    assert arm.q == before, "the command waits in the stop"


def test_the_latest_motion_command_wins() -> None:
    """Two threads command motion: the first command returns when the second takes the arm."""
    host = _host()
    arm = host.arm
    first = lib_motion.movej(host, _offset(arm.q, j0=1.0), 1.4, 1.05, 0, 0)
    next(first)
    arm.step(DT)
    second = lib_motion.speedj(host, [0, 0.2, 0, 0, 0, 0], 2.0, 0.5)
    next(second)
    with pytest.raises(StopIteration):
        next(first)
    arm.step(DT)
    assert _run(host, second) > 0
    assert arm.target_qd[1] == pytest.approx(0.2)


def test_killing_the_commanding_thread_stops_the_arm() -> None:
    host = _host()
    arm = host.arm
    gen = lib_motion.movej(host, _offset(arm.q, j0=1.0), 1.4, 1.05, 0, 0)
    for _ in range(300):
        next(gen)
        arm.step(DT)
    gen.close()  # kill: the scheduler drops the thread's generator
    for _ in range(300):
        arm.step(DT)
    assert arm.qd == [0.0] * 6
    assert arm.q[0] < arm.history.ago(0)[0] + 1e-12


def test_a_speedj_stream_under_a_reduced_slider_stays_smooth_at_the_scaled_speed() -> None:
    """speedj every cycle at slider 0.5: the arm runs at half the speed, without a jerk per command."""
    host = _host(0.5)
    arm = host.arm
    speeds: list[float] = []
    for _ in range(400):
        _run(host, lib_motion.speedj(host, [0.4, 0, 0, 0, 0, 0], 2.0, DT))
        speeds.append(arm.qd[0])
    assert speeds[-1] == pytest.approx(0.2, abs=1e-9)
    steps = [abs(b - a) for a, b in itertools.pairwise(speeds)]
    assert max(steps) <= 2.0 * 0.5 * 0.5 * DT * 2 + 1e-12, (
        "acceleration at most a, scaled twice by the slider"
    )


def test_speedl_moves_the_tcp_at_the_commanded_twist() -> None:
    host = _host()
    arm = host.arm
    twist = [0.05, -0.03, 0.02, 0.0, 0.0, 0.1]
    _run(host, lib_motion.speedl(host, twist, 0.5, 0.5, Computed("param:a")))
    assert list(lib_state.get_target_tcp_speed(host)) == pytest.approx(twist, abs=1e-3)
    before = lib_state.get_actual_tcp_pose(host)
    gen = lib_motion.speedl(host, twist, 0.5, 0.2, Computed("param:a"))
    cycles = _run(host, gen)
    after = lib_state.get_actual_tcp_pose(host)
    moved = [(b - a) / (cycles * DT) for a, b in zip(before[:3], after[:3], strict=True)]
    assert moved == pytest.approx(twist[:3], abs=1e-3)
    for _ in range(500):  # not renewed: it stops
        arm.step(DT)
    assert arm.qd == [0.0] * 6


def test_servoc_and_optimovej_reach_their_targets() -> None:
    host = _host()
    arm = host.arm
    start = lib_state.get_actual_tcp_pose(host)
    goal = UrPose([start[0] - 0.05, start[1] + 0.05, start[2], *start[3:]])
    _run(host, lib_motion.servoc(host, goal, 1.2, 0.25, 0))
    assert math.dist(lib_state.get_actual_tcp_pose(host)[:3], goal[:3]) < 1e-4
    target = _offset(arm.q, j3=0.3)
    cycles = _run(host, lib_motion.optimovej(host, target, 0.5, 0.5, 0))
    assert max(abs(a - b) for a, b in zip(arm.q, target, strict=True)) < 1e-3
    slowest = min(arm.max_velocity) * 0.5
    assert cycles * DT >= 0.3 / slowest


def test_movel_to_joint_positions_goes_to_their_pose_on_a_line() -> None:
    """movel(q) with a joint list (our script's tool-contact retreat): the arm ends at those joints."""
    host = _host()
    arm = host.arm
    target = _offset(arm.q, j0=0.1, j1=-0.05)
    _run(host, lib_motion.movel(host, UrList(target), 1.2, 0.25, 0, 0))
    assert max(abs(a - b) for a, b in zip(arm.q, target, strict=True)) < 1e-6


def test_a_movej_interrupted_by_a_protective_stop_resumes_to_its_target() -> None:
    host = _host()
    arm = host.arm
    target = _offset(arm.q, j0=1.0)
    gen = lib_motion.movej(host, target, 1.4, 1.05, 0, 0)
    for _ in range(200):
        next(gen)
        arm.step(DT)
    lib_motion.protective_stop(host)
    assert arm.safety_mode is SafetyMode.PROTECTIVE_STOP
    for _ in range(round(UNLOCK_WAIT_S / DT) + 1):  # the controller does not step a paused program
        arm.step(DT)
    assert arm.qd == [0.0] * 6
    assert arm.unlock_protective_stop() is None, "at rest and 5 s after the stop"
    assert arm.resume_program() is None
    _run(host, gen)
    assert max(abs(a - b) for a, b in zip(arm.q, target, strict=True)) < 1e-3


def test_set_pos_puts_the_arm_there_at_once() -> None:
    host = _host()
    arm = host.arm
    target = _offset(arm.q, j5=1.0)
    lib_motion.set_pos(host, target)
    assert arm.q == target
    arm.step(DT)
    assert arm.q == target
    assert arm.qd == [0.0] * 6


def test_bad_arguments_are_runtime_errors() -> None:
    host = _host()
    with pytest.raises(ScriptRuntimeError, match="movej"):
        _run(host, lib_motion.movej(host, [0.0] * 5, 1.4, 1.05, 0, 0))
    with pytest.raises(ScriptRuntimeError, match="speedj"):
        _run(host, lib_motion.speedj(host, [0.0] * 6, -1.0, 0))
    with pytest.raises(ScriptRuntimeError, match="stopj"):
        _run(host, lib_motion.stopj(host, "fast"))
    with pytest.raises(ScriptRuntimeError, match="movel"):
        _run(host, lib_motion.movel(host, UrPose([5.0, 0, 0, 0, 0]), 1.2, 0.25, 0, 0))
    # an unreachable pose is no bad argument: a protective stop, in which the movel waits
    gen = lib_motion.movel(host, UrPose([5.0, 0, 0, 0, 0, 0]), 1.2, 0.25, 0, 0)
    next(gen)
    assert host.arm.safety_mode is SafetyMode.PROTECTIVE_STOP


def test_movec_keeps_the_tcp_on_the_circle_through_the_three_points() -> None:
    host = _host()
    arm = host.arm
    start = lib_state.get_actual_tcp_pose(host)
    via = UrPose([start[0] + 0.1, start[1] + 0.1, start[2], *start[3:]])
    goal = UrPose([start[0] + 0.2, start[1], start[2], *start[3:]])
    center = [start[0] + 0.1, start[1], start[2]]
    gen = lib_motion.movec(host, via, goal, 1.2, 0.25, 0, 0)
    worst = 0.0
    passed_via = False
    for _ in range(LIMIT):
        try:
            next(gen)
        except StopIteration:
            break
        arm.step(DT)
        p = lib_state.get_actual_tcp_pose(host)
        worst = max(worst, abs(math.dist(p[:3], center) - 0.1))
        passed_via = passed_via or math.dist(p[:3], via[:3]) < 1e-3
    end = lib_state.get_actual_tcp_pose(host)
    assert worst < 1e-6
    assert passed_via
    assert math.dist(end[:3], goal[:3]) < 1e-6
    with pytest.raises(ScriptRuntimeError, match="one line"):
        _run(
            host,
            lib_motion.movec(
                host,
                UrPose([*end[:2], end[2] + 0.1, *end[3:]]),
                UrPose([*end[:2], end[2] + 0.2, *end[3:]]),
                1.2,
                0.25,
                0,
                0,
            ),
        )


def test_a_servoj_beyond_the_speed_limit_commands_only_what_the_joints_can_do() -> None:
    """Servoj targets 15 rad/s apart (gain 2000 / lookahead 0.03 to pull hard): target speeds within the
    limit, and stopj stops within the stopping distance of the limit speed (reproduction: servoj
    0.03 rad apart, then stopj(4))."""
    host = _host()
    arm = host.arm
    limit = arm.max_velocity[0]
    target = list(arm.q)
    for _ in range(30):
        target = _offset(target, j0=0.03)
        _run(host, lib_motion.servoj(host, target, 0, 0, DT, 0.03, 2000))
        assert abs(lib_state.get_target_joint_speeds(host)[0]) <= limit + 1e-9
    assert arm.qd[0] == pytest.approx(limit)
    at = arm.q[0]
    stopping = limit / 4.0
    cycles = _run(host, lib_motion.stopj(host, 4.0))
    assert cycles <= round(stopping / DT) + 1
    assert arm.q[0] - at <= limit * stopping / 2 + 2 * limit * DT


def test_servoj_refuses_a_lookahead_or_gain_outside_the_controllers_ranges() -> None:
    host = _host()
    target = list(host.arm.q)
    with pytest.raises(ScriptRuntimeError, match=r"lookahead_time 0\.01 is outside"):
        _run(host, lib_motion.servoj(host, target, 0, 0, DT, 0.01, 300))
    with pytest.raises(ScriptRuntimeError, match="gain 5000"):
        _run(host, lib_motion.servoj(host, target, 0, 0, DT, 0.1, 5000))
