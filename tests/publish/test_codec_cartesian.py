"""Issue 17's messages: pose move goals, linear goals, twists and set_tcp; every refusal names its field.

Reproduction (each test): on the code before issue 17 ``decode_move_goal`` refused ``pose`` as an
unknown field and ``decode_linear_goal``, ``decode_twist`` and ``decode_set_tcp`` did not exist.
"""

from __future__ import annotations

import json
import math
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from urdaemon.errors import MessageError
from urdaemon.publish import envelope, linear_goal, services
from urdaemon.publish.fields import ToleranceMessage
from urdaemon.publish.linear_goal import (
    LINEAR_MESSAGE_BYTES,
    MAX_LINEAR_POSES,
    LinearGoalMessage,
    decode_linear_goal,
)
from urdaemon.publish.move_goal import decode_move_goal
from urdaemon.publish.service_requests import decode_set_tcp
from urdaemon.publish.stream_commands import TwistMessage, decode_twist

POSE = [0.4, -0.1, 0.3, 3.1, 0.0, 0.0]


def dumps(obj: object) -> bytes:
    return json.dumps(obj).encode()


def refused(decode: Any, payload: bytes) -> str:
    with pytest.raises(MessageError) as err:
        decode(payload)
    return str(err.value)


def test_a_pose_move_goal_decodes_every_field() -> None:
    goal = decode_move_goal(
        dumps(
            {
                "pose": POSE,
                "frame": "world",
                "configuration": {"elbow": "down", "shoulder": "left"},
                "duration": 2,
                "velocity_scale": 0.5,
                "preempt": True,
            }
        )
    )
    assert goal.pose == tuple(POSE)
    assert goal.positions == ()
    assert goal.frame == "world"
    assert goal.configuration == (("shoulder", "left"), ("elbow", "down"))
    assert (goal.duration, goal.velocity_scale, goal.preempt) == (2.0, 0.5, True)


def test_a_pose_move_goal_defaults_to_the_base_frame_and_any_configuration() -> None:
    goal = decode_move_goal(dumps({"pose": POSE}))
    assert (goal.frame, goal.configuration, goal.joint_names) == ("base", (), None)


def test_a_joint_move_goal_is_as_before() -> None:
    goal = decode_move_goal(dumps({"positions": [0.1, 0.2]}))
    assert (goal.positions, goal.pose, goal.frame) == ((0.1, 0.2), None, "base")


def test_linear_goal_decodes_every_field() -> None:
    message = {
        "poses": [POSE, POSE],
        "frame": "world",
        "blend_radii": [0.01],
        "speed": 0.1,
        "angular_jerk": 20,
        "tolerances": {"goal": 0.02},
    }
    assert decode_linear_goal(dumps(message)) == LinearGoalMessage(
        poses=(tuple(POSE), tuple(POSE)),  # type: ignore[arg-type]
        frame="world",
        blend_radii=(0.01,),
        limits=(("speed", 0.1), ("angular_jerk", 20.0)),
        tolerances=ToleranceMessage(goal=0.02),
    )


def test_linear_goal_defaults() -> None:
    goal = decode_linear_goal(dumps({"poses": [POSE, POSE, POSE]}))
    assert (goal.frame, goal.blend_radii, goal.limits) == ("base", (0.0, 0.0), ())


def test_the_largest_linear_goal_fits() -> None:
    """Every pose and radius a full-precision negative number, every field: within the 16 KiB."""
    pose = [
        -0.12345678901234568,
        -0.12345678901234568,
        -0.12345678901234568,
        -1.2345678901234568,
        1.2345678901234568,
        -1.2345678901234568,
    ]
    limits = dict.fromkeys(linear_goal.LINEAR_LIMITS, 0.12345678901234568)
    message = {
        "poses": [pose] * MAX_LINEAR_POSES,
        "blend_radii": [0.012345678901234568] * (MAX_LINEAR_POSES - 1),
        "frame": "world",
        "tolerances": {"path": 0.12345678901234568, "goal": 0.12345678901234568},
        **limits,
    }
    payload = dumps(message)
    assert len(payload) <= LINEAR_MESSAGE_BYTES
    assert len(decode_linear_goal(payload).poses) == MAX_LINEAR_POSES


def test_a_linear_goal_is_at_most_the_nodes_ordinary_message_size() -> None:
    """Its JSON is parsed in one call, like every other non-trajectory message (was 256 KiB: 5-9 ms
    of loop in one call)."""
    assert LINEAR_MESSAGE_BYTES == envelope.SMALL_MESSAGE_BYTES == 16 * 1024
    assert MAX_LINEAR_POSES == 100


def test_a_too_large_linear_goal_is_refused_before_it_is_parsed(monkeypatch: pytest.MonkeyPatch) -> None:
    """Counted, not timed: json.loads is never called for a message over the limit (the review's 17 KB
    goal of empty poses was parsed whole before its pose count was refused)."""
    calls = 0
    real = json.loads

    def counted(data: Any, **options: Any) -> Any:
        nonlocal calls
        calls += 1
        return real(data, **options)

    monkeypatch.setattr(json, "loads", counted)  # the module codec parses with
    body = b'{"poses": [' + b"[]," * (envelope.SMALL_MESSAGE_BYTES // 3) + b"[]]}"
    reason = refused(linear_goal.LinearGoalDecoder, body)
    assert reason == f"linear goal: message of {len(body)} bytes exceeds the limit of 16384 bytes"
    assert calls == 0
    small = dumps({"poses": [POSE]})
    linear_goal.LinearGoalDecoder(small)
    assert calls == 1


def test_twist_decodes() -> None:
    assert decode_twist(dumps({"linear": [0.1, 0, 0], "angular": [0, 0, 0.2], "frame": "tool"})) == (
        TwistMessage((0.1, 0.0, 0.0), (0.0, 0.0, 0.2), "tool")
    )
    assert decode_twist(dumps({"linear": [0, 0, 0], "angular": [0, 0, 0]})).frame == "base"


def test_set_tcp_decodes_and_checks_the_cell_files_ranges() -> None:
    assert decode_set_tcp(dumps({"pose": [0, 0, 0.1, 0, 0, 0]})) == (0.0, 0.0, 0.1, 0.0, 0.0, 0.0)
    decode = services.spec("set_tcp").decode
    assert decode(dumps({"pose": [0, 0, 0.1, 0, 0, 0]})).pose == (0.0, 0.0, 0.1, 0.0, 0.0, 0.0)
    assert (
        refused(decode, dumps({"pose": [0, 0, 1.5, 0, 0, 0]}))
        == "set_tcp.pose: TCP z = 1.5 m is beyond ±1.0 m"
    )
    assert refused(decode, dumps({"pose": [0, 0, 0, 0, 0, 3.5]})).startswith(
        "set_tcp.pose: TCP rotation 3.5 rad"
    )


FIELD_ERRORS: list[tuple[Any, object, str]] = [
    # pose move goal
    (
        decode_move_goal,
        {"pose": POSE, "positions": [0]},
        "move goal: give positions (joints) or pose (the TCP), not both",
    ),
    (
        decode_move_goal,
        {"positions": [0], "frame": "world"},
        "move goal.frame: only a pose goal has a frame (send pose, not positions)",
    ),
    (
        decode_move_goal,
        {"positions": [0], "configuration": {"elbow": "up"}},
        "move goal.configuration: only a pose goal has a configuration (send pose, not positions)",
    ),
    (
        decode_move_goal,
        {"pose": POSE, "joint_names": ["a"]},
        "move goal.joint_names: a pose goal names no joints",
    ),
    (
        decode_move_goal,
        {"pose": [1, 2, 3]},
        "move goal.pose: expected six numbers [x, y, z, rx, ry, rz], got 3",
    ),
    (decode_move_goal, {"pose": [1, 2, 3, 4, 5, 6, 7]}, "move goal.pose: 7 values; at most 6 are accepted"),
    (decode_move_goal, {"pose": [0, 0, "1", 0, 0, 0]}, 'move goal.pose[2]: expected a number, got "1"'),
    (decode_move_goal, {"pose": "here"}, "move goal.pose: expected a list of numbers, got str"),
    (
        decode_move_goal,
        {"pose": [0, 0, 101, 0, 0, 0]},
        "move goal.pose[2] (m): must be within -100..100, got 101",
    ),
    (
        decode_move_goal,
        {"pose": POSE, "frame": "tool"},
        'move goal.frame: expected one of base, world, got "tool"',
    ),
    (
        decode_move_goal,
        {"pose": POSE, "configuration": "up"},
        "move goal.configuration: expected an object with any of shoulder, elbow, wrist",
    ),
    (
        decode_move_goal,
        {"pose": POSE, "configuration": {"knee": "up"}},
        "move goal.configuration: unknown field(s) knee",
    ),
    (
        decode_move_goal,
        {"pose": POSE, "configuration": {"elbow": "left"}},
        'move goal.configuration.elbow: expected up or down, got "left"',
    ),
    (
        decode_move_goal,
        {"pose": POSE, "configuration": {"shoulder": "up"}},
        'move goal.configuration.shoulder: expected left or right, got "up"',
    ),
    # linear goal
    (decode_linear_goal, {}, "linear goal.poses: expected a list of one or more poses [x, y, z, rx, ry, rz]"),
    (
        decode_linear_goal,
        {"poses": []},
        "linear goal.poses: expected a list of one or more poses [x, y, z, rx, ry, rz]",
    ),
    (decode_linear_goal, {"poses": POSE}, "linear goal.poses[0]: expected a list of numbers, got float"),
    (
        decode_linear_goal,
        {"poses": [POSE, POSE, [0, 0, 0]]},
        "linear goal.poses[2]: expected six numbers [x, y, z, rx, ry, rz], got 3",
    ),
    (
        decode_linear_goal,
        {"poses": [POSE, [0, 0, 0, 0, None, 0]]},
        "linear goal.poses[1][4]: expected a number, got null",
    ),
    (
        decode_linear_goal,
        {"poses": [POSE], "frame": "tool"},
        'linear goal.frame: expected one of base, world, got "tool"',
    ),
    (
        decode_linear_goal,
        {"poses": [POSE, POSE], "blend_radii": [0.1, 0.1]},
        "linear goal.blend_radii: 2 radii for 2 poses; expected 1 (one per corner)",
    ),
    (
        decode_linear_goal,
        {"poses": [POSE, POSE], "blend_radii": [-0.1]},
        "linear goal.blend_radii[0] (m): must be within 0..100, got -0.1",
    ),
    (
        decode_linear_goal,
        {"poses": [POSE], "speed": 0},
        "linear goal.speed: must be a finite number > 0, got 0",
    ),
    (
        decode_linear_goal,
        {"poses": [POSE], "jerk": -1},
        "linear goal.jerk: must be a finite number > 0, got -1",
    ),
    (
        decode_linear_goal,
        {"poses": [POSE], "angular_speed": "1"},
        'linear goal.angular_speed: expected a number, got "1"',
    ),
    (decode_linear_goal, {"poses": [POSE], "force": 1}, "linear goal: unknown field(s) force"),
    (
        decode_linear_goal,
        {"poses": [POSE], "tolerances": {"goal": 0}},
        "linear goal.tolerances.goal: must be > 0 and ≤ 6.28319, got 0",
    ),
    # twist
    (decode_twist, {"angular": [0, 0, 0]}, "twist command.linear: missing"),
    (decode_twist, {"linear": [0, 0, 0]}, "twist command.angular: missing"),
    (
        decode_twist,
        {"linear": [0, 0], "angular": [0, 0, 0]},
        "twist command.linear: expected three finite numbers",
    ),
    (
        decode_twist,
        {"linear": [0, 0, 0, 0], "angular": [0, 0, 0]},
        "twist command.linear: 4 values; at most 3 are accepted",
    ),
    (
        decode_twist,
        {"linear": [0, 0, 0], "angular": [0, True, 0]},
        "twist command.angular[1]: expected a number, got true",
    ),
    (
        decode_twist,
        {"linear": [0, 0, 0], "angular": [0, 0, 0], "frame": "world"},
        'twist command.frame: expected one of base, tool, got "world"',
    ),
    (
        decode_twist,
        {"linear": [0, 0, 0], "angular": [0, 0, 0], "speed": 1},
        "twist command: unknown field(s) speed",
    ),
    # set_tcp
    (decode_set_tcp, {}, "set_tcp.pose: missing"),
    (decode_set_tcp, {"pose": [0, 0, 0]}, "set_tcp.pose: expected six numbers [x, y, z, rx, ry, rz], got 3"),
    (decode_set_tcp, {"pose": POSE, "frame": "base"}, "set_tcp: unknown field(s) frame"),
]


@pytest.mark.parametrize(
    ("decode", "message", "expected"), FIELD_ERRORS, ids=[str(i) for i in range(len(FIELD_ERRORS))]
)
def test_field_errors_name_the_field(decode: Any, message: object, expected: str) -> None:
    assert refused(decode, dumps(message)) == expected


@pytest.mark.parametrize(
    ("decode", "payload", "expected"),
    [
        (
            decode_move_goal,
            b'{"pose": [0, 0, NaN, 0, 0, 0]}',
            "move goal.pose[2]: expected a finite number, got nan",
        ),
        (
            decode_linear_goal,
            b'{"poses": [[0, 0, 0, 0, Infinity, 0]]}',
            "linear goal.poses[0][4]: expected a finite number, got inf",
        ),
        (
            decode_linear_goal,
            b'{"poses": [[0, 0, 0, 0, 0, 0]], "speed": NaN}',
            "linear goal.speed: must be a finite number > 0, got nan",
        ),
        (
            decode_linear_goal,
            b'{"poses": [[0, 0, 0, 0, 0, 0]], "speed": Infinity}',
            "linear goal.speed: must be a finite number > 0, got inf",
        ),
        (
            decode_twist,
            b'{"linear": [0, NaN, 0], "angular": [0, 0, 0]}',
            "twist command.linear: expected three finite numbers",
        ),
    ],
)
def test_non_finite_values_are_refused(decode: Any, payload: bytes, expected: str) -> None:
    assert refused(decode, payload) == expected


def test_too_many_poses_are_refused() -> None:
    payload = dumps({"poses": [[0] * 6] * (MAX_LINEAR_POSES + 1)})
    assert (
        refused(decode_linear_goal, payload)
        == f"linear goal.poses: {MAX_LINEAR_POSES + 1} poses; at most 100 are accepted"
    )


def test_an_oversized_linear_goal_is_refused_before_decoding() -> None:
    payload = b'{"poses": [' + b" " * LINEAR_MESSAGE_BYTES + b"]}"
    assert refused(decode_linear_goal, payload).startswith(
        f"linear goal: message of {len(payload)} bytes exceeds"
    )


def test_an_oversized_twist_is_refused_before_decoding() -> None:
    payload = b'{"linear": [' + b" " * envelope.SMALL_MESSAGE_BYTES + b"]}"
    assert "exceeds the limit" in refused(decode_twist, payload)


JSON = st.recursive(
    st.none() | st.booleans() | st.integers(-(10**30), 10**30) | st.floats() | st.text(max_size=4),
    lambda c: st.lists(c, max_size=7) | st.dictionaries(st.text(max_size=4), c, max_size=3),
    max_leaves=14,
)
FIELDS = st.sampled_from(
    ["pose", "poses", "positions", "frame", "configuration", "blend_radii", "speed", "linear", "angular", "x"]
)


@settings(max_examples=300, deadline=None)
@given(
    message=st.dictionaries(FIELDS, JSON, max_size=5),
    decode=st.sampled_from([decode_move_goal, decode_linear_goal, decode_twist, decode_set_tcp]),
)
def test_any_json_object_gives_a_value_or_message_error(message: dict[str, Any], decode: Any) -> None:
    error: MessageError | None = None
    try:
        decode(json.dumps(message).encode())
    except MessageError as err:
        error = err
    assert error is None or str(error)


ROTATION = (
    "(rotation vector, rad): length {} is over 2 pi (6.28319); give the axis times the angle in radians"
)


@pytest.mark.parametrize(
    ("decode", "message", "expected"),
    [
        (
            decode_move_goal,
            {"pose": [0.4, 0, 0.3, 1e300, 0, 0]},
            "move goal.pose[3:6] " + ROTATION.format("1e+300"),
        ),
        (decode_move_goal, {"pose": [0.4, 0, 0.3, 0, 180, 0]}, "move goal.pose[3:6] " + ROTATION.format(180)),
        (
            decode_linear_goal,
            {"poses": [POSE, [0.4, 0, 0.3, 4, 4, 4]]},
            "linear goal.poses[1][3:6] " + ROTATION.format("6.9282"),
        ),
    ],
)
def test_a_rotation_vector_longer_than_two_pi_is_refused_naming_the_field(
    decode: Any, message: object, expected: str
) -> None:
    """Degrees typed as radians (180) or garbage (1e300) was accepted as an orientation."""
    assert refused(decode, dumps(message)) == expected


def test_rotation_vectors_up_to_two_pi_are_accepted() -> None:
    full = [0.4, 0.0, 0.3, 0.0, 0.0, 2.0 * math.pi]
    assert decode_move_goal(dumps({"pose": full})).pose == tuple(full)
    assert decode_linear_goal(dumps({"poses": [POSE, full]})).poses[1] == tuple(full)
