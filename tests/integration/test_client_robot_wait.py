"""``Client.robot(name)`` waits while a starting daemon's robots still appear (issue 32).

Reproduction: benchmarks/control_loop.py with 8 robots failed with ``NoSuchRobot r5``: some but not
all of a starting daemon's robots were listed, and after 3 polls the client gave up. Counted polls of
a stand-in list, no daemon: a list that keeps growing is waited for; one that stays the same without
the robot is answered ``NoSuchRobot`` after ``STABLE_POLLS`` polls.
"""

from __future__ import annotations

import asyncio

import pytest

from urdaemon.client import Client, NoSuchRobot
from urdaemon.client.cell_connection import STABLE_POLLS


class Listing(Client):
    """A client whose served robots are a script: one list per poll, the last one repeated."""

    def __init__(self, lists: list[list[tuple[str, str]]]) -> None:
        super().__init__(None, asyncio.get_running_loop(), "tcp/127.0.0.1:1")
        self.lists = lists
        self.polls = 0

    async def robots(self, *, timeout: float = 2.0) -> list[tuple[str, str]]:
        served = self.lists[min(self.polls, len(self.lists) - 1)]
        self.polls += 1
        return served


def _first(n: int) -> list[tuple[str, str]]:
    return [("bench", f"r{i}") for i in range(1, n + 1)]


async def test_a_list_that_still_grows_is_waited_for() -> None:
    client = Listing([_first(1), _first(2), _first(3), _first(4), _first(5), _first(8)])
    robot = await client.robot("r5", timeout=30.0)
    assert robot.keys.base == "bench/r5"
    assert client.polls == 5


async def test_a_list_that_grows_slowly_is_waited_for_between_arrivals() -> None:
    lists = [_first(1)] * (STABLE_POLLS - 1) + [_first(2)] * (STABLE_POLLS - 1) + [_first(3)]
    client = Listing(lists)
    await client.robot("r3", timeout=30.0)
    assert client.polls == len(lists)


async def test_a_stable_list_without_the_robot_is_answered_at_once() -> None:
    client = Listing([_first(2)])
    with pytest.raises(NoSuchRobot) as caught:
        await client.robot("carol", timeout=30.0)
    assert client.polls == STABLE_POLLS + 1  # the first sighting, then STABLE_POLLS unchanged
    assert caught.value.robots == _first(2)
