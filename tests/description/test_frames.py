"""Rigid frames and UR poses (description/frames.py): the one definition every user shares."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from urdaemon.description.frames import IDENTITY, compose, frame_of_pose, inverse, pose_of_frame


@given(
    st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3),
    st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3),
    st.floats(0.0, math.pi),
)
def test_pose_frame_round_trip_up_to_a_half_turn(
    position: list[float], axis: list[float], angle: float
) -> None:
    norm = math.sqrt(sum(v * v for v in axis))
    if norm < 1e-3:
        return
    rotation = [v / norm * angle for v in axis]
    pose = (*position, *rotation)
    back = pose_of_frame(frame_of_pose(pose))
    again = frame_of_pose(back)
    assert list(again) == pytest.approx(list(frame_of_pose(pose)), abs=1e-9)
    identity = compose(frame_of_pose(pose), inverse(frame_of_pose(pose)))
    assert list(identity) == pytest.approx(list(IDENTITY), abs=1e-12)


def test_a_half_turn_keeps_its_axis() -> None:
    """Near a half turn the rotation vector is read off the symmetric part, not the (vanishing) sine."""
    for axis in ((1.0, 0.0, 0.0), (0.0, 0.6, 0.8), (0.48, -0.6, 0.64)):
        pose = (0.1, 0.2, 0.3, *(math.pi * a for a in axis))
        back = pose_of_frame(frame_of_pose(pose))
        assert math.dist(back[3:], pose[3:]) < 1e-12 or math.dist(back[3:], [-v for v in pose[3:]]) < 1e-12
