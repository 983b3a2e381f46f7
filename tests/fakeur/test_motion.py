"""The fake arm's joint motions (fakeur/joint_motion.py) and the pause's time scaling (playback.py)."""

from __future__ import annotations

import itertools
import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from urdaemon.fakeur.joint_motion import (
    JointMove,
    LinearStop,
    ServoFilter,
    SpeedRamp,
    joint_move,
    leading_stop_time,
    profile,
)
from urdaemon.fakeur.playback import ScalingRamp

START = [0.0, -1.5, 1.5, -1.5, -1.5, 0.0]


def _samples(move: JointMove | SpeedRamp | LinearStop | ServoFilter, dt: float = 0.002) -> list[list[float]]:
    count = math.ceil(move.duration / dt)
    return [move.position(min(k * dt, move.duration)) for k in range(count + 1)]


def test_profile_trapezoid_and_triangle() -> None:
    shape = profile(1.0, velocity=1.0, acceleration=2.0)
    assert shape.duration == pytest.approx(1.0 / 1.0 + 1.0 / 2.0)
    assert shape.at(shape.duration) == (1.0, 0.0)
    assert shape.at(0.25) == pytest.approx((0.0625, 0.5))
    short = profile(0.01, velocity=1.0, acceleration=1.0)  # never reaches v
    assert short.peak == pytest.approx(0.1)
    assert short.duration == pytest.approx(0.2)
    timed = profile(1.0, velocity=1.0, acceleration=2.0, duration=3.0)
    assert timed.duration == pytest.approx(3.0)
    with pytest.raises(ValueError, match="a > 0"):
        profile(1.0, velocity=0.0, acceleration=1.0)


@given(
    st.lists(st.floats(-2.0, 2.0), min_size=6, max_size=6),
    st.floats(0.1, 3.0),
    st.floats(0.2, 5.0),
)
def test_joint_move_arrives_together_within_v_a_and_the_joint_limits(
    delta: list[float], velocity: float, acceleration: float
) -> None:
    target = [a + d for a, d in zip(START, delta, strict=True)]
    limits = [2.0, 2.0, 3.0, 3.0, 3.0, 3.0]
    move = joint_move(START, target, velocity=velocity, acceleration=acceleration, max_velocity=limits)
    assert move.position(move.duration) == pytest.approx(target, abs=1e-12)
    assert move.velocity(move.duration) == pytest.approx([0.0] * 6, abs=1e-12)
    for k in range(50):
        qd = move.velocity(move.duration * k / 50)
        assert max(abs(v) for v in qd) <= velocity + 1e-9
        assert all(abs(v) <= limit + 1e-9 for v, limit in zip(qd, limits, strict=True))


def test_a_blended_joint_move_starts_at_the_given_velocity_and_stays_within_a() -> None:
    v0 = [0.8, -0.3, 0.0, 0.0, 0.0, 0.0]
    target = [0.5, -1.0, 1.5, -1.5, -1.5, 0.0]
    move = joint_move(START, target, velocity=1.0, acceleration=1.4, start_velocity=v0)
    assert move.velocity(0.0) == pytest.approx(v0, abs=1e-12)
    assert move.position(move.duration) == pytest.approx(target, abs=1e-12)
    dt = 0.001
    speeds = [move.velocity(k * dt) for k in range(int(move.duration / dt))]
    worst = max(
        max(abs(b - a) for a, b in zip(s, t, strict=True)) / dt for s, t in itertools.pairwise(speeds)
    )
    assert worst <= 2 * 1.4 + 1e-6, "the fade adds at most a to the move's own acceleration"


def test_speed_ramp_reaches_the_speed_with_the_leading_joint_at_a() -> None:
    ramp = SpeedRamp(START, [0.0] * 6, [1.0, -0.5, 0, 0, 0, 0], 2.0, 0.0)
    assert ramp.duration == pytest.approx(0.5)
    assert ramp.velocity(0.25) == pytest.approx([0.5, -0.25, 0, 0, 0, 0])
    assert ramp.position(0.5)[0] == pytest.approx(0.25)
    assert ramp.position(1.0)[0] == pytest.approx(0.25 + 0.5)


def test_linear_stop() -> None:
    stop = LinearStop(START, [1.0, 0.5, 0, 0, 0, 0], leading_stop_time([1.0, 0.5], 4.0))
    assert stop.duration == pytest.approx(0.25)
    assert stop.velocity(stop.duration) == [0.0] * 6
    assert stop.position(stop.duration)[0] == pytest.approx(0.125)
    assert stop.position(stop.duration)[1] == pytest.approx(START[1] + 0.0625)
    assert LinearStop(START, [0.0] * 6, 1.0).duration == 0.0


SERVO_CASES = [(300.0, 0.1), (2000.0, 0.03), (100.0, 0.03), (100.0, 0.2), (1000.0, 0.2)]
"""(gain, lookahead_time): under-damped (ζ 0.87, 0.67, 0.15), critically damped (ζ 1) and over-damped."""


def _damping(gain: float, lookahead: float) -> float:
    return 0.5 * lookahead * math.sqrt(gain)


@pytest.mark.parametrize(("gain", "lookahead"), SERVO_CASES)
def test_servo_filter_step_response_overshoots_as_its_damping_says(gain: float, lookahead: float) -> None:
    """A step of 0.1 rad from rest: the peak overshoot is the second-order system's exp(-πζ/√(1-ζ²))
    (none from ζ = 1 on), and position and velocity follow q'' = gain·(q* − q − lookahead·q').
    On f5f0e26 servoj reached its target exactly (ServoRamp, no gain or lookahead): no overshoot."""
    zeta = _damping(gain, lookahead)
    target = [0.1, *START[1:]]
    servo = ServoFilter(list(START), [0.0] * 6, target, 12.0, gain, lookahead)
    samples = [servo.position(k * 1e-4)[0] for k in range(30001)]
    overshoot = (max(samples) - 0.1) / 0.1
    expected = math.exp(-math.pi * zeta / math.sqrt(1 - zeta * zeta)) if zeta < 1 else 0.0
    assert overshoot == pytest.approx(expected, abs=2e-3)
    assert servo.position(12.0)[0] == pytest.approx(0.1, abs=1e-6)
    assert servo.position(12.0)[1:] == START[1:]  # joints at their setpoint stay there
    h = 1e-6
    for t in (0.01, 0.05, 0.2):
        q, qd = servo.position(t)[0], servo.velocity(t)[0]
        assert qd == pytest.approx((servo.position(t + h)[0] - servo.position(t - h)[0]) / (2 * h), rel=1e-5)
        qdd = (servo.velocity(t + h)[0] - servo.velocity(t - h)[0]) / (2 * h)
        assert qdd == pytest.approx(gain * (0.1 - q - lookahead * qd), rel=1e-4, abs=1e-6)


@pytest.mark.parametrize(("gain", "lookahead"), SERVO_CASES)
def test_servo_filter_lags_a_moving_setpoint_by_lookahead_times_speed(gain: float, lookahead: float) -> None:
    """A setpoint moving at 0.5 rad/s, one servoj of 2 ms per step from the last filter state (as the
    controller chains them): once settled the joint is lookahead × 0.5 rad behind (within the half
    step the held setpoint adds). On f5f0e26 the joint was on the setpoint at the end of every step."""
    speed, dt = 0.5, 0.002
    q, qd = list(START), [0.0] * 6
    lags = []
    for k in range(1, 5001):
        setpoint = [START[0] + speed * k * dt, *START[1:]]
        servo = ServoFilter(q, qd, setpoint, dt, gain, lookahead)
        q, qd = servo.position(dt), servo.velocity(dt)
        lags.append(setpoint[0] - q[0])
    assert lags[-1] == pytest.approx(lookahead * speed, abs=speed * dt)
    assert max(lags[-100:]) - min(lags[-100:]) < 1e-7  # steady
    assert qd[0] == pytest.approx(speed, rel=1e-3)


def _settled(ramp: ScalingRamp) -> bool:
    """``ramp.settled``, read through a call so that the type checker does not pin it."""
    return ramp.settled


def test_scaling_ramp_takes_the_time_the_fastest_joint_needs_to_stop_at_its_share() -> None:
    ramp = ScalingRamp()
    assert ramp.scale == 1.0
    assert _settled(ramp)
    # joint 1 at 1 rad/s stopping at half of 5 rad/s^2: 0.4 s; joint 0 needs only 0.2 s
    ramp.ramp_to(0.0, [0.5, -1.0, 0, 0, 0, 0], [5.0] * 6, 0.5, 0.002)
    assert not _settled(ramp)
    scales = [ramp.step(0.002) for _ in range(200)]
    assert scales[0] == pytest.approx(1.0 - 0.002 / 0.4)
    assert all(b < a for a, b in itertools.pairwise(scales))
    assert scales[-1] == 0.0
    assert _settled(ramp)
    assert ramp.step(0.002) == 0.0
    ramp.ramp_to(1.0, [0.0, 1.0, 0, 0, 0, 0], [5.0] * 6, 0.5, 0.002)
    assert [ramp.step(0.002) for _ in range(200)][-1] == 1.0


def test_scaling_ramp_within_one_cycle_happens_at_once() -> None:
    ramp = ScalingRamp()
    ramp.ramp_to(0.0, [0.001] + [0.0] * 5, [5.0] * 6, 0.5, 0.002)
    assert ramp.scale == 0.0
    assert _settled(ramp)
    ramp.ramp_to(1.0, [0.0] * 6, [5.0] * 6, 0.5, 0.002)
    assert ramp.scale == 1.0
    assert _settled(ramp)
