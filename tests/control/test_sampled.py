"""SampledTrajectory: joint samples every cycle, cubic Hermite in between, freed in chunks."""

from __future__ import annotations

import math
import sys

import pytest

from urdaemon.control.planned import plan_seed
from urdaemon.control.sampled import CHUNK_SAMPLES, SampledTrajectory, SampleWriter

PERIOD = 0.002


def _curve(t: float) -> tuple[float, float, float]:
    """A smooth two-joint motion's first joint (position, velocity, acceleration) at ``t``."""
    return math.sin(3.0 * t), 3.0 * math.cos(3.0 * t), -9.0 * math.sin(3.0 * t)


def _plan(count: int) -> SampledTrajectory:
    writer = SampleWriter(2, PERIOD)
    for n in range(count):
        p = _curve(n * PERIOD)[0]
        writer.append((p, 0.5 * p))
    return writer.finish()


def test_samples_are_returned_exactly_at_their_times() -> None:
    plan = _plan(300)
    pos, vel, acc = [0.0, 0.0], [0.0, 0.0], [0.0, 0.0]
    for n in (0, 1, 7, 150, 298, 299):
        plan.sample(n * PERIOD, pos, vel, acc)
        assert pos == list(plan.positions(n))
    assert plan.duration == pytest.approx(299 * PERIOD)
    assert plan.final_positions == plan.positions(299)
    assert plan.final_velocities == (0.0, 0.0)


def test_first_and_last_samples_are_at_rest_and_times_clamp() -> None:
    plan = _plan(100)
    pos, vel, acc = [9.0, 9.0], [9.0, 9.0], [9.0, 9.0]
    plan.sample(-1.0, pos, vel, acc)
    assert pos == list(plan.positions(0))
    assert vel == [0.0, 0.0]
    plan.sample(plan.duration + 5.0, pos, vel, acc)
    assert pos == list(plan.final_positions)
    assert vel == [0.0, 0.0]
    assert acc == [0.0, 0.0]


def test_between_samples_the_hermite_interpolation_follows_the_curve() -> None:
    """Velocities are central differences, so positions between samples are O(h^3) accurate, the
    velocity and acceleration of the polynomial close to the curve's."""
    plan = _plan(1000)
    pos, vel, acc = [0.0, 0.0], [0.0, 0.0], [0.0, 0.0]
    for n in range(5, 990, 37):
        for f in (0.25, 0.5, 0.9):
            t = (n + f) * PERIOD
            p, v, a = _curve(t)
            plan.sample(t, pos, vel, acc)
            assert pos[0] == pytest.approx(p, abs=1e-8)
            assert pos[1] == pytest.approx(0.5 * p, abs=1e-8)
            assert vel[0] == pytest.approx(v, abs=1e-4)
            assert acc[0] == pytest.approx(a, abs=0.05)


def test_velocity_and_acceleration_are_the_derivatives_of_the_positions() -> None:
    plan = _plan(400)
    pos, vel, acc = [0.0, 0.0], [0.0, 0.0], [0.0, 0.0]
    eps = 1e-7
    for t in (0.0301, 0.1234, 0.5555, 0.7007):  # inside intervals: acceleration jumps at a sample
        plan.sample(t - eps, pos, vel, acc)
        p0, v0 = pos[0], vel[0]
        plan.sample(t + eps, pos, vel, acc)
        p1, v1 = pos[0], vel[0]
        plan.sample(t, pos, vel, acc)
        assert (p1 - p0) / (2 * eps) == pytest.approx(vel[0], rel=1e-5, abs=1e-6)
        assert (v1 - v0) / (2 * eps) == pytest.approx(acc[0], rel=1e-3, abs=1e-3)


def test_a_single_sample_is_a_plan_of_no_time() -> None:
    writer = SampleWriter(3, PERIOD)
    writer.append((1.0, 2.0, 3.0))
    plan = writer.finish(slowed_by=1.0)
    pos, vel, acc = [0.0] * 3, [0.0] * 3, [0.0] * 3
    plan.sample(0.0, pos, vel, acc)
    assert plan.duration == 0.0
    assert pos == [1.0, 2.0, 3.0]
    assert vel == [0.0] * 3
    assert plan.final_positions == (1.0, 2.0, 3.0)


def test_release_frees_the_chunks_a_few_at_a_time() -> None:
    plan = _plan(5 * CHUNK_SAMPLES + 3)
    assert plan.segment_count == 6
    assert plan.release(4) is True
    assert plan.segment_count == 2
    assert plan.release(4) is False
    assert plan.segment_count == 0


def test_sample_reads_across_a_chunk_boundary() -> None:
    plan = _plan(2 * CHUNK_SAMPLES + 10)
    pos, vel, acc = [0.0, 0.0], [0.0, 0.0], [0.0, 0.0]
    t = (CHUNK_SAMPLES - 0.5) * PERIOD
    plan.sample(t, pos, vel, acc)
    assert pos[0] == pytest.approx(_curve(t)[0], abs=1e-8)


def test_sample_allocates_nothing_that_stays() -> None:
    plan = _plan(3000)
    pos, vel, acc = [0.0, 0.0], [0.0, 0.0], [0.0, 0.0]
    for k in range(100):
        plan.sample(k * 0.00137, pos, vel, acc)
    before = sys.getallocatedblocks()
    for k in range(2000):
        plan.sample(k * 0.00291, pos, vel, acc)
    assert sys.getallocatedblocks() - before < 50


def test_a_plan_passes_the_controllers_start_check() -> None:
    """The controller's ``accept_planned`` checks a ready plan starts at rest where the robot is."""
    plan = _plan(200)
    start, _, _ = plan_seed(plan, list(plan.positions(0)), ("a", "b"))
    assert start == list(plan.positions(0))


def test_a_sampled_trajectory_needs_its_samples() -> None:
    with pytest.raises(ValueError, match="at least one sample"):
        SampledTrajectory([], 0, 6, PERIOD)
