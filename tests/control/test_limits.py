"""Joint mapping, validation helpers and the braking-distance bound."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from ruckig import ControlInterface, InputParameter, Ruckig, Synchronization, Trajectory

from urdaemon.control import check_finite, check_positions_within, check_velocities_within, reorder
from urdaemon.control.limits import (
    BRAKE_DOWN,
    BRAKE_UP,
    braking_needed,
    check_accelerations_within,
    check_scale,
    joint_permutation,
    stopping_distance,
)
from urdaemon.errors import GoalRejected

from .sim import THREE_LIMITS


def test_reorder_maps_client_order_onto_controller_order() -> None:
    assert reorder(["c", "a", "b"], [3.0, 1.0, 2.0], ("a", "b", "c")) == (1.0, 2.0, 3.0)
    assert joint_permutation(("b", "c", "a"), ("a", "b", "c")) == (2, 0, 1)


def test_reorder_rejects_unknown_joint_by_name() -> None:
    with pytest.raises(GoalRejected, match="unknown joint") as info:
        reorder(["a", "b", "wrist_9"], [0.0, 0.0, 0.0], ("a", "b", "c"))
    assert "'wrist_9'" in info.value.reason


def test_reorder_rejects_missing_joint_by_name() -> None:
    with pytest.raises(GoalRejected, match="missing joint") as info:
        reorder(["a", "b"], [0.0, 0.0], ("a", "b", "c"))
    assert "'c'" in info.value.reason


def test_reorder_rejects_duplicates_by_name() -> None:
    with pytest.raises(GoalRejected, match="listed twice") as info:
        reorder(["a", "a", "b"], [0.0, 0.0, 0.0], ("a", "b", "c"))
    assert "'a'" in info.value.reason


def test_reorder_rejects_wrong_length() -> None:
    with pytest.raises(GoalRejected, match="has 2 values for 3 joint names"):
        reorder(["a", "b", "c"], [0.0, 0.0], ("a", "b", "c"), "positions")


def test_check_finite_names_joint() -> None:
    with pytest.raises(GoalRejected, match=r"positions: b is nan"):
        check_finite("positions", [0.0, math.nan, 0.0], ("a", "b", "c"))
    with pytest.raises(GoalRejected, match=r"index 2 is inf"):
        check_finite("velocities", [0.0, 0.0, math.inf])
    check_finite("ok", [0.0, 1.0, -1.0], ("a", "b", "c"))


def test_position_velocity_acceleration_checks_name_joint_value_and_limit() -> None:
    with pytest.raises(GoalRejected) as info:
        check_positions_within(THREE_LIMITS, [0.0, 0.0, 0.75], "target")
    assert info.value.reason == "target: c position 0.75 is outside its limits [-0.5, 0.5]"
    with pytest.raises(GoalRejected) as info:
        check_velocities_within(THREE_LIMITS, [0.0, -1.6, 0.0], "point 1")
    assert "b velocity -1.6 exceeds its limit 1.5" in info.value.reason
    with pytest.raises(GoalRejected) as info:
        check_accelerations_within(THREE_LIMITS, [6.0, 0.0, 0.0], "point 0")
    assert "a acceleration 6 exceeds its limit 5" in info.value.reason
    check_positions_within(THREE_LIMITS, [1.0, -2.0, 0.5], "edges are inside")


@pytest.mark.parametrize("value", [0.0, -0.1, 1.01, math.nan, math.inf])
def test_check_scale_rejects_outside_unit_interval(value: float) -> None:
    with pytest.raises(GoalRejected, match="velocity_scale must be in"):
        check_scale("velocity_scale", value)


def _ruckig_stop_distance(v: float, a: float, amax: float, jmax: float) -> float:
    inp = InputParameter(1)
    inp.control_interface = ControlInterface.Velocity
    inp.synchronization = Synchronization.No
    inp.current_position = [0.0]
    inp.current_velocity = [v]
    inp.current_acceleration = [a]
    inp.target_velocity = [0.0]
    inp.max_velocity = [10.0]
    inp.max_acceleration = [amax]
    inp.max_jerk = [jmax]
    traj = Trajectory(1)
    Ruckig(1).calculate(inp, traj)
    return float(traj.position_extrema[0].max)


@settings(max_examples=200, deadline=None, derandomize=True)
@given(
    v=st.floats(0.0, 3.0),
    a=st.floats(-5.0, 5.0),
    amax=st.floats(1.0, 10.0),
    jmax=st.floats(10.0, 200.0),
)
def test_stopping_distance_bounds_ruckigs_stop(v: float, a: float, amax: float, jmax: float) -> None:
    a = max(-amax, min(amax, a))
    assert stopping_distance(v, a, amax, jmax) >= _ruckig_stop_distance(v, a, amax, jmax) - 1e-9


def test_stopping_distance_closed_forms() -> None:
    # Reaching max deceleration: v·(v/a + a/j)/2 = 2·(0.4 + 0.1)/2.
    assert stopping_distance(2.0, 0.0, 5.0, 50.0) == pytest.approx(0.5)
    # Triangular deceleration: v·sqrt(v/j) = 0.1·sqrt(0.002).
    assert stopping_distance(0.1, 0.0, 5.0, 50.0) == pytest.approx(0.1 * math.sqrt(0.002))
    assert stopping_distance(0.0, 0.0, 5.0, 50.0) == 0.0


def test_braking_needed_directions() -> None:
    dt = 0.002
    assert braking_needed(0.0, 0.0, 0.0, -1.0, 1.0, 5.0, 50.0, dt) == 0
    assert braking_needed(0.5, 2.0, 0.0, -1.0, 1.0, 5.0, 50.0, dt) == BRAKE_UP
    assert braking_needed(-0.5, -2.0, 0.0, -1.0, 1.0, 5.0, 50.0, dt) == BRAKE_DOWN
    # At rest right at a limit only motion beyond it is blocked.
    assert braking_needed(1.0, 0.0, 0.0, -1.0, 1.0, 5.0, 50.0, dt) == BRAKE_UP
    assert braking_needed(0.0, 0.0, 0.0, -1e-7, 1e-7, 5.0, 50.0, dt) == BRAKE_UP | BRAKE_DOWN
