"""The handoff from Zenoh's threads never waits: past its capacity a sample is dropped and counted."""

from __future__ import annotations

import threading

from urdaemon.foxglove_bridge.handoff import Handoff


def test_full_drops_and_counts_and_keeps_the_order() -> None:
    handoff = Handoff(capacity=3)
    kept = [handoff.offer(f"k{i}", bytes([i])) for i in range(5)]
    assert kept == [True, True, True, False, False]
    assert (handoff.offered, handoff.dropped) == (5, 2)
    taken = [handoff.take(0.0) for _ in range(4)]
    assert [t[:2] if t else None for t in taken] == [("k0", b"\x00"), ("k1", b"\x01"), ("k2", b"\x02"), None]


def test_offers_from_many_threads_are_all_counted() -> None:
    handoff = Handoff(capacity=100)
    barrier = threading.Barrier(4)

    def offer() -> None:
        barrier.wait(10)
        for i in range(100):
            handoff.offer("k", bytes([i % 256]))

    threads = [threading.Thread(target=offer) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(30)
    taken = 0
    while handoff.take(0.0) is not None:
        taken += 1
    assert taken == 100
    assert handoff.dropped == 300
