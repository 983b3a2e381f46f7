"""The message codec: every decoder with good and bad input, and the encoders' JSON output."""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from typing import Any

import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from urdaemon.control.goal_types import GoalFeedback, GoalResult, GoalStatus, TrajectoryPoint
from urdaemon.errors import MessageError
from urdaemon.model import RobotState
from urdaemon.publish import envelope, service_requests
from urdaemon.publish.envelope import (
    MAX_MESSAGE_BYTES,
    SMALL_MESSAGE_BYTES,
    encode,
    encode_feedback,
    encode_result,
    state_time,
)
from urdaemon.publish.fields import ToleranceMessage
from urdaemon.publish.goal_cancel import decode_cancel
from urdaemon.publish.move_goal import MoveGoalMessage, decode_move_goal
from urdaemon.publish.service_requests import decode_set_io, decode_set_payload, decode_speed_slider
from urdaemon.publish.state_encoder import JointStateEncoder
from urdaemon.publish.stream_commands import StreamMessage, decode_stream_position, decode_stream_velocity
from urdaemon.publish.trajectory_goal import MAX_TRAJECTORY_POINTS, TrajectoryGoalMessage
from urdaemon.publish.trajectory_json import decode_trajectory_goal

Decoder = Callable[[bytes | None], object]

DECODERS: dict[str, tuple[Decoder, str]] = {
    "trajectory": (decode_trajectory_goal, "trajectory goal"),
    "move": (decode_move_goal, "move goal"),
    "cancel": (decode_cancel, "cancel"),
    "stream_position": (decode_stream_position, "joint_position command"),
    "stream_velocity": (decode_stream_velocity, "joint_velocity command"),
    "set_io": (decode_set_io, "set_io"),
    "set_payload": (decode_set_payload, "set_payload"),
    "speed_slider": (decode_speed_slider, "set_speed_slider"),
}
"""name → (decoder, the label its messages start with)."""

GOOD: dict[str, dict[str, Any]] = {
    "trajectory": {"points": [{"positions": [0.0, 1.0], "time_from_start": 1.0}]},
    "move": {"positions": [0.0, 1.0]},
    "cancel": {"goal_id": "g1"},
    "stream_position": {"positions": [0.0, 1.0]},
    "stream_velocity": {"velocities": [0.0, 1.0]},
    "set_io": {"kind": "digital", "pin": 0, "value": True},
    "set_payload": {"mass": 1.0},
    "speed_slider": {"fraction": 0.5},
}
"""A minimal valid message per decoder."""


def dumps(obj: object) -> bytes:
    return json.dumps(obj).encode()


def refused(decoder: Decoder, payload: bytes | None) -> str:
    """The message of the ``MessageError`` the decoder raises."""
    with pytest.raises(MessageError) as info:
        decoder(payload)
    return str(info.value)


# --- every decoder: the envelope ---


@pytest.mark.parametrize("name", list(DECODERS))
def test_minimal_good_message_decodes(name: str) -> None:
    decoder, _ = DECODERS[name]
    assert decoder(dumps(GOOD[name])) is not None
    assert decoder(dumps({"v": 1, **GOOD[name]})) == decoder(dumps(GOOD[name]))


@pytest.mark.parametrize("name", [n for n in DECODERS if n != "cancel"])
@pytest.mark.parametrize("payload", [b"", None])
def test_empty_message_is_refused(name: str, payload: bytes | None) -> None:
    decoder, what = DECODERS[name]
    assert refused(decoder, payload) == f"{what}: empty message; expected a JSON object"


@pytest.mark.parametrize("payload", [b"", None])
def test_empty_cancel_means_the_active_goal(payload: bytes | None) -> None:
    assert decode_cancel(payload) is None


@pytest.mark.parametrize("name", list(DECODERS))
@pytest.mark.parametrize("payload", [b"{", b"not json", b"{'a': 1}", b"\xff\xfe", b"{}x", b" "])
def test_not_json_is_refused(name: str, payload: bytes) -> None:
    decoder, what = DECODERS[name]
    assert refused(decoder, payload).startswith(f"{what}: not valid JSON: ")


@pytest.mark.parametrize("name", list(DECODERS))
@pytest.mark.parametrize(
    ("payload", "kind"),
    [
        (b"[]", "list"),
        (b'"x"', "str"),
        (b"1", "int"),
        (b"2.5", "float"),
        (b"null", "NoneType"),
        (b"true", "bool"),
    ],
)
def test_not_an_object_is_refused(name: str, payload: bytes, kind: str) -> None:
    decoder, what = DECODERS[name]
    assert refused(decoder, payload) == f"{what}: expected a JSON object, got {kind}"


@pytest.mark.parametrize("name", list(DECODERS))
@pytest.mark.parametrize("version", [2, 0, "1", None, [1], 1.5])
def test_wrong_version_is_refused(name: str, version: object) -> None:
    decoder, what = DECODERS[name]
    message = refused(decoder, dumps({"v": version, **GOOD[name]}))
    assert message == f"{what}: unsupported schema version {version!r}; this daemon speaks 1"


@pytest.mark.parametrize("name", list(DECODERS))
def test_boolean_version_is_refused(name: str) -> None:
    decoder, _ = DECODERS[name]
    assert "schema version" in refused(decoder, dumps({"v": True, **GOOD[name]}))


@pytest.mark.parametrize("name", list(DECODERS))
def test_unknown_fields_are_refused(name: str) -> None:
    decoder, what = DECODERS[name]
    message = refused(decoder, dumps({**GOOD[name], "zeta": 1, "alpha": 2}))
    assert message == f"{what}: unknown field(s) alpha, zeta"


@pytest.mark.parametrize("name", list(DECODERS))
def test_oversize_message_is_refused(name: str) -> None:
    """Every key has its limit, checked before decoding: 2 MiB for a trajectory, 16 KiB for the rest."""
    decoder, what = DECODERS[name]
    limit = MAX_MESSAGE_BYTES if name == "trajectory" else SMALL_MESSAGE_BYTES
    payload = dumps(GOOD[name])[:-1] + b" " * (limit + 1) + b"}"
    assert refused(decoder, payload) == (
        f"{what}: message of {len(payload)} bytes exceeds the limit of {limit} bytes"
    )


def test_message_of_exactly_the_limit_is_accepted() -> None:
    head = b'{"fraction": 0.25'
    payload = head + b" " * (SMALL_MESSAGE_BYTES - len(head) - 1) + b"}"
    assert len(payload) == SMALL_MESSAGE_BYTES
    assert decode_speed_slider(payload) == 0.25


def test_bytearray_and_memoryview_payloads() -> None:
    raw = b'{"fraction": 0.75}'
    assert envelope.decode_message(bytearray(raw), "x") == {"fraction": 0.75}
    assert envelope.decode_message(memoryview(raw), "x") == {"fraction": 0.75}


def test_message_error_is_a_value_error() -> None:
    with pytest.raises(ValueError, match="set_speed_slider"):
        decode_speed_slider(b"[]")


def test_deeply_nested_json_is_refused_not_crashed() -> None:
    payload = b'{"fraction": ' + b"[" * 8_000 + b"]" * 8_000 + b"}"  # within the size limit
    assert len(payload) <= SMALL_MESSAGE_BYTES
    assert refused(decode_speed_slider, payload).startswith("set_speed_slider: not valid JSON")


# --- field errors, per decoder ---

FIELD_ERRORS: list[tuple[str, object, str]] = [
    # trajectory goal
    ("trajectory", {}, "trajectory goal.points: expected a list of points"),
    ("trajectory", {"points": {"positions": [1]}}, "trajectory goal.points: expected a list of points"),
    ("trajectory", {"points": [1]}, "trajectory goal.points[0]: expected an object"),
    ("trajectory", {"points": [{"time_from_start": 1}]}, "trajectory goal.points[0].positions: missing"),
    ("trajectory", {"points": [{"positions": [1]}]}, "trajectory goal.points[0].time_from_start: missing"),
    (
        "trajectory",
        {"points": [{"positions": [1], "time_from_start": 1}, {"positions": [1], "time": 2}]},
        "trajectory goal.points[1]: unknown field(s) time",
    ),
    (
        "trajectory",
        {"points": [{"positions": [1, True], "time_from_start": 1}]},
        "trajectory goal.points[0].positions[1]: expected a number, got true",
    ),
    (
        "trajectory",
        {"points": [{"positions": [1], "time_from_start": "1"}]},
        'trajectory goal.points[0].time_from_start: expected a number, got "1"',
    ),
    (
        "trajectory",
        {"points": [{"positions": [1], "time_from_start": False}]},
        "trajectory goal.points[0].time_from_start: expected a number, got false",
    ),
    (
        "trajectory",
        {"points": [{"positions": 1, "time_from_start": 1}]},
        "trajectory goal.points[0].positions: expected a list of numbers, got int",
    ),
    (
        "trajectory",
        {"points": [{"positions": [1], "velocities": [None], "time_from_start": 1}]},
        "trajectory goal.points[0].velocities[0]: expected a number, got null",
    ),
    (
        "trajectory",
        {"points": [{"positions": [1], "accelerations": "x", "time_from_start": 1}]},
        "trajectory goal.points[0].accelerations: expected a list of numbers, got str",
    ),
    (
        "trajectory",
        {"points": [], "joint_names": ["a", 1]},
        "trajectory goal.joint_names: expected a list of joint name strings",
    ),
    (
        "trajectory",
        {"points": [], "joint_names": "a"},
        "trajectory goal.joint_names: expected a list of joint name strings",
    ),
    ("trajectory", {"points": [], "preempt": 1}, "trajectory goal.preempt: expected true or false"),
    ("trajectory", {"points": [], "preempt": None}, "trajectory goal.preempt: expected true or false"),
    (
        "trajectory",
        {"points": [], "tolerances": [0.1]},
        "trajectory goal.tolerances: expected an object with path, goal, goal_time",
    ),
    (
        "trajectory",
        {"points": [], "tolerances": {"paths": 0.1}},
        "trajectory goal.tolerances: unknown field(s) paths",
    ),
    (
        "trajectory",
        {"points": [], "tolerances": {"path": True}},
        "trajectory goal.tolerances.path: expected a number, got true",
    ),
    (
        "trajectory",
        {"points": [], "tolerances": {"goal": [0.1, "x"]}},
        'trajectory goal.tolerances.goal[1]: expected a number, got "x"',
    ),
    (
        "trajectory",
        {"points": [], "tolerances": {"goal_time": [1]}},
        "trajectory goal.tolerances.goal_time: expected a number, got [1]",
    ),
    # move goal
    ("move", {}, "move goal.positions: missing"),
    ("move", {"positions": None}, "move goal.positions: expected a list of numbers, got NoneType"),
    ("move", {"positions": [True]}, "move goal.positions[0]: expected a number, got true"),
    ("move", {"positions": [1], "duration": "2"}, 'move goal.duration: expected a number, got "2"'),
    ("move", {"positions": [1], "duration": True}, "move goal.duration: expected a number, got true"),
    (
        "move",
        {"positions": [1], "velocity_scale": False},
        "move goal.velocity_scale: expected a number, got false",
    ),
    (
        "move",
        {"positions": [1], "acceleration_scale": [1]},
        "move goal.acceleration_scale: expected a number, got [1]",
    ),
    (
        "move",
        {"positions": [1], "joint_names": [None]},
        "move goal.joint_names: expected a list of joint name strings",
    ),
    ("move", {"positions": [1], "preempt": "yes"}, "move goal.preempt: expected true or false"),
    (
        "move",
        {"positions": [1], "tolerances": {"goal_time": True}},
        "move goal.tolerances.goal_time: expected a number, got true",
    ),
    # cancel
    ("cancel", {"goal_id": 5}, "cancel.goal_id: expected a string"),
    ("cancel", {"goal_id": True}, "cancel.goal_id: expected a string"),
    ("cancel", {"goal_id": ["g"]}, "cancel.goal_id: expected a string"),
    # streaming
    ("stream_position", {}, "joint_position command.positions: missing"),
    (
        "stream_position",
        {"positions": [1], "velocities": [True]},
        "joint_position command.velocities[0]: expected a number, got true",
    ),
    (
        "stream_position",
        {"positions": "1"},
        "joint_position command.positions: expected a list of numbers, got str",
    ),
    (
        "stream_position",
        {"positions": [1], "joint_names": [1]},
        "joint_position command.joint_names: expected a list of joint name strings",
    ),
    ("stream_velocity", {}, "joint_velocity command.velocities: missing"),
    (
        "stream_velocity",
        {"velocities": [1], "positions": [1]},
        "joint_velocity command: unknown field(s) positions",
    ),
    (
        "stream_velocity",
        {"velocities": [False]},
        "joint_velocity command.velocities[0]: expected a number, got false",
    ),
    (
        "stream_velocity",
        {"velocities": {"a": 1}},
        "joint_velocity command.velocities: expected a list of numbers, got dict",
    ),
    # set_io
    ("set_io", {"pin": 0, "value": True}, "set_io.kind: expected one of digital, configurable, tool, analog"),
    (
        "set_io",
        {"kind": 1, "pin": 0, "value": True},
        "set_io.kind: expected one of digital, configurable, tool, analog",
    ),
    ("set_io", {"kind": "digital", "value": True}, "set_io.pin: expected an integer"),
    ("set_io", {"kind": "digital", "pin": True, "value": True}, "set_io.pin: expected an integer"),
    ("set_io", {"kind": "digital", "pin": 1.0, "value": True}, "set_io.pin: expected an integer"),
    ("set_io", {"kind": "digital", "pin": "1", "value": True}, "set_io.pin: expected an integer"),
    ("set_io", {"kind": "digital", "pin": 0}, "set_io.value: a digital output takes true or false, got null"),
    ("set_io", {"kind": "analog", "pin": 0, "value": True}, "set_io.value: expected a number, got true"),
    ("set_io", {"kind": "analog", "pin": 0, "value": "0.5"}, 'set_io.value: expected a number, got "0.5"'),
    # set_payload
    ("set_payload", {}, "set_payload.mass: expected a number, got null"),
    ("set_payload", {"mass": True}, "set_payload.mass: expected a number, got true"),
    ("set_payload", {"mass": -0.1}, "set_payload.mass: must be a finite number ≥ 0, got -0.1"),
    ("set_payload", {"mass": 1, "cog": [0, 0]}, "set_payload.cog: expected three finite numbers"),
    ("set_payload", {"mass": 1, "cog": [0, 0, 0, 0]}, "set_payload.cog: expected three finite numbers"),
    ("set_payload", {"mass": 1, "cog": [0, True, 0]}, "set_payload.cog[1]: expected a number, got true"),
    ("set_payload", {"mass": 1, "cog": None}, "set_payload.cog: expected a list of numbers, got NoneType"),
    ("set_payload", {"mass": 1, "cog": "0,0,0"}, "set_payload.cog: expected a list of numbers, got str"),
    # speed slider
    ("speed_slider", {}, "set_speed_slider.fraction: expected a number, got null"),
    ("speed_slider", {"fraction": True}, "set_speed_slider.fraction: expected a number, got true"),
    ("speed_slider", {"fraction": "0.5"}, 'set_speed_slider.fraction: expected a number, got "0.5"'),
    ("speed_slider", {"fraction": 1.5}, "set_speed_slider.fraction: must be within 0..1, got 1.5"),
    ("speed_slider", {"fraction": -0.01}, "set_speed_slider.fraction: must be within 0..1, got -0.01"),
]


@pytest.mark.parametrize(
    ("name", "message", "expected"),
    FIELD_ERRORS,
    ids=[f"{n}-{i}" for i, (n, _, _) in enumerate(FIELD_ERRORS)],
)
def test_field_errors_name_the_field(name: str, message: object, expected: str) -> None:
    decoder, _ = DECODERS[name]
    assert refused(decoder, dumps(message)) == expected


@pytest.mark.parametrize(
    ("name", "payload", "expected"),
    [
        ("set_payload", b'{"mass": NaN}', "set_payload.mass: must be a finite number ≥ 0, got nan"),
        ("set_payload", b'{"mass": Infinity}', "set_payload.mass: must be a finite number ≥ 0, got inf"),
        ("set_payload", b'{"mass": 1, "cog": [0, NaN, 0]}', "set_payload.cog: expected three finite numbers"),
        (
            "set_payload",
            b'{"mass": 1, "cog": [0, 0, -Infinity]}',
            "set_payload.cog: expected three finite numbers",
        ),
        ("speed_slider", b'{"fraction": NaN}', "set_speed_slider.fraction: must be within 0..1, got nan"),
        (
            "speed_slider",
            b'{"fraction": Infinity}',
            "set_speed_slider.fraction: must be within 0..1, got inf",
        ),
    ],
)
def test_non_finite_values_where_ranges_are_checked(name: str, payload: bytes, expected: str) -> None:
    decoder, _ = DECODERS[name]
    assert refused(decoder, payload) == expected


def test_too_many_trajectory_points_are_refused() -> None:
    point = b'{"positions":[0],"time_from_start":1}'
    payload = b'{"points": [' + b",".join([point] * (MAX_TRAJECTORY_POINTS + 1)) + b"]}"
    assert len(payload) < MAX_MESSAGE_BYTES
    assert refused(decode_trajectory_goal, payload) == (
        f"trajectory goal.points: more than {MAX_TRAJECTORY_POINTS} points"
    )


# --- good messages decode to the right values ---


def test_trajectory_goal_decodes_every_field() -> None:
    message = {
        "v": 1,
        "joint_names": ["a", "b"],
        "points": [
            {"positions": [0, 1], "time_from_start": 0.5},
            {"positions": [1.5, -2], "velocities": [0, 0], "accelerations": [0.1, 0.2], "time_from_start": 2},
        ],
        "tolerances": {"path": 0.1, "goal": [0.01, 0.02], "goal_time": 1},
        "preempt": True,
    }
    goal = decode_trajectory_goal(dumps(message))
    assert goal == TrajectoryGoalMessage(
        joint_names=("a", "b"),
        points=(
            TrajectoryPoint(positions=(0.0, 1.0), time_from_start=0.5),
            TrajectoryPoint(
                positions=(1.5, -2.0), time_from_start=2.0, velocities=(0.0, 0.0), accelerations=(0.1, 0.2)
            ),
        ),
        tolerances=ToleranceMessage(path=0.1, goal=(0.01, 0.02), goal_time=1.0),
        preempt=True,
    )
    assert all(isinstance(v, float) for p in goal.points for v in p.positions)
    assert isinstance(goal.points[1].time_from_start, float)


def test_trajectory_goal_defaults() -> None:
    goal = decode_trajectory_goal(b'{"points": [], "joint_names": null, "tolerances": null}')
    assert goal == TrajectoryGoalMessage(
        joint_names=None, points=(), tolerances=ToleranceMessage(), preempt=False
    )


def test_move_goal_decodes_every_field() -> None:
    message = {
        "positions": [1, 2.5],
        "joint_names": ["x", "y"],
        "duration": 3,
        "velocity_scale": 0.5,
        "acceleration_scale": 0.25,
        "tolerances": {"goal": 0.05},
        "preempt": False,
    }
    assert decode_move_goal(dumps(message)) == MoveGoalMessage(
        joint_names=("x", "y"),
        positions=(1.0, 2.5),
        duration=3.0,
        velocity_scale=0.5,
        acceleration_scale=0.25,
        tolerances=ToleranceMessage(goal=0.05),
        preempt=False,
    )


def test_move_goal_defaults() -> None:
    assert decode_move_goal(b'{"positions": []}') == MoveGoalMessage(
        joint_names=None,
        positions=(),
        duration=None,
        velocity_scale=1.0,
        acceleration_scale=1.0,
        tolerances=ToleranceMessage(),
        preempt=False,
    )
    explicit_null = decode_move_goal(b'{"positions": [0], "duration": null, "velocity_scale": null}')
    assert explicit_null.duration is None
    assert explicit_null.velocity_scale == 1.0


def test_cancel_decodes() -> None:
    assert decode_cancel(b'{"goal_id": "abc"}') == "abc"
    assert decode_cancel(b"{}") is None
    assert decode_cancel(b'{"goal_id": null, "v": 1}') is None


def test_stream_messages_decode() -> None:
    assert decode_stream_position(
        b'{"positions": [1, 2], "velocities": [0.5, 0], "joint_names": ["a", "b"]}'
    ) == (StreamMessage(joint_names=("a", "b"), positions=(1.0, 2.0), velocities=(0.5, 0.0)))
    assert decode_stream_position(b'{"positions": [1]}') == StreamMessage(None, (1.0,), None)
    assert decode_stream_velocity(b'{"velocities": [-1, 2]}') == StreamMessage(None, None, (-1.0, 2.0))


@pytest.mark.parametrize(
    ("message", "expected"),
    [
        ({"kind": "digital", "pin": 3, "value": True}, ("digital", 3, True)),
        ({"kind": "tool", "pin": 1, "value": False}, ("tool", 1, False)),
        ({"kind": "analog", "pin": 0, "value": 0.5}, ("analog", 0, 0.5)),
        ({"kind": "analog", "pin": 1, "value": 1}, ("analog", 1, 1.0)),
        # range and kind are the backend's business (check_io), not the codec's
        ({"kind": "weird", "pin": -1, "value": 7}, ("weird", -1, 7.0)),
    ],
)
def test_set_io_decodes(message: dict[str, Any], expected: tuple[str, int, float | bool]) -> None:
    kind, pin, value = decode_set_io(dumps(message))
    assert (kind, pin, value) == expected
    assert type(value) is type(expected[2])


def test_set_payload_decodes() -> None:
    assert decode_set_payload(b'{"mass": 2, "cog": [0.1, 0, -0.2]}') == (2.0, (0.1, 0.0, -0.2))
    assert decode_set_payload(b'{"mass": 0}') == (0.0, (0.0, 0.0, 0.0))


@pytest.mark.parametrize("fraction", [0, 0.0, 0.3, 1, 1.0])
def test_speed_slider_decodes(fraction: float) -> None:
    value = decode_speed_slider(dumps({"fraction": fraction}))
    assert value == float(fraction)
    assert isinstance(value, float)


# --- robustness: anything in gives a value or a MessageError ---


def _call(decoder: Decoder, payload: bytes) -> None:
    """Decode; a ``MessageError`` with a message is fine, any other exception fails the test."""
    error: MessageError | None = None
    try:
        decoder(payload)
    except MessageError as err:
        error = err
    assert error is None or str(error)


@settings(max_examples=300, deadline=None)
@given(payload=st.binary(max_size=200), name=st.sampled_from(list(DECODERS)))
def test_any_bytes_give_a_value_or_message_error(payload: bytes, name: str) -> None:
    _call(DECODERS[name][0], payload)


SAFE_INTS = st.integers(min_value=-(10**300), max_value=10**300)
JSON_LEAVES = st.none() | st.booleans() | SAFE_INTS | st.floats(allow_nan=True) | st.text(max_size=5)
JSON_VALUES = st.recursive(
    JSON_LEAVES,
    lambda children: (
        st.lists(children, max_size=4) | st.dictionaries(st.text(max_size=5), children, max_size=4)
    ),
    max_leaves=12,
)
FIELD_NAMES = st.sampled_from(
    [
        "v",
        "joint_names",
        "points",
        "positions",
        "velocities",
        "accelerations",
        "time_from_start",
        "tolerances",
        "path",
        "goal",
        "goal_time",
        "preempt",
        "duration",
        "velocity_scale",
        "acceleration_scale",
        "goal_id",
        "kind",
        "pin",
        "value",
        "mass",
        "cog",
        "fraction",
        "other",
    ]
)
POINT = st.dictionaries(FIELD_NAMES, JSON_VALUES, max_size=5)
FIELD_VALUES = (
    JSON_VALUES | st.lists(POINT, max_size=3) | st.lists(SAFE_INTS | st.floats(), max_size=4) | POINT
)


@settings(max_examples=200, deadline=None)
@given(message=st.dictionaries(FIELD_NAMES, FIELD_VALUES, max_size=6), name=st.sampled_from(list(DECODERS)))
def test_any_json_object_gives_a_value_or_message_error(message: dict[str, Any], name: str) -> None:
    _call(DECODERS[name][0], json.dumps(message).encode())


@settings(max_examples=300, deadline=None)
@given(name=st.sampled_from(list(DECODERS)), key=FIELD_NAMES, value=FIELD_VALUES)
def test_good_message_with_one_field_replaced_gives_a_value_or_message_error(
    name: str, key: str, value: Any
) -> None:
    _call(DECODERS[name][0], json.dumps({**GOOD[name], key: value}).encode())


@pytest.mark.parametrize("name", ["move", "speed_slider", "set_io", "set_payload", "trajectory"])
def test_huge_integer_is_a_message_error(name: str) -> None:
    huge = "1" + "0" * 400
    payloads = {
        "move": f'{{"positions": [{huge}]}}',
        "speed_slider": f'{{"fraction": {huge}}}',
        "set_io": f'{{"kind": "analog", "pin": 0, "value": {huge}}}',
        "set_payload": f'{{"mass": {huge}}}',
        "trajectory": f'{{"points": [{{"positions": [0], "time_from_start": {huge}}}]}}',
    }
    refused(DECODERS[name][0], payloads[name].encode())


def test_integer_with_too_many_digits_is_a_message_error() -> None:
    payload = b'{"fraction": 1' + b"0" * 5000 + b"}"
    assert refused(decode_speed_slider, payload).startswith("set_speed_slider: not valid JSON")


# --- encoders ---


def test_encode_adds_version_and_is_compact() -> None:
    data = encode({"robot": "alice", "ok": True, "x": [1.5, None]})
    assert data == b'{"v":1,"robot":"alice","ok":true,"x":[1.5,null]}'
    assert json.loads(data)["v"] == 1


def test_encode_maps_non_finite_numbers_to_null_at_any_depth() -> None:
    data = json.loads(encode({"x": math.nan, "y": [1.0, math.inf], "z": {"w": -math.inf, "ok": 2.5}}))
    assert data == {"v": 1, "x": None, "y": [1.0, None], "z": {"w": None, "ok": 2.5}}


def test_encode_feedback() -> None:
    feedback = GoalFeedback(
        goal_id="g1",
        time_from_start=1.0,
        duration=4.0,
        desired=(0.5, 1.0),
        actual=(0.25, 1.0),
        error=(0.25, 0.0),
    )
    state = make_state([0.5, 1.0], [0.0, 0.0], [0.0, 0.0])
    assert json.loads(encode_feedback("alice", feedback, state_time(state, 0))) == {
        "v": 1,
        "robot": "alice",
        "host_time_ns": 1_700_000_000_123_456_789,
        "controller_time": 12.004,
        "goal_id": "g1",
        "time_from_start": 1.0,
        "duration": 4.0,
        "progress": 0.25,
        "desired": [0.5, 1.0],
        "actual": [0.25, 1.0],
        "error": [0.25, 0.0],
    }


def test_encode_result() -> None:
    result = GoalResult(
        goal_id="g2",
        status=GoalStatus.ABORTED,
        reason="path tolerance",
        final_positions=(1.0,),
        final_error=(0.3,),
        duration=2.5,
    )
    state = make_state([1.0], [0.0], [0.0])
    assert json.loads(encode_result("bob", result, state_time(state, 0))) == {
        "v": 1,
        "robot": "bob",
        "host_time_ns": 1_700_000_000_123_456_789,
        "controller_time": 12.004,
        "goal_id": "g2",
        "status": "aborted",
        "reason": "path tolerance",
        "final_positions": [1.0],
        "final_error": [0.3],
        "duration": 2.5,
    }


def make_state(positions: list[float], velocities: list[float], efforts: list[float]) -> RobotState:
    names = tuple(f"j{i}" for i in range(len(positions)))
    state = RobotState(joint_names=names, positions=positions, velocities=velocities, efforts=efforts)
    state.controller_time = 12.004
    state.host_time_ns = 1_700_000_000_123_456_789
    state.cycle = 6001
    return state


def expected_float(value: float) -> float | None:
    return value if math.isfinite(value) else None


def test_joint_state_encoder_layout() -> None:
    encoder = JointStateEncoder("alice", ["alice_j0", "alice_j1"])
    state = make_state([0.1, -2.0], [0.0, 1e-300], [5.0, -0.0])
    data = json.loads(encoder.encode(state))
    assert list(data) == [
        "v",
        "robot",
        "names",
        "controller_time",
        "host_time_ns",
        "cycle",
        "position",
        "velocity",
        "effort",
    ]
    assert data == {
        "v": 1,
        "robot": "alice",
        "names": ["alice_j0", "alice_j1"],
        "controller_time": 12.004,
        "host_time_ns": 1_700_000_000_123_456_789,
        "cycle": 6001,
        "position": [0.1, -2.0],
        "velocity": [0.0, 1e-300],
        "effort": [5.0, -0.0],
    }
    assert math.copysign(1.0, data["effort"][1]) == -1.0


def test_joint_state_encoder_maps_nan_and_inf_to_null() -> None:
    encoder = JointStateEncoder("a", ["x", "y", "z"])
    data = json.loads(
        encoder.encode(make_state([math.nan, math.inf, -math.inf], [1.0, math.nan, 2.0], [0, 0, 0]))
    )
    assert data["position"] == [None, None, None]
    assert data["velocity"] == [1.0, None, 2.0]


def test_joint_state_encoder_escapes_names() -> None:
    encoder = JointStateEncoder('we"ird\\', ["ä", 'q"'])
    data = json.loads(encoder.encode(make_state([1.0, 2.0], [0.0, 0.0], [0.0, 0.0])))
    assert data["robot"] == 'we"ird\\'
    assert data["names"] == ["ä", 'q"']


def test_joint_state_encoder_with_no_joints() -> None:
    data = json.loads(JointStateEncoder("a", []).encode(make_state([], [], [])))
    assert data["position"] == data["velocity"] == data["effort"] == []


FLOATS = st.floats(allow_nan=True, allow_infinity=True)


@settings(max_examples=300, deadline=None)
@given(
    values=st.lists(st.tuples(FLOATS, FLOATS, FLOATS), min_size=0, max_size=8),
    controller_time=st.floats(min_value=0, max_value=1e12),
    host_time_ns=st.integers(min_value=0, max_value=2**63),
    cycle=st.integers(min_value=0, max_value=2**40),
)
def test_joint_state_encoder_round_trips_floats_exactly(
    values: list[tuple[float, float, float]], controller_time: float, host_time_ns: int, cycle: int
) -> None:
    positions = [v[0] for v in values]
    velocities = [v[1] for v in values]
    efforts = [v[2] for v in values]
    state = make_state(positions, velocities, efforts)
    state.controller_time, state.host_time_ns, state.cycle = controller_time, host_time_ns, cycle
    data = json.loads(JointStateEncoder("r", state.joint_names).encode(state))
    assert data["position"] == [expected_float(v) for v in positions]
    assert data["velocity"] == [expected_float(v) for v in velocities]
    assert data["effort"] == [expected_float(v) for v in efforts]
    for got, sent in zip(data["position"], positions, strict=True):
        if got is not None:
            assert math.copysign(1.0, got) == math.copysign(1.0, sent)
    assert data["controller_time"] == controller_time
    assert data["host_time_ns"] == host_time_ns
    assert data["cycle"] == cycle


def test_encode_pose_layout() -> None:
    encoder = JointStateEncoder("alice", ["j"])
    state = make_state([0.0], [0.0], [0.0])
    pose = [0.1, 0.2, 0.3, 0.0, 0.0, 0.7071067811865476, 0.7071067811865476]
    data = json.loads(encoder.encode_pose(state, "alice_base", "alice_tool0", pose))
    assert data == {
        "v": 1,
        "robot": "alice",
        "frame": "alice_base",
        "child": "alice_tool0",
        "controller_time": 12.004,
        "host_time_ns": 1_700_000_000_123_456_789,
        "position": [0.1, 0.2, 0.3],
        "orientation": [0.0, 0.0, 0.7071067811865476, 0.7071067811865476],
        "pose": [0.1, 0.2, 0.3, 0.0, 0.0, pytest.approx(math.pi / 2, abs=1e-15)],
    }


@example(pose=[0.0, 0.0, 0.0, 0.0, 0.0, 5e-324, 0.0])  # a turn of pi about z, the axis denormal
@settings(max_examples=200, deadline=None)
@given(pose=st.lists(FLOATS, min_size=7, max_size=7))
def test_encode_pose_round_trips_and_maps_non_finite_to_null(pose: list[float]) -> None:
    encoder = JointStateEncoder("r", ["j"])
    data = json.loads(encoder.encode_pose(make_state([0.0], [0.0], [0.0]), "r_base", "r_tool0", pose))
    assert data["position"] == [expected_float(v) for v in pose[:3]]
    assert data["orientation"] == [expected_float(v) for v in pose[3:]]


def test_encode_pose_escapes_frame_names() -> None:
    encoder = JointStateEncoder("r", ["j"])
    data = json.loads(encoder.encode_pose(make_state([0.0], [0.0], [0.0]), 'my"frame', "tool\\0", [0.0] * 7))
    assert data["frame"] == 'my"frame'
    assert data["child"] == "tool\\0"


def test_joint_state_encoder_keeps_percent_signs_in_names_literal() -> None:
    encoder = JointStateEncoder("r%d", ["j%r", "k%%"])
    state = make_state([1.0, 2.0], [0.0, 0.0], [0.0, 0.0])
    data = json.loads(encoder.encode(state))
    assert (data["robot"], data["names"], data["position"]) == ("r%d", ["j%r", "k%%"], [1.0, 2.0])
    pose = json.loads(encoder.encode_pose(state, "b%s", "t%", [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]))
    assert (pose["frame"], pose["child"], pose["orientation"]) == ("b%s", "t%", [0.0, 0.0, 0.0, 1.0])


def test_joint_state_encoder_copes_with_a_state_of_another_length() -> None:
    """The fast template is made for the joint count; a state of another length still encodes."""
    data = json.loads(JointStateEncoder("r", ["a", "b"]).encode(make_state([1.0, 2.0, 3.0], [0.0], [])))
    assert (data["position"], data["velocity"], data["effort"]) == ([1.0, 2.0, 3.0], [0.0], [])


def test_joint_state_encoder_finite_values_whose_sum_overflows() -> None:
    data = json.loads(JointStateEncoder("r", ["a", "b"]).encode(make_state([1e308, 1e308], [0, 0], [0, 0])))
    assert data["position"] == [1e308, 1e308]


def test_cycle_stats_request() -> None:
    assert service_requests.decode_cycle_stats(None) is False
    assert service_requests.decode_cycle_stats(b"") is False
    assert service_requests.decode_cycle_stats(b'{"reset": true}') is True
    assert service_requests.decode_cycle_stats(b"{}") is False
    with pytest.raises(MessageError, match="unknown field"):
        service_requests.decode_cycle_stats(b'{"reste": true}')
    with pytest.raises(MessageError, match="expected a JSON object"):
        service_requests.decode_cycle_stats(b"[1]")
