"""The pieces that keep a client's message from holding the loop: the trajectory goal decoded a
point at a time, and client text made safe."""

from __future__ import annotations

import json

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.helpers import Stepped
from urdaemon.errors import MessageError
from urdaemon.publish.envelope import client_text
from urdaemon.publish.trajectory_json import POINT_CHARS, TrajectoryGoalDecoder, decode_trajectory_goal


def _goal(points: int) -> bytes:
    return json.dumps(
        {
            "joint_names": ["a", "b"],
            "points": [{"positions": [0.1 * k, 0.2], "time_from_start": 1.0 + k} for k in range(points)],
            "tolerances": {"goal": 0.1},
            "preempt": True,
        }
    ).encode()


def test_a_goal_is_decoded_in_many_steps_with_the_result_of_json_loads() -> None:
    """Reproduction: a trajectory goal was decoded by one json.loads call (tens of ms for 2 MiB)."""
    payload = _goal(500)
    decoder = Stepped(TrajectoryGoalDecoder(payload).steps())
    steps = 0
    while decoder.step():  # one unit of work per step
        steps += 1
    assert steps > 500  # at least one step per point
    goal = decoder.result()
    assert goal == decode_trajectory_goal(payload)
    assert [p.positions for p in goal.points] == [(0.1 * k, 0.2) for k in range(500)]
    assert goal.preempt is True
    assert goal.joint_names == ("a", "b")


@settings(max_examples=200, deadline=None)
@given(
    st.dictionaries(
        st.sampled_from(["points", "joint_names", "preempt", "x"]),
        st.recursive(
            st.none() | st.booleans() | st.floats(allow_nan=False) | st.text(max_size=5),
            lambda inner: (
                st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=3), inner, max_size=3)
            ),
            max_leaves=10,
        ),
    )
)
def test_any_json_object_is_decoded_or_refused_with_a_message_error(data: dict[str, object]) -> None:
    payload = json.dumps(data).encode()
    try:
        decode_trajectory_goal(payload)
    except MessageError as err:
        message = str(err)
    else:
        message = "trajectory goal decoded"
    assert message.startswith("trajectory goal")


@pytest.mark.parametrize(
    ("payload", "reason"),
    [
        (b'{"points": [' + b" " * 5000 + b"]}", "more than 4096 whitespace characters"),
        (
            b'{"points": [{"positions": [' + b"1," * POINT_CHARS + b'1], "time_from_start": 1}]}',
            f"points[0] at character 12 is malformed or longer than {POINT_CHARS} characters",
        ),
        (b'{"points": []} x', "extra data"),
        (b"[1, 2]", "expected a JSON object, got list"),
        (b'{"points": [], "points2": 1}', "unknown field(s) points2"),
        (b'{"points": [' + b"[" * 3000 + b"]" * 3000 + b"]}", "nested too deeply"),
    ],
)
def test_what_is_too_long_or_not_json_is_refused_without_reading_on(payload: bytes, reason: str) -> None:
    with pytest.raises(MessageError, match=r"^trajectory goal") as err:
        decode_trajectory_goal(payload)
    assert reason in str(err.value)


@pytest.mark.parametrize(
    ("text", "shown"),
    [
        ("joint", "joint"),
        ("a\nb\rc\x00", "a\\nb\\rc\\x00"),
        ("x" * 100, "x" * 40 + "…"),
        ("\x1b[31mred", "\\x1b[31mred"),
    ],
)
def test_client_text_is_short_and_has_no_control_characters(text: str, shown: str) -> None:
    assert client_text(text) == shown
