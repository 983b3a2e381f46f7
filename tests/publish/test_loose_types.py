"""Every number a client's message carries is a JSON number and every flag a JSON boolean: ``true`` is
no number (Python's ``isinstance(True, int)``), ``"50"`` is no number, ``1`` is no flag. Each
decoder refuses them naming the field. The walk replaces one leaf of a valid message at a time."""

from __future__ import annotations

import json
from collections.abc import Callable, Generator, Iterator
from typing import Any

import pytest

from urdaemon.errors import MessageError
from urdaemon.publish import service_requests as requests
from urdaemon.publish import stream_commands
from urdaemon.publish.linear_goal import LinearGoalDecoder
from urdaemon.publish.move_goal import decode_move_goal
from urdaemon.publish.trajectory_json import decode_trajectory_goal

Path = tuple[str | int, ...]


def finish(steps: Generator[None, None, Any]) -> Any:
    """Run a sliced decoder to its result, in a bounded number of steps."""
    for _ in range(100_000):
        try:
            next(steps)
        except StopIteration as done:
            return done.value
    raise AssertionError("the decoder did not finish")


SIX = [0.1, -0.2, 0.3, 0.0, 0.1, 0.2]
TOLERANCES = {"path": 0.1, "goal": [0.01] * 6, "goal_time": 1.0}
VALID: dict[str, tuple[Callable[[bytes], Any], dict[str, Any]]] = {
    "move goal": (
        decode_move_goal,
        {
            "positions": SIX,
            "duration": 2.0,
            "velocity_scale": 0.5,
            "acceleration_scale": 0.5,
            "tolerances": TOLERANCES,
            "preempt": False,
        },
    ),
    "pose goal": (decode_move_goal, {"pose": [0.3, 0.1, 0.4, 0.0, 3.1, 0.0], "preempt": True}),
    "linear goal": (
        lambda payload: finish(LinearGoalDecoder(payload).steps()),
        {
            "poses": [[0.3, 0.1, 0.4, 0.0, 3.1, 0.0], [0.3, 0.2, 0.4, 0.0, 3.1, 0.0]],
            "blend_radii": [0.0],
            "speed": 0.1,
            "angular_jerk": 5.0,
            "tolerances": TOLERANCES,
        },
    ),
    "trajectory goal": (
        decode_trajectory_goal,
        {
            "points": [
                {"positions": SIX, "velocities": [0.0] * 6, "accelerations": [0.0] * 6, "time_from_start": 1}
            ],
            "tolerances": TOLERANCES,
            "preempt": False,
            "passthrough": False,
        },
    ),
    "joint_position command": (
        stream_commands.decode_stream_position,
        {"positions": SIX, "velocities": [0.0] * 6},
    ),
    "joint_velocity command": (stream_commands.decode_stream_velocity, {"velocities": SIX}),
    "twist command": (stream_commands.decode_twist, {"linear": [0.0, 0.1, 0.0], "angular": [0.0, 0.0, 0.1]}),
    "freedrive command": (stream_commands.decode_freedrive, {"active": True}),
    "set_tcp": (requests.decode_set_tcp, {"pose": [0.0, 0.0, 0.1, 0.0, 0.0, 0.0]}),
    "set_io analog": (requests.decode_set_io, {"kind": "analog", "pin": 0, "value": 0.5}),
    "set_io digital": (requests.decode_set_io, {"kind": "digital", "pin": 3, "value": True}),
    "set_io tool": (requests.decode_set_io, {"kind": "tool", "pin": 1, "value": False}),
    "set_payload": (requests.decode_set_payload, {"mass": 1.5, "cog": [0.0, 0.0, 0.05]}),
    "set_tool_voltage": (requests.decode_tool_voltage, {"volts": 24}),
    "start_force_mode": (
        requests.decode_force_mode,
        {
            "task_frame": [0.0] * 6,
            "selection": [0, 0, 1, 0, 0, 0],
            "wrench": [0.0, 0.0, 5.0, 0.0, 0.0, 0.0],
            "type": 2,
            "limits": [0.1] * 6,
            "damping": 0.5,
            "gain_scaling": 1.0,
        },
    ),
    "set_speed_slider": (requests.decode_speed_slider, {"fraction": 0.5}),
    "cycle_stats": (requests.decode_cycle_stats, {"reset": True}),
}


def leaves(value: Any, path: Path = ()) -> Iterator[tuple[Path, Any]]:
    """Every number and boolean of a message, with its path."""
    if isinstance(value, dict):
        for key, item in value.items():
            yield from leaves(item, (*path, key))
    elif isinstance(value, list):
        for i, item in enumerate(value):
            yield from leaves(item, (*path, i))
    elif isinstance(value, bool | int | float):
        yield path, value


def replaced(message: Any, path: Path, new: Any) -> Any:
    """A deep copy of ``message`` with the leaf at ``path`` replaced by ``new``."""
    copy = json.loads(json.dumps(message))
    node = copy
    for step in path[:-1]:
        node = node[step]
    node[path[-1]] = new
    return copy


def named(path: Path) -> str:
    """How a refusal names the leaf: ``points[0].time_from_start``, ``goal[3]``."""
    text = ""
    for step in path:
        text += f"[{step}]" if isinstance(step, int) else f".{step}"
    return text.lstrip(".")


CASES = [
    (what, path, bad)
    for what, (_, message) in VALID.items()
    for path, value in leaves(message)
    for bad in ((1, "true") if isinstance(value, bool) else (True, "50"))
]
"""Each leaf of each valid message with a loose value: a flag given as a number or text, a number
given as a flag or text (an analog output's value is a number, a digital one's a flag)."""


@pytest.mark.parametrize("what", list(VALID))
def test_the_valid_messages_decode(what: str) -> None:
    decode, message = VALID[what]
    decode(json.dumps(message).encode())


@pytest.mark.parametrize(("what", "path", "bad"), CASES, ids=[f"{w}:{named(p)}={b!r}" for w, p, b in CASES])
def test_a_loose_type_is_refused_naming_the_field(what: str, path: Path, bad: Any) -> None:
    decode, message = VALID[what]
    with pytest.raises(MessageError) as info:
        decode(json.dumps(replaced(message, path, bad)).encode())
    field = named(path)
    assert field.split("[")[0].split(".")[-1] in str(info.value), (field, str(info.value))


def test_every_decoder_has_a_loose_case() -> None:
    assert {what for what, _, _ in CASES} == set(VALID)
    assert len(CASES) > 100
