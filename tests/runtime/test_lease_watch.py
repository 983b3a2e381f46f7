"""The watch of lease holders' liveliness tokens (publish/node.py ``LivelinessWatch``), fed samples as
Zenoh's thread would: bounded in tokens kept and in calls waiting for the loop."""

from __future__ import annotations

from dataclasses import dataclass

import pytest
import zenoh

from urdaemon.publish import node
from urdaemon.publish.node import LivelinessWatch


@dataclass
class Sample:
    key_expr: str
    kind: zenoh.SampleKind


def came(key: str) -> Sample:
    return Sample(key, zenoh.SampleKind.PUT)


def went(key: str) -> Sample:
    return Sample(key, zenoh.SampleKind.DELETE)


def test_many_changes_ask_the_loop_once_until_it_ran() -> None:
    asked: list[int] = []

    def notify() -> bool:
        asked.append(1)
        return True

    watch = LivelinessWatch(notify)
    seen: list[bool] = []
    watch.changed = lambda: seen.append(watch.alive("c/alice/lease/s1"))
    for n in range(100):
        watch.on_sample(came(f"c/alice/lease/s{n}"))
    watch.on_sample(went("c/alice/lease/s2"))
    assert len(asked) == 1, "one call waits for the loop, however many tokens came"
    watch.handed()
    assert seen == [True]
    assert not watch.alive("c/alice/lease/s2")
    watch.on_sample(went("c/alice/lease/s1"))
    assert len(asked) == 2, "a change after the loop ran asks again"
    watch.handed()
    assert seen == [True, False]


def test_tokens_beyond_the_bound_are_not_kept_but_a_token_going_always_is(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(node, "MAX_WATCHED_TOKENS", 3)
    watch = LivelinessWatch(lambda: True)
    for n in range(5):
        watch.on_sample(came(f"k/{n}"))
    assert [watch.alive(f"k/{n}") for n in range(5)] == [True, True, True, False, False]
    assert watch.dropped == 2
    watch.on_sample(went("k/0"))
    assert not watch.alive("k/0")
    watch.on_sample(came("k/4"))
    assert watch.alive("k/4"), "room again once a token went"


def test_a_closed_loop_does_not_leave_the_watch_waiting_forever() -> None:
    answers = iter([False, True])
    asked: list[int] = []

    def notify() -> bool:
        asked.append(1)
        return next(answers)

    watch = LivelinessWatch(notify)
    watch.on_sample(came("k/1"))  # the loop could not be told
    watch.on_sample(came("k/2"))  # so the next change asks again
    assert len(asked) == 2
