"""Feed a codec its input three ways: whole, split at every index, and one byte at a time."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar

__all__ = ["feed_all_ways", "feed_bytewise", "feed_split"]

C = TypeVar("C")


def feed_split(make: Callable[[], C], data: bytes, at: int) -> tuple[C, list[Any]]:
    """A fresh codec fed ``data[:at]`` then ``data[at:]``; the codec and all events."""
    conn = make()
    events = list(conn.receive_data(data[:at]))  # type: ignore[attr-defined]
    events += conn.receive_data(data[at:])  # type: ignore[attr-defined]
    return conn, events


def feed_bytewise(make: Callable[[], C], data: bytes) -> tuple[C, list[Any]]:
    """A fresh codec fed one byte at a time; the codec and all events."""
    conn = make()
    events: list[Any] = []
    for i in range(len(data)):
        events += conn.receive_data(data[i : i + 1])  # type: ignore[attr-defined]
    return conn, events


def feed_all_ways(make: Callable[[], Any], data: bytes) -> list[Any]:
    """The events of ``data`` fed whole; asserts every split and the bytewise feed give the same events."""
    whole = list(make().receive_data(data))
    for at in range(len(data) + 1):
        _, events = feed_split(make, data, at)
        assert events == whole, f"split at byte {at} gave {events!r}, whole gave {whole!r}"
    _, events = feed_bytewise(make, data)
    assert events == whole, f"bytewise feed gave {events!r}, whole gave {whole!r}"
    return whole
