"""The plots' redraw rule on made-up samples (no page, no viser): a moving robot is redrawn every
``REDRAW_S``; a robot at rest every ``REST_REDRAW_S`` while its window fills, then not at all until it
moves again.

Reproduction on the code before: the plots were redrawn every ``REDRAW_S`` whatever the robot did,
so a robot at rest for 20 s was redrawn 80 times and
``test_a_robot_at_rest_is_drawn_while_its_window_fills_then_not_again`` fails.
"""

from __future__ import annotations

import itertools
from typing import Any

from urdaemon.view.feed import JointSample
from urdaemon.view.plots import REDRAW_S, REST_REDRAW_S, SAMPLE_S, WINDOW_S, JointPlots

NAMES = ("a", "b")
TICK = 1.0 / 30.0
"""The display task's period."""


class _Plot:
    def __init__(self) -> None:
        self.data: Any = None


class _Gui:
    def add_uplot(self, data: Any, series: Any, **_: Any) -> _Plot:
        return _Plot()


def _run(plots: JointPlots, start: float, seconds: float, position: Any) -> list[float]:
    """The display task for ``seconds`` from ``start`` with the robot at ``position(t)``; the times of
    the redraws."""
    drawn = []
    for i in range(round(seconds / TICK)):
        now = start + i * TICK
        p = position(now)
        plots.record(JointSample(NAMES, (p, 0.0), (0.0, 0.0), now))
        if plots.redraw(now):
            drawn.append(now)
    return drawn


def test_a_moving_robot_is_redrawn_every_redraw_period() -> None:
    plots = JointPlots(_Gui(), NAMES)
    drawn = _run(plots, 100.0, 20.0, lambda t: 0.01 * t)
    gaps = [b - a for a, b in itertools.pairwise(drawn)]
    assert len(drawn) >= 20.0 / (REDRAW_S + TICK)
    assert max(gaps) < REDRAW_S + 2 * TICK


def test_a_robot_at_rest_is_drawn_while_its_window_fills_then_not_again() -> None:
    plots = JointPlots(_Gui(), NAMES)
    drawn = _run(plots, 100.0, 2 * WINDOW_S, lambda t: 0.5)
    assert drawn[0] == 100.0
    gaps = [b - a for a, b in itertools.pairwise(drawn)]
    assert min(gaps) >= REST_REDRAW_S - TICK / 2
    assert drawn[-1] <= 100.0 + WINDOW_S + REST_REDRAW_S  # not redrawn once its window was full of rest
    times = plots.positions.data[0]
    assert times[0] <= -(WINDOW_S - 2 * SAMPLE_S)  # the last drawing shows the whole window
    assert len(drawn) <= WINDOW_S / REST_REDRAW_S + 2


def test_a_robot_that_moves_again_is_redrawn_at_once() -> None:
    plots = JointPlots(_Gui(), NAMES)
    _run(plots, 100.0, 2 * WINDOW_S, lambda t: 0.5)
    drawn = _run(plots, 100.0 + 2 * WINDOW_S, 1.0, lambda t: 0.6)
    assert drawn
    assert drawn[0] - (100.0 + 2 * WINDOW_S) < REDRAW_S
    assert plots.positions.data[1][-1] == 0.6
