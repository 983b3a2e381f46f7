"""Review of issue 13: the size limit of every message but a trajectory goal is what valid messages
need, with margin, and no more."""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import Any

import pytest

from urdaemon.errors import MessageError
from urdaemon.publish import envelope, fields, move_goal, service_requests, stream_commands

LONGEST_FLOAT = -1.2345678901234567e-100  # 24 characters of JSON
NAMES = [f"j{i:02d}".ljust(fields.MAX_NAME_CHARS, "x") for i in range(fields.MAX_JOINTS)]
VALUES = [LONGEST_FLOAT] * fields.MAX_JOINTS
LARGEST_MOVE = {
    "v": 1,
    "joint_names": NAMES,
    "positions": VALUES,
    "duration": 7199.999999999999,
    "velocity_scale": 0.9999999999999999,
    "acceleration_scale": 0.9999999999999999,
    "tolerances": {"path": [6.283185307179586] * 64, "goal": [6.283185307179586] * 64, "goal_time": 7199.5},
    "preempt": False,
}
LARGEST_STREAM = {"v": 1, "joint_names": NAMES, "positions": VALUES, "velocities": VALUES}


@pytest.mark.parametrize(
    ("decode", "message"),
    [(move_goal.decode_move_goal, LARGEST_MOVE), (stream_commands.decode_stream_position, LARGEST_STREAM)],
)
def test_the_largest_valid_messages_fit_with_room(
    decode: Callable[[bytes], Any], message: dict[str, Any]
) -> None:
    """The largest valid move and stream command (64 joints, 64-character names, every field, the
    longest numbers), even indented, decode within the limit with at least 1.5x room."""
    for payload in (json.dumps(message).encode(), json.dumps(message, indent=2).encode()):
        decode(payload)
        assert len(payload) * 1.5 < envelope.SMALL_MESSAGE_BYTES, len(payload)


@pytest.mark.parametrize(
    "decode",
    [move_goal.decode_move_goal, stream_commands.decode_stream_position, service_requests.decode_set_payload],
)
def test_a_message_twice_the_largest_valid_one_is_refused_before_decoding(
    decode: Callable[[bytes], Any],
) -> None:
    """Reproduction: a 20 000-byte move, stream command or service request (twice the largest
    valid one) was read and decoded: the limit was 64 KiB, ~64x what any valid message needs, so a
    flood of such messages cost the loop ~1 ms each. Now it is refused by size, unread."""
    payload = b"[" + b"1," * 9_999 + b"1]"
    assert len(payload) == 20_001
    with pytest.raises(MessageError, match="message of 20001 bytes exceeds the limit of 16384 bytes"):
        decode(payload)
