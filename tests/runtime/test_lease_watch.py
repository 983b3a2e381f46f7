"""The watch of lease tokens (publish/liveliness.py ``LivelinessWatch``), fed samples as Zenoh's thread
would: it keeps only the keys asked about, and at most one call waits for the loop."""

from __future__ import annotations

from dataclasses import dataclass

import zenoh

from urdaemon.publish.liveliness import LivelinessWatch


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
    for n in range(100):
        watch.watch(f"c/alice/lease/s{n}")
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


def test_tokens_nobody_watches_are_dropped_and_nothing_is_kept_of_them() -> None:
    """Review 16 M1 (a flood of 4096 tokens filled the watch and no acquire could be granted): a
    flood of tokens under keys nobody asked about keeps no state and asks nothing of the loop."""
    asked: list[int] = []

    def notify() -> bool:
        asked.append(1)
        return True

    watch = LivelinessWatch(notify)
    watch.watch("c/alice/lease/mine")
    for n in range(5000):
        watch.on_sample(came(f"c/zz/lease/s{n}"))
    assert watch.ignored == 5000, "every sample of a key nobody asked about dropped, none kept"
    assert asked == []
    assert not watch.alive("c/zz/lease/s0")
    watch.on_sample(came("c/alice/lease/mine"))
    assert watch.alive("c/alice/lease/mine")
    assert asked == [1]


def test_a_key_is_forgotten_when_the_last_part_watching_it_lets_go() -> None:
    watch = LivelinessWatch(lambda: True)
    watch.watch("k")
    watch.watch("k")
    watch.on_sample(came("k"))
    watch.unwatch("k")
    assert watch.alive("k"), "still watched once"
    watch.unwatch("k")
    assert not watch.alive("k")
    watch.on_sample(came("k"))
    assert watch.ignored == 1, "forgotten: its samples are dropped as anyone's"
    assert not watch.alive("k")
    watch.watch("k")
    assert not watch.alive("k"), "watched anew: nothing heard yet"


def test_a_probe_answer_counts_only_if_no_sample_came_since_the_key_was_watched() -> None:
    probed: list[str] = []
    watch = LivelinessWatch(lambda: True, probed.append)
    watch.watch("k")
    watch.probe("k")
    assert probed == ["k"]
    watch.heard("k")
    assert watch.alive("k")
    watch.watch("gone")
    watch.on_sample(went("gone"))
    watch.heard("gone")  # an answer made before the token went, arriving after its DELETE
    assert not watch.alive("gone")
    assert watch.ignored == 0
    watch.heard("unwatched")
    assert watch.ignored == 1, "an answer for a key nobody watches is dropped, nothing kept"
    assert not watch.alive("unwatched")


def test_a_closed_loop_does_not_leave_the_watch_waiting_forever() -> None:
    answers = iter([False, True])
    asked: list[int] = []

    def notify() -> bool:
        asked.append(1)
        return next(answers)

    watch = LivelinessWatch(notify)
    watch.watch("k/1")
    watch.watch("k/2")
    watch.on_sample(came("k/1"))  # the loop could not be told
    watch.on_sample(came("k/2"))  # so the next change asks again
    assert len(asked) == 2
