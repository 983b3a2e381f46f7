"""The flight recorder's restart waits: longer for each death in a row, the first again after a process
that ran a minute (it died of something new)."""

from __future__ import annotations

import pytest

from urdaemon.runtime.flight_recorder import HEALTHY_RUN_S, RESTART_BACKOFF_S, restart_wait


@pytest.mark.parametrize(
    ("failures", "ran_s", "expected"),
    [
        (0, 0.5, (1, 1.0)),
        (1, 0.5, (2, 2.0)),
        (2, 0.5, (3, 5.0)),
        (4, 0.5, (5, 30.0)),
        (9, 0.5, (10, 30.0)),
        (0, HEALTHY_RUN_S + 1.0, (1, 1.0)),
        (7, HEALTHY_RUN_S + 1.0, (1, 1.0)),
    ],
)
def test_restart_waits(failures: int, ran_s: float, expected: tuple[int, float]) -> None:
    assert restart_wait(failures, ran_s) == expected


def test_the_waits_grow() -> None:
    assert list(RESTART_BACKOFF_S) == sorted(RESTART_BACKOFF_S)
