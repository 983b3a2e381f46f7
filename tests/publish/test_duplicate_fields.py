"""A field named twice in any object of a client's message is refused, naming the field (issue 32:
``{"fraction": 0.5, "fraction": 0.2}`` set 0.2, the last one winning)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest

from urdaemon.errors import MessageError
from urdaemon.publish.cell_goal import CellGoalDecoder, decode_lease_tokens
from urdaemon.publish.goal_cancel import decode_cancel
from urdaemon.publish.lease_request import parse_request
from urdaemon.publish.linear_goal import decode_linear_goal
from urdaemon.publish.move_goal import decode_move_goal
from urdaemon.publish.service_requests import decode_set_io, decode_speed_slider
from urdaemon.publish.stream_commands import decode_stream_position, decode_stream_velocity
from urdaemon.publish.trajectory_json import decode_trajectory_goal

POINT = '{"positions": [0, 0, 0, 0, 0, 0], "time_from_start": 1.0}'


def _run(steps: Any) -> Any:
    while True:
        try:
            next(steps)
        except StopIteration as stop:
            return stop.value


CASES: list[tuple[Callable[[bytes], Any], str, str]] = [
    (decode_speed_slider, '{"fraction": 0.5, "fraction": 0.2}', "fraction"),
    (decode_speed_slider, '{"v": 1, "fraction": 0.5, "v": 1}', "v"),
    (decode_set_io, '{"kind": "standard_digital", "index": 1, "value": true, "index": 2}', "index"),
    (decode_move_goal, '{"positions": [0, 0, 0, 0, 0, 0], "duration": 3, "duration": 0.1}', "duration"),
    (
        decode_stream_position,
        '{"positions": [0, 0, 0, 0, 0, 0], "positions": [1, 1, 1, 1, 1, 1]}',
        "positions",
    ),
    (
        decode_stream_velocity,
        '{"velocities": [0, 0, 0, 0, 0, 0], "velocities": [1, 0, 0, 0, 0, 0]}',
        "velocities",
    ),
    (decode_cancel, '{"goal_id": "a", "goal_id": "b"}', "goal_id"),
    (parse_request, '{"action": "acquire", "holder": "a", "holder": "b"}', "holder"),
    (decode_linear_goal, '{"pose": [0.4, 0, 0.4, 0, 3.14, 0], "pose": [0.4, 0, 0.4, 0, 3.14, 0]}', "pose"),
    (decode_trajectory_goal, f'{{"points": [{POINT}], "points": [{POINT}]}}', "points"),
    (decode_trajectory_goal, f'{{"scale": 1, "points": [{POINT}], "scale": 2}}', "scale"),
    (
        decode_trajectory_goal,
        '{"points": [{"positions": [0,0,0,0,0,0], "positions": [1,1,1,1,1,1], "time_from_start": 1}]}',
        "positions",
    ),
    (
        lambda p: _run(CellGoalDecoder(p).steps()),
        '{"on_abort": "stop", "on_abort": "continue", "robots": {}}',
        "on_abort",
    ),
    (lambda p: _run(CellGoalDecoder(p).steps()), '{"robots": {}, "robots": {}}', "robots"),
    (decode_lease_tokens, '{"alice": "x", "alice": "y"}', "alice"),
]


@pytest.mark.parametrize(("decode", "text", "field"), CASES)
def test_a_field_given_twice_is_refused_naming_it(
    decode: Callable[[bytes], Any], text: str, field: str
) -> None:
    with pytest.raises(MessageError, match=f"'{field}' is given twice"):
        decode(text.encode())


def test_the_same_name_in_two_objects_is_no_duplicate() -> None:
    assert decode_speed_slider(b'{"fraction": 0.5}') == 0.5
    two = f'{{"points": [{POINT}, {POINT.replace("1.0", "2.0")}]}}'
    assert len(decode_trajectory_goal(two.encode()).points) == 2
