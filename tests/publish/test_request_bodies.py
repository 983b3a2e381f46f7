"""Each request a client sends, built by its encoder next to its decoder: decoding what the encoder
gives returns the message it was made from (``decode(encode(m)) == m``), for every message the
encoder can express (issue 31: the client builds bodies from the same message types).

A message ``m`` is drawn as the daemon decodes it; ``*_request(m)`` is the request a client sends
for it (tolerances and configuration as the fields a program gives); its body goes on the wire as
the client's session encodes it (``encode_body``).
"""

from __future__ import annotations

from typing import Any

from hypothesis import given, settings
from hypothesis import strategies as st

from tests.helpers import Stepped
from urdaemon.client.session import encode_body
from urdaemon.control.goal_types import TrajectoryPoint
from urdaemon.control.intake import MAX_JOINT_TOLERANCE
from urdaemon.control.trajectory import MAX_GOAL_TIME_S
from urdaemon.model import HOLDER_MAX_CHARS
from urdaemon.publish.cell_goal import (
    CELL_GOAL_POLICIES,
    CellGoalDecoder,
    CellGoalRequest,
    cell_goal_body,
    decode_lease_tokens,
    lease_tokens_attachment,
)
from urdaemon.publish.envelope import message_body
from urdaemon.publish.fields import MAX_POSE_M, POSE_FRAMES, ToleranceMessage
from urdaemon.publish.goal_cancel import cancel_body, decode_cancel, decode_cell_cancel
from urdaemon.publish.lease_request import LeaseRequest, lease_body, parse_request
from urdaemon.publish.linear_goal import (
    LINEAR_FIELDS,
    LINEAR_LIMITS,
    LinearGoalMessage,
    LinearGoalRequest,
    decode_linear_goal,
    linear_goal_body,
)
from urdaemon.publish.move_goal import (
    CONFIGURATIONS,
    MOVE_FIELDS,
    MoveGoalMessage,
    MoveGoalRequest,
    decode_move_goal,
    move_goal_body,
)
from urdaemon.publish.stream_commands import decode_freedrive, freedrive_body
from urdaemon.publish.trajectory_goal import (
    TRAJECTORY_FIELDS,
    TrajectoryGoalMessage,
    TrajectoryGoalRequest,
    trajectory_goal_body,
)
from urdaemon.publish.trajectory_json import decode_trajectory_goal

EXAMPLES = settings(max_examples=60, deadline=None)

# ---- what a decoder returns -----------------------------------------------------------------------

finite = st.floats(-1e6, 1e6, allow_nan=False)
joint_values = st.lists(finite, min_size=1, max_size=8).map(tuple)
joint_names = st.none() | st.lists(
    st.text(st.characters(codec="ascii", categories=["L", "N"]), min_size=1, max_size=12), max_size=8
).map(tuple)
tolerance = st.floats(1e-6, MAX_JOINT_TOLERANCE)
tolerances = st.builds(
    ToleranceMessage,
    path=st.none() | tolerance | st.lists(tolerance, min_size=1, max_size=8).map(tuple),
    goal=st.none() | tolerance | st.lists(tolerance, min_size=1, max_size=8).map(tuple),
    goal_time=st.none() | st.floats(0.0, MAX_GOAL_TIME_S),
)
scale = st.floats(1e-6, 1.0)
duration = st.none() | st.floats(1e-6, MAX_GOAL_TIME_S)
coordinate = st.floats(-MAX_POSE_M, MAX_POSE_M)
rotation = st.floats(-3.6, 3.6)  # 3.6 * sqrt(3) < 2 pi: every such rotation vector is accepted
pose = st.tuples(coordinate, coordinate, coordinate, rotation, rotation, rotation)
configuration = st.fixed_dictionaries(
    {}, optional={group: st.sampled_from(values) for group, values in CONFIGURATIONS.items()}
).map(lambda chosen: tuple((group, chosen[group]) for group in CONFIGURATIONS if group in chosen))

joint_moves = st.builds(
    MoveGoalMessage,
    joint_names=joint_names,
    positions=joint_values,
    duration=duration,
    velocity_scale=scale,
    acceleration_scale=scale,
    tolerances=tolerances,
    preempt=st.booleans(),
)
pose_moves = st.builds(
    MoveGoalMessage,
    joint_names=st.none(),
    positions=st.just(()),
    duration=duration,
    velocity_scale=scale,
    acceleration_scale=scale,
    tolerances=tolerances,
    preempt=st.booleans(),
    pose=pose,
    frame=st.sampled_from(POSE_FRAMES),
    configuration=configuration,
)
points = st.builds(
    TrajectoryPoint,
    positions=joint_values,
    time_from_start=finite,
    velocities=st.none() | joint_values,
    accelerations=st.none() | joint_values,
)
trajectories = st.builds(
    TrajectoryGoalMessage,
    joint_names=joint_names,
    points=st.lists(points, max_size=5).map(tuple),
    tolerances=tolerances,
    preempt=st.booleans(),
    passthrough=st.booleans(),
)


@st.composite
def linear_goals(draw: st.DrawFn) -> LinearGoalMessage:
    poses = tuple(draw(st.lists(pose, min_size=1, max_size=6)))
    radii = draw(st.lists(st.floats(0.0, MAX_POSE_M), min_size=len(poses) - 1, max_size=len(poses) - 1))
    limits = tuple((key, draw(st.floats(1e-6, 1e6))) for key in LINEAR_LIMITS if draw(st.booleans()))
    frame = draw(st.sampled_from(POSE_FRAMES))
    return LinearGoalMessage(poses, frame, tuple(radii), limits, draw(tolerances))


goal_ids = st.text(st.characters(codec="utf-8", exclude_categories=["C", "Z"]), min_size=1, max_size=200)
sessions = st.text(st.sampled_from("abcXYZ019_-"), min_size=16, max_size=64)
holders = st.text(st.characters(codec="ascii", categories=["L", "N"]), min_size=1, max_size=HOLDER_MAX_CHARS)
leases = (
    st.builds(LeaseRequest, st.sampled_from(("show", "release")))
    | st.builds(LeaseRequest, st.just("acquire"), sessions, holders)
    | st.builds(LeaseRequest, st.just("acquire"), sessions, holders, st.just(True), holders)
)

# ---- the request a client sends for it ------------------------------------------------------------


def tolerance_fields(message: ToleranceMessage) -> dict[str, Any] | None:
    """Tolerances as a program gives them (left out when none is given)."""
    given_fields = message_body(message)
    return given_fields or None


def move_request(m: MoveGoalMessage) -> MoveGoalRequest:
    pose_goal = m.pose is not None
    return MoveGoalRequest(
        positions=None if pose_goal else m.positions,
        pose=m.pose,
        frame=m.frame if pose_goal else None,
        velocity_scale=m.velocity_scale,
        acceleration_scale=m.acceleration_scale,
        preempt=m.preempt,
        configuration=dict(m.configuration) if m.configuration else None,
        duration=m.duration,
        joint_names=m.joint_names,
        tolerances=tolerance_fields(m.tolerances),
    )


def point_fields(point: TrajectoryPoint) -> dict[str, Any]:
    return message_body(point)


def trajectory_request(m: TrajectoryGoalMessage) -> TrajectoryGoalRequest:
    return TrajectoryGoalRequest(
        tuple(point_fields(p) for p in m.points),
        m.preempt,
        m.passthrough,
        m.joint_names,
        tolerance_fields(m.tolerances),
    )


def linear_request(m: LinearGoalMessage) -> LinearGoalRequest:
    return LinearGoalRequest(
        m.poses, m.frame, m.blend_radii, tolerances=tolerance_fields(m.tolerances), **dict(m.limits)
    )


# ---- decode(encode(m)) == m -----------------------------------------------------------------------


@EXAMPLES
@given(joint_moves | pose_moves)
def test_a_move_goal_decodes_to_what_it_was_made_from(m: MoveGoalMessage) -> None:
    assert decode_move_goal(encode_body(move_goal_body(move_request(m)))) == m


@EXAMPLES
@given(trajectories)
def test_a_trajectory_goal_decodes_to_what_it_was_made_from(m: TrajectoryGoalMessage) -> None:
    assert decode_trajectory_goal(encode_body(trajectory_goal_body(trajectory_request(m)))) == m


@EXAMPLES
@given(linear_goals())
def test_a_linear_goal_decodes_to_what_it_was_made_from(m: LinearGoalMessage) -> None:
    assert decode_linear_goal(encode_body(linear_goal_body(linear_request(m)))) == m


@EXAMPLES
@given(st.none() | goal_ids)
def test_a_cancel_decodes_to_its_goal_id(goal_id: str | None) -> None:
    assert decode_cancel(encode_body(cancel_body(goal_id))) == goal_id
    if goal_id is not None:
        assert decode_cell_cancel(encode_body(cancel_body(goal_id))) == goal_id


@given(st.booleans())
def test_a_freedrive_command_decodes_to_its_state(active: bool) -> None:
    assert decode_freedrive(encode_body(freedrive_body(active))) is active


@EXAMPLES
@given(leases)
def test_a_lease_request_decodes_to_what_it_was_made_from(request: LeaseRequest) -> None:
    assert parse_request(encode_body(lease_body(request))) == request


@EXAMPLES
@given(
    st.dictionaries(holders, trajectories, min_size=1, max_size=3),
    st.sampled_from(CELL_GOAL_POLICIES),
)
def test_a_cell_goal_splits_into_each_robots_goal(
    parts: dict[str, TrajectoryGoalMessage], on_abort: str
) -> None:
    robots: dict[str, TrajectoryGoalRequest | dict[str, Any]] = {
        name: trajectory_request(m) for name, m in parts.items()
    }
    decoder = CellGoalDecoder(encode_body(cell_goal_body(CellGoalRequest(robots, on_abort))))
    stepped = Stepped(decoder.steps())
    while stepped.step(1000):
        pass
    split = stepped.result()
    assert split.on_abort == on_abort
    assert {name: decode_trajectory_goal(bytes(body)) for name, body in split.robots.items()} == parts


@EXAMPLES
@given(st.dictionaries(holders, st.text(st.characters(codec="ascii"), max_size=40), max_size=4))
def test_the_lease_tokens_attachment_decodes_to_each_robots_token(tokens: dict[str, str]) -> None:
    decoded = decode_lease_tokens(lease_tokens_attachment(tokens))
    assert decoded == {name: token.encode() for name, token in tokens.items()}


def test_each_request_type_names_exactly_the_fields_its_decoder_takes() -> None:
    assert {
        "joint_names",
        "positions",
        "pose",
        "frame",
        "configuration",
        "duration",
        "velocity_scale",
        "acceleration_scale",
        "tolerances",
        "preempt",
    } == MOVE_FIELDS
    assert {"joint_names", "points", "tolerances", "preempt", "passthrough"} == TRAJECTORY_FIELDS
    assert {"poses", "frame", "blend_radii", "tolerances", *LINEAR_LIMITS} == LINEAR_FIELDS
