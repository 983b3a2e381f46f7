"""Trajectory point codec (docs/protocols.md §4.4): frame layout, validation, both sides, fuzz and a pair."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.protocols.feeding import feed_all_ways
from urdaemon.errors import LocalProtocolError, RemoteProtocolError
from urdaemon.protocols import Side
from urdaemon.protocols._fixed import INT32_MAX, INT32_MIN, MULT
from urdaemon.protocols.reverse import ReverseConnection, TrajectoryAction, TrajectoryControl
from urdaemon.protocols.trajectory_point import (
    CIRCULAR_TYPES,
    FRAME_BYTES,
    JOINT_TARGET_TYPES,
    OPTIMOVE_TYPES,
    POSE_TARGET_TYPES,
    MotionPoint,
    MotionType,
    SplinePoint,
    TrajectoryPoint,
    TrajectoryPointConnection,
    TrajectoryResult,
    TrajectoryResultCode,
    TrajectoryResultMessage,
    UnknownTrajectoryPoint,
    decode_point,
    encode_point,
)

Q = (0.1, -1.2, 1.3, -0.4, 1.5, 0.6)
QD = (0.01, 0.02, 0.03, -0.04, -0.05, 0.0)
QDD = (1.0, 0.0, -1.0, 0.5, 0.0, 0.25)
VIA = (0.4, 0.1, 0.3, 0.0, 3.14, 0.0)
TARGET_POSE = (0.5, -0.1, 0.2, 0.0, 3.14, 0.0)


def _ints(values: tuple[float, ...]) -> list[int]:
    return [round(v * 1_000_000) for v in values]


def _frame(ints: list[int]) -> bytes:
    """An independent encoder for expected bytes: 21 big-endian int32."""
    assert len(ints) == 21
    return b"".join(i.to_bytes(4, "big", signed=True) for i in ints)


def _robot() -> TrajectoryPointConnection:
    return TrajectoryPointConnection(Side.ROBOT)


def _daemon() -> TrajectoryPointConnection:
    return TrajectoryPointConnection(Side.DAEMON)


def _sent(point: TrajectoryPoint) -> bytes:
    conn = _daemon()
    conn.send(point)
    return conn.data_to_send()


# -- frame layout (§4.4 table, built independently) -----------------------------------------------------


LAYOUTS = [
    (
        SplinePoint(Q, QD, None, 0.008),
        _frame([*_ints(Q), *_ints(QD), *[0] * 6, 8000, 1, 51]),
    ),
    (
        SplinePoint(Q, QD, QDD, 0.5),
        _frame([*_ints(Q), *_ints(QD), *_ints(QDD), 500_000, 2, 51]),
    ),
    (
        MotionPoint(MotionType.MOVEJ, Q, velocity=1.05, acceleration=1.4, blend_radius=0.05, duration=2.0),
        _frame([*_ints(Q), *[0] * 6, 1_050_000, 1_400_000, 0, 0, 0, 0, 2_000_000, 50_000, 0]),
    ),
    (
        MotionPoint(MotionType.MOVEL, TARGET_POSE, velocity=0.25, acceleration=1.2),
        _frame([*_ints(TARGET_POSE), *[0] * 6, 250_000, 1_200_000, 0, 0, 0, 0, 0, 0, 1]),
    ),
    (
        MotionPoint(MotionType.MOVEJ_POSE, TARGET_POSE, Q, velocity=1.0, acceleration=1.0),
        _frame([*_ints(TARGET_POSE), *_ints(Q), MULT, MULT, MULT, 0, 0, 0, 0, 0, 6]),
    ),
    (
        MotionPoint(MotionType.MOVEC, TARGET_POSE, VIA, 0.1, 0.2, 0.01, arc_mode=1),
        _frame([*_ints(TARGET_POSE), *_ints(VIA), 100_000, 200_000, MULT, 0, 0, 0, 0, 10_000, 3]),
    ),
    (
        MotionPoint(MotionType.OPTIMOVEJ, Q, velocity=0.3, acceleration=0.3),
        _frame([*_ints(Q), *[0] * 6, 300_000, 300_000, 0, 0, 0, 0, 0, 0, 4]),
    ),
]


@pytest.mark.parametrize(("point", "wire"), LAYOUTS)
def test_points_have_the_documented_layout(point: TrajectoryPoint, wire: bytes) -> None:
    assert len(wire) == FRAME_BYTES
    assert _sent(point) == wire
    assert encode_point(point) == wire


@pytest.mark.parametrize(("point", "wire"), LAYOUTS)
def test_points_decode_every_way_on_the_robot_side(point: TrajectoryPoint, wire: bytes) -> None:
    assert feed_all_ways(_robot, wire) == [point]


def test_motion_types_have_the_reference_values() -> None:
    assert {t.name: t.value for t in MotionType} == {
        "MOVEJ": 0,
        "MOVEL": 1,
        "MOVEP": 2,
        "MOVEC": 3,
        "OPTIMOVEJ": 4,
        "OPTIMOVEL": 5,
        "MOVEJ_POSE": 6,
        "MOVEL_JOINT": 7,
        "MOVEP_JOINT": 8,
        "MOVEC_JOINT": 9,
        "MOVEC_JOINT_POSE": 10,
        "MOVEC_POSE_JOINT": 11,
        "OPTIMOVEJ_POSE": 12,
        "OPTIMOVEL_JOINT": 13,
        "SPLINE": 51,
    }
    groups = (JOINT_TARGET_TYPES, POSE_TARGET_TYPES, CIRCULAR_TYPES)
    assert set().union(*groups) == set(MotionType) - {MotionType.SPLINE}
    assert sum(len(g) for g in groups) == len(MotionType) - 1


def test_positions_only_splines_are_cubic_with_zero_velocities() -> None:
    wire = _sent(SplinePoint(Q, None, None, 0.1))
    assert wire == _frame([*_ints(Q), *[0] * 12, 100_000, 1, 51])
    assert decode_point(wire) == SplinePoint(Q, (0.0,) * 6, None, 0.1)


def test_accelerations_without_velocities_are_quintic_with_zero_velocities() -> None:
    wire = _sent(SplinePoint(Q, None, QDD, 0.1))
    assert decode_point(wire) == SplinePoint(Q, (0.0,) * 6, QDD, 0.1)


def test_a_pose_target_without_q_near_leaves_the_second_block_zero() -> None:
    wire = _sent(MotionPoint(MotionType.OPTIMOVEJ_POSE, TARGET_POSE, None, 0.5, 0.5))
    assert wire[24:48] == bytes(24)
    assert wire[56:60] == bytes(4)


# -- what the daemon side refuses to send --------------------------------------------------------------


@pytest.mark.parametrize(
    "point",
    [
        SplinePoint((0, 0, 0, 0, 0), None, None, 0.1),
        SplinePoint(Q, (0, 0, 0), None, 0.1),
        SplinePoint(Q, QD, (math.nan,) * 6, 0.1),
        SplinePoint(Q, None, None, -0.001),
        SplinePoint(Q, None, None, 2147.5),
        SplinePoint(Q, None, None, math.inf),
        SplinePoint(None, None, None, 0.1),  # type: ignore[arg-type]
        SplinePoint((3000.0, 0, 0, 0, 0, 0), None, None, 0.1),
        MotionPoint(MotionType.SPLINE, Q),
        MotionPoint(99, Q),  # type: ignore[arg-type]
        MotionPoint(MotionType.MOVEJ, Q, velocity=-1.0),
        MotionPoint(MotionType.MOVEJ, Q, acceleration=-0.1),
        MotionPoint(MotionType.MOVEJ, Q, blend_radius=-0.01),
        MotionPoint(MotionType.MOVEJ, Q, velocity=math.nan),
        MotionPoint(MotionType.MOVEJ, Q, duration=-1.0),
        MotionPoint(MotionType.MOVEJ, Q, duration=2148.0),
        MotionPoint(MotionType.MOVEJ, Q, VIA),
        MotionPoint(MotionType.MOVEL_JOINT, Q, VIA),
        MotionPoint(MotionType.MOVEJ, Q, arc_mode=1),
        MotionPoint(MotionType.MOVEL, TARGET_POSE, arc_mode=1),
        MotionPoint(MotionType.MOVEC, TARGET_POSE),
        MotionPoint(MotionType.MOVEC, TARGET_POSE, VIA, arc_mode=2),
        MotionPoint(MotionType.MOVEC, TARGET_POSE, VIA, arc_mode=1.0),  # type: ignore[arg-type]
        MotionPoint(MotionType.OPTIMOVEJ, Q),  # default 1.05 is not a fraction
        MotionPoint(MotionType.OPTIMOVEL, TARGET_POSE, velocity=0.5, acceleration=0.0),
        MotionPoint(MotionType.MOVEJ, (0, 0, 0, 0, 0, 0, 0)),
        MotionPoint(MotionType.MOVEJ_POSE, TARGET_POSE, (0, 0)),
    ],
)
def test_invalid_points_are_local_protocol_errors(point: TrajectoryPoint) -> None:
    conn = _daemon()
    with pytest.raises(LocalProtocolError) as info:
        conn.send(point)
    assert info.value.protocol == "trajectory_point"
    assert conn.data_to_send() == b""


def test_each_side_sends_only_its_own_messages() -> None:
    with pytest.raises(LocalProtocolError):
        _daemon().send(TrajectoryResultMessage(TrajectoryResultCode.SUCCESS))
    with pytest.raises(LocalProtocolError):
        _robot().send(SplinePoint(Q, None, None, 0.1))
    with pytest.raises(LocalProtocolError):
        _robot().send(TrajectoryResultMessage(5))  # type: ignore[arg-type]
    with pytest.raises(LocalProtocolError):
        encode_point(TrajectoryResultMessage(TrajectoryResultCode.SUCCESS))  # type: ignore[arg-type]


# -- robot side decoding --------------------------------------------------------------------------------


def test_unknown_motion_and_spline_types_are_reported() -> None:
    ints = [*_ints(Q), *[0] * 12, 100_000, 0, 14]
    assert feed_all_ways(_robot, _frame(ints)) == [UnknownTrajectoryPoint(14, tuple(ints))]
    spline = [*_ints(Q), *[0] * 12, 100_000, 3, 51]
    assert decode_point(_frame(spline)) == UnknownTrajectoryPoint(51, tuple(spline))


def test_the_robot_side_reads_only_what_the_script_reads() -> None:
    # joint target: the second block and the flag are not read
    joint = _frame([*_ints(Q), *_ints(VIA), 0, 0, MULT, 9, 9, 9, 0, 0, 0])
    assert decode_point(joint) == MotionPoint(MotionType.MOVEJ, Q, None, 0.0, 0.0)
    # pose target with a zero flag: no q_near
    pose = _frame([*_ints(TARGET_POSE), *_ints(Q), 0, 0, 0, 0, 0, 0, 0, 0, 1])
    assert decode_point(pose) == MotionPoint(MotionType.MOVEL, TARGET_POSE, None, 0.0, 0.0)
    # any non-zero flag means q_near (the script tests it for truth)
    seeded = _frame([*_ints(TARGET_POSE), *_ints(Q), 0, 0, 3, 0, 0, 0, 0, 0, 6])
    assert decode_point(seeded) == MotionPoint(MotionType.MOVEJ_POSE, TARGET_POSE, Q, 0.0, 0.0)
    # cubic: the acceleration block is not read
    cubic = _frame([*_ints(Q), *_ints(QD), *_ints(QDD), 1, 1, 51])
    assert decode_point(cubic) == SplinePoint(Q, QD, None, 1e-6)


def test_values_are_reported_as_read_without_range_checks() -> None:
    odd = _frame([*_ints(Q), *[0] * 6, -5, -6, 0, 0, 0, 0, -7, -8, 0])
    assert decode_point(odd) == MotionPoint(MotionType.MOVEJ, Q, None, -5e-6, -6e-6, -8e-6, -7e-6)
    negative_time = _frame([*_ints(Q), *[0] * 12, -1_000_000, 1, 51])
    assert decode_point(negative_time) == SplinePoint(Q, (0.0,) * 6, None, -1.0)


def test_a_fractional_arc_mode_is_a_remote_protocol_error() -> None:
    wire = _frame([*_ints(TARGET_POSE), *_ints(VIA), 0, 0, 500_000, 0, 0, 0, 0, 0, 3])
    conn = _robot()
    conn.receive_data(_sent(SplinePoint(Q, None, None, 0.1)))
    with pytest.raises(RemoteProtocolError) as info:
        conn.receive_data(wire)
    assert info.value.protocol == "trajectory_point"
    assert info.value.offset == FRAME_BYTES
    with pytest.raises(RemoteProtocolError):
        conn.receive_data(b"")
    with pytest.raises(LocalProtocolError):
        conn.send(TrajectoryResultMessage(TrajectoryResultCode.FAILURE))


# -- daemon side: results -------------------------------------------------------------------------------


@pytest.mark.parametrize("code", list(TrajectoryResultCode))
def test_each_result_decodes_every_way(code: TrajectoryResultCode) -> None:
    wire = code.to_bytes(4, "big", signed=True)
    assert feed_all_ways(_daemon, wire) == [TrajectoryResult(code)]


def test_results_are_zero_one_two() -> None:
    assert [c.value for c in TrajectoryResultCode] == [0, 1, 2]


def test_several_results_in_one_chunk() -> None:
    wire = bytes.fromhex("00000000 00000001 00000002")
    assert feed_all_ways(_daemon, wire) == [
        TrajectoryResult(TrajectoryResultCode.SUCCESS),
        TrajectoryResult(TrajectoryResultCode.CANCELED),
        TrajectoryResult(TrajectoryResultCode.FAILURE),
    ]


@pytest.mark.parametrize("value", [-1, 3, 0x01000000, INT32_MIN, INT32_MAX])
def test_an_unknown_result_is_a_remote_protocol_error(value: int) -> None:
    conn = _daemon()
    assert conn.receive_data(bytes(4) + value.to_bytes(4, "big", signed=True)[:2]) == [
        TrajectoryResult(TrajectoryResultCode.SUCCESS)
    ]
    with pytest.raises(RemoteProtocolError) as info:
        conn.receive_data(value.to_bytes(4, "big", signed=True)[2:])
    assert info.value.offset == 4
    with pytest.raises(LocalProtocolError):
        conn.send(SplinePoint(Q, None, None, 0.1))


def test_eof_in_the_middle_of_a_result_is_an_error() -> None:
    conn = _daemon()
    conn.receive_data(b"\x00\x00")
    with pytest.raises(RemoteProtocolError):
        conn.receive_eof()


# -- hypothesis: round trips and fuzz -------------------------------------------------------------------

scaled = st.integers(INT32_MIN, INT32_MAX).map(lambda i: i / MULT)
vector6 = st.tuples(scaled, scaled, scaled, scaled, scaled, scaled)
durations = st.integers(0, 2_147_000_000).map(lambda i: i / MULT)
non_negative = st.integers(0, INT32_MAX).map(lambda i: i / MULT)
fractions = st.integers(1, MULT).map(lambda i: i / MULT)

splines = st.builds(SplinePoint, vector6, vector6, st.none() | vector6, durations)


@st.composite
def motions(draw: st.DrawFn) -> MotionPoint:
    kind = draw(st.sampled_from(sorted(set(MotionType) - {MotionType.SPLINE})))
    if kind in CIRCULAR_TYPES:
        second: tuple[float, ...] | None = draw(vector6)
    elif kind in POSE_TARGET_TYPES:
        second = draw(st.none() | vector6)
    else:
        second = None
    speeds = fractions if kind in OPTIMOVE_TYPES else non_negative
    return MotionPoint(
        kind,
        draw(vector6),
        second,
        draw(speeds),
        draw(speeds),
        draw(non_negative),
        draw(durations),
        draw(st.sampled_from([0, 1])) if kind in CIRCULAR_TYPES else 0,
    )


@given(st.lists(splines | motions(), min_size=1, max_size=5), st.data())
@settings(max_examples=300, deadline=None)
def test_every_point_round_trips_daemon_to_robot(points: list[TrajectoryPoint], data: st.DataObject) -> None:
    daemon, robot = _daemon(), _robot()
    for point in points:
        daemon.send(point)
    wire = daemon.data_to_send()
    assert len(wire) == FRAME_BYTES * len(points)
    cuts = sorted(data.draw(st.lists(st.integers(0, len(wire)), max_size=5)))
    events = []
    for start, end in zip([0, *cuts], [*cuts, len(wire)], strict=True):
        events += robot.receive_data(wire[start:end])
    assert events == points


@given(st.lists(st.sampled_from(TrajectoryResultCode), max_size=8))
@settings(max_examples=100, deadline=None)
def test_every_result_round_trips_robot_to_daemon(codes: list[TrajectoryResultCode]) -> None:
    robot, daemon = _robot(), _daemon()
    for code in codes:
        robot.send(TrajectoryResultMessage(code))
    assert daemon.receive_data(robot.data_to_send()) == [TrajectoryResult(c) for c in codes]


@given(st.binary(max_size=500), st.lists(st.integers(0, 500), max_size=6))
@settings(max_examples=300, deadline=None)
def test_any_bytes_give_events_or_a_remote_protocol_error(blob: bytes, cuts: list[int]) -> None:
    for side in (Side.ROBOT, Side.DAEMON):
        conn = TrajectoryPointConnection(side)
        failure: RemoteProtocolError | None = None
        try:
            for start, end in zip([0, *sorted(cuts)], [*sorted(cuts), len(blob)], strict=True):
                for event in conn.receive_data(blob[start:end]):
                    expected = TrajectoryResult if side is Side.DAEMON else (SplinePoint, MotionPoint)
                    assert isinstance(event, expected) or (
                        side is Side.ROBOT and isinstance(event, UnknownTrajectoryPoint)
                    )
            conn.receive_eof()
        except RemoteProtocolError as err:
            failure = err
        assert failure is None or failure.protocol == "trajectory_point"


# -- a finite trajectory, both parties in memory (reverse 50001 + trajectory 50003) ---------------------


def test_pair_a_finite_trajectory_from_start_to_success() -> None:
    reverse_d, reverse_r = ReverseConnection(Side.DAEMON), ReverseConnection(Side.ROBOT)
    points_d, points_r = _daemon(), _robot()
    path: list[TrajectoryPoint] = [
        SplinePoint((i / 10, 0, 0, 0, 0, 0), (0.1, 0, 0, 0, 0, 0), None, 0.1) for i in range(1, 4)
    ]
    path.append(SplinePoint((0.4, 0, 0, 0, 0, 0), (0.0,) * 6, (0.0,) * 6, 0.1))  # end at rest
    path.append(MotionPoint(MotionType.MOVEJ, (0, 0, 0, 0, 0, 0), duration=1.0))

    # START(n) on 50001 first, then the n points on 50003 (§4.4)
    reverse_d.send(TrajectoryControl(TrajectoryAction.START, len(path)))
    (start,) = reverse_r.receive_data(reverse_d.data_to_send())
    assert start == TrajectoryControl(TrajectoryAction.START, len(path))
    for point in path:
        points_d.send(point)
    received = points_r.receive_data(points_d.data_to_send())
    assert received == path

    # NOOPs keep the reverse read alive while the robot executes
    for _ in range(3):
        reverse_d.send(TrajectoryControl(TrajectoryAction.NOOP, timeout=0.01))
    assert (
        reverse_r.receive_data(reverse_d.data_to_send())
        == [TrajectoryControl(TrajectoryAction.NOOP, timeout=0.01)] * 3
    )

    points_r.send(TrajectoryResultMessage(TrajectoryResultCode.SUCCESS))
    assert points_d.receive_data(points_r.data_to_send()) == [TrajectoryResult(TrajectoryResultCode.SUCCESS)]
    assert points_d.receive_eof() == []
    assert points_r.receive_eof() == []
