"""Keyboard teleop's state machine (urdaemon/teleop_keys.py): keys and the time in, the twist out.

Reproduction on the code before issue 17: there was no teleop at all (``urdaemon.teleop_keys`` does
not exist), so every test here fails at its import.
"""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from urdaemon.teleop_keys import (
    ANGULAR_PER_LINEAR,
    DEFAULT_SPEED,
    ESC,
    MAX_SPEED,
    MIN_SPEED,
    RELEASE_S,
    SPEED_STEP,
    TeleopKeys,
    keys_of,
    rotation_vector,
    status_line,
)

LINEAR = {"q": (0, 1.0), "w": (1, 1.0), "e": (2, 1.0), "a": (0, -1.0), "s": (1, -1.0), "d": (2, -1.0)}
ANGULAR = {"r": (0, 1.0), "t": (1, 1.0), "y": (2, 1.0), "f": (0, -1.0), "g": (1, -1.0), "h": (2, -1.0)}


@pytest.mark.parametrize("key", sorted(LINEAR))
def test_each_linear_key_moves_its_axis_at_the_speed(key: str) -> None:
    keys = TeleopKeys(0.2)
    assert keys.feed(key, 10.0) == "move"
    twist = keys.twist(10.0)
    axis, sign = LINEAR[key]
    expected = [0.0, 0.0, 0.0]
    expected[axis] = sign * 0.2
    assert twist.linear == tuple(expected)
    assert twist.angular == (0.0, 0.0, 0.0)


@pytest.mark.parametrize("key", sorted(ANGULAR))
def test_each_rotation_key_turns_its_axis_at_the_angular_speed(key: str) -> None:
    keys = TeleopKeys(0.1)
    keys.feed(key, 0.0)
    twist = keys.twist(0.0)
    axis, sign = ANGULAR[key]
    assert twist.linear == (0.0, 0.0, 0.0)
    assert twist.angular[axis] == pytest.approx(sign * 0.1 * ANGULAR_PER_LINEAR)
    assert sum(abs(v) for v in twist.angular) == pytest.approx(0.1 * ANGULAR_PER_LINEAR)


def test_a_held_key_keeps_moving_and_the_twist_is_zero_once_keys_stop() -> None:
    keys = TeleopKeys()
    for i in range(20):  # auto-repeat every 30 ms
        keys.feed("w", i * 0.03)
        assert keys.twist(i * 0.03 + 0.02).linear[1] == DEFAULT_SPEED
    last = 19 * 0.03
    assert not keys.twist(last + 0.99 * RELEASE_S).zero, "within the window it still moves"
    assert keys.twist(last + RELEASE_S + 1e-6).zero, "no key within the window: zero twist"
    assert keys.moving(last + RELEASE_S + 1e-6) is None


def test_the_last_motion_key_wins_and_l_stops_at_once() -> None:
    keys = TeleopKeys(0.1)
    keys.feed("w", 0.0)
    keys.feed("a", 0.01)
    assert keys.twist(0.02).linear == (-0.1, 0.0, 0.0)
    assert keys.moving(0.02) == "-x"
    assert keys.feed("l", 0.03) == "stop"
    assert keys.twist(0.03).zero, "l stops within the window too"


def test_i_and_k_change_the_speed_within_its_range() -> None:
    keys = TeleopKeys(0.1)
    assert keys.feed("i", 0.0) == "speed"
    assert keys.speed == pytest.approx(0.1 * SPEED_STEP)
    keys.feed("k", 0.0)
    keys.feed("k", 0.0)
    assert keys.speed == pytest.approx(0.1 / SPEED_STEP)
    for _ in range(100):
        keys.feed("i", 0.0)
    assert keys.speed == MAX_SPEED
    for _ in range(100):
        keys.feed("k", 0.0)
    assert keys.speed == MIN_SPEED
    keys.feed("q", 1.0)
    assert keys.twist(1.0).linear[0] == MIN_SPEED, "a motion key moves at the changed speed"


def test_b_toggles_the_frame() -> None:
    keys = TeleopKeys(frame="base")
    assert keys.feed("b", 0.0) == "frame"
    assert keys.frame == "tool"
    keys.feed("b", 0.0)
    assert keys.frame == "base"


@pytest.mark.parametrize("key", ["x", ESC, "\x03", "\x04"])
def test_quit_keys_end_and_zero_the_twist(key: str) -> None:
    keys = TeleopKeys()
    keys.feed("w", 0.0)
    assert keys.feed(key, 0.01) == "quit"
    assert keys.done
    assert keys.twist(0.01).zero


def test_other_keys_are_ignored_and_capitals_are_the_same_keys() -> None:
    keys = TeleopKeys()
    for key in ("z", "1", " ", "\r", "é"):
        assert keys.feed(key, 0.0) is None
    assert keys.twist(0.0).zero
    assert not keys.done
    keys.feed("W", 0.0)
    assert keys.twist(0.0).linear[1] == DEFAULT_SPEED


def test_a_bad_start_speed_or_frame_is_refused() -> None:
    with pytest.raises(ValueError, match="speed"):
        TeleopKeys(MAX_SPEED * 2)
    with pytest.raises(ValueError, match="speed"):
        TeleopKeys(math.nan)
    with pytest.raises(ValueError, match="frame"):
        TeleopKeys(frame="world")


def test_keys_of_splits_characters_and_tells_a_lone_escape_from_a_sequence() -> None:
    assert keys_of("wwq") == ["w", "w", "q"]
    assert keys_of("\x1b") == [ESC]
    assert keys_of("w\x1b[Aw") == ["w", "w"], "an arrow key is no key"
    assert keys_of("\x1bOP") == [], "F1 is no key"
    assert keys_of("\x1b[1;5Cq") == ["q"]
    assert keys_of("\x1b\x1b") == [ESC, ESC]
    assert keys_of("\x03") == ["\x03"]


@given(st.text(max_size=40))
def test_keys_of_never_fails_and_the_machine_takes_anything(chunk: str) -> None:
    keys = TeleopKeys()
    for i, key in enumerate(keys_of(chunk)):
        keys.feed(key, i * 0.01)
    twist = keys.twist(0.0)
    assert all(math.isfinite(v) for v in (*twist.linear, *twist.angular))
    assert max(abs(v) for v in (*twist.linear, *twist.angular)) <= MAX_SPEED * ANGULAR_PER_LINEAR


def test_rotation_vector_of_quaternions() -> None:
    assert rotation_vector((0.0, 0.0, 0.0, 1.0)) == (0.0, 0.0, 0.0)
    half = math.sqrt(0.5)
    assert rotation_vector((0.0, 0.0, half, half)) == pytest.approx((0.0, 0.0, math.pi / 2))
    assert rotation_vector((0.0, 0.0, -half, -half)) == pytest.approx((0.0, 0.0, math.pi / 2))
    assert rotation_vector((1.0, 0.0, 0.0, 0.0)) == pytest.approx((math.pi, 0.0, 0.0))


def test_status_line_shows_the_pose_speed_frame_and_motion() -> None:
    keys = TeleopKeys(0.1, "tool")
    message = {"position": [0.5, -0.25, 1.0], "orientation": [0.0, 0.0, 0.0, 1.0]}
    line = status_line("alice", message, keys, 0.0)
    assert "x +0.5000 y -0.2500 z +1.0000 m" in line
    assert "0.100 m/s" in line
    assert "frame tool" in line
    assert line.endswith("stopped")
    keys.feed("e", 0.0)
    assert status_line("alice", None, keys, 0.0).endswith("+z")
    assert "waiting for tcp_pose" in status_line("alice", {"position": [None, 0, 0]}, keys, 0.0)
