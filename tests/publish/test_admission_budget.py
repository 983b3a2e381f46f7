"""The budgets and the tarpit that bound what a flood of wildcard queries costs (admission.py)."""

from __future__ import annotations

from typing import Any

from urdaemon.publish.admission import Budget, Tarpit


class Now:
    """A time source the test advances."""

    def __init__(self) -> None:
        self.t = 50.0

    def __call__(self) -> float:
        return self.t


class Query:
    """Stands in for a Zenoh query: counts its end."""

    def __init__(self) -> None:
        self.dropped = 0

    def drop(self) -> None:
        self.dropped += 1


def test_a_budget_allows_its_burst_at_once_then_its_rate() -> None:
    now = Now()
    budget = Budget(100.0, clock=now)
    assert sum(budget.take() for _ in range(1000)) == 100
    assert budget.dropped == 900
    now.t += 0.5
    assert sum(budget.take() for _ in range(1000)) == 50
    now.t += 3600.0  # a long quiet spell refills the burst, no more
    assert sum(budget.take() for _ in range(1000)) == 100


def test_widening_a_budget_raises_its_burst_and_its_level_now() -> None:
    now = Now()
    budget = Budget(100.0, clock=now)
    budget.widen(180)
    budget.widen(50)  # never narrows
    assert budget.burst == 180
    assert sum(budget.take() for _ in range(1000)) == 180


def test_the_tarpit_holds_queries_for_their_time_and_ends_all_on_release() -> None:
    now = Now()
    pit = Tarpit(hold_s=5.0, size=3, clock=now)
    queries = [Query() for _ in range(5)]
    pit.hold(queries[0])
    pit.hold(queries[1])
    assert [q.dropped for q in queries] == [0, 0, 0, 0, 0]
    now.t += 5.0
    pit.hold(queries[2])  # the first two were held long enough: they end now
    assert [q.dropped for q in queries[:3]] == [1, 1, 0]
    pit.hold(queries[3])
    pit.hold(queries[4])
    pit.hold(Query())  # past its size the oldest ends at once
    assert queries[2].dropped == 1
    assert len(pit) == 3
    pit.release()
    assert len(pit) == 0
    assert all(q.dropped == 1 for q in queries)


def test_a_query_that_fails_to_end_does_not_stop_the_others() -> None:
    class Gone:
        def drop(self) -> Any:
            raise RuntimeError("the querier left")

    now = Now()
    pit = Tarpit(hold_s=0.0, size=10, clock=now)
    pit.hold(Gone())
    last = Query()
    pit.hold(last)
    pit.release()
    assert last.dropped == 1
