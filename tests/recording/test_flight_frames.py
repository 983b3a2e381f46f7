"""The flight recorder's pipe from tables: frames encoded and read back however the reads split
them, and bytes that are no frame refused."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from urdaemon.recording.flight_frames import (
    HEADER,
    MAX_PAYLOAD,
    REQUEST,
    SAMPLE,
    URDF,
    Frame,
    FrameError,
    FrameReader,
    encode_frame,
    encode_samples,
)

T = 1_764_350_000_123_456_789

FRAMES: list[Frame] = [
    (URDF, "", b"<robot name='c'/>", T),
    (SAMPLE, "c/alice/joint_states", b'{"position":[0.1]}', T),
    (SAMPLE, "c/alice/goal/\u00e9t\u00e9/result", b"", T + 1),
    (REQUEST, "", b'{"reason": "request", "id": "3"}', 0),
]


def _encoded(frames: list[Frame]) -> bytes:
    return b"".join(encode_frame(*frame) for frame in frames)


def test_a_frame_is_a_header_the_key_and_the_payload() -> None:
    data = encode_frame(SAMPLE, "c/a/io", b"{}", T)
    assert data == HEADER.pack(0, 6, 2, T) + b"c/a/io{}"
    assert HEADER.size == 15


def test_samples_of_a_batch_share_its_time() -> None:
    items = [("c/a/status", b"1"), ("c/b/status", b"22")]
    assert FrameReader().feed(encode_samples(items, T)) == [
        (SAMPLE, "c/a/status", b"1", T),
        (SAMPLE, "c/b/status", b"22", T),
    ]
    assert encode_samples([], T) == b""


@pytest.mark.parametrize("cut", [1, 7, 15, 16, 20, 40, 60])
def test_frames_split_across_reads_come_out_whole(cut: int) -> None:
    data = _encoded(FRAMES)
    reader = FrameReader()
    first = reader.feed(data[:cut])
    assert reader.pending == cut - sum(len(encode_frame(*f)) for f in first)
    assert first + reader.feed(data[cut:]) == FRAMES
    assert reader.pending == 0


@given(st.lists(st.integers(min_value=1, max_value=40), max_size=30))
def test_any_split_reads_the_same_frames(sizes: list[int]) -> None:
    data = _encoded(FRAMES)
    reader = FrameReader()
    out: list[Frame] = []
    at = 0
    for size in sizes:
        out += reader.feed(data[at : at + size])
        at += size
    out += reader.feed(data[at:])
    assert out == FRAMES


@pytest.mark.parametrize(
    ("data", "error"),
    [
        (HEADER.pack(7, 0, 0, T), "unknown frame kind 7"),
        (HEADER.pack(SAMPLE, 1, MAX_PAYLOAD + 1, T), "exceeds"),
        (HEADER.pack(SAMPLE, 2, 0, T) + b"\xff\xfe", "not UTF-8"),
        (encode_frame(SAMPLE, "k", b"x", T) + b"garbage that is no header", "unknown frame kind"),
    ],
)
def test_bytes_that_are_no_frame_are_refused(data: bytes, error: str) -> None:
    with pytest.raises(FrameError, match=error):
        FrameReader().feed(data)
