"""One robot's live plots: joint positions and velocities over the last ``WINDOW_S`` seconds.

The display task ``record``s the robot's newest joints at display rate (never per sample: a robot
publishes up to 500 Hz); the plots are redrawn every ``REDRAW_S``, a few times a second. A robot at
rest (every sample in the window the same) is redrawn only every ``REST_REDRAW_S`` while its window
fills, and not at all once the window is full of it: its flat lines would not change, and redrawing
them is most of what an open page costs the browser (0.54 of a core with two robots at rest,
0.13 without the plots; docs/performance.md).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from typing import Any

import numpy as np

from urdaemon.view.feed import JointSample

__all__ = ["REDRAW_S", "WINDOW_S", "JointPlots"]

WINDOW_S = 10.0
"""The plots show this many seconds."""
REDRAW_S = 0.25
"""The plots are sent to the page at most this often (4 Hz)."""
REST_REDRAW_S = 1.0
"""...and a robot at rest's plots at most this often, until its window is full."""
SAMPLE_S = 0.1
"""The plots keep one sample per this long (10 Hz): 10 s of six joints is ~100 points a line, a few
kB per redraw, whatever the robot's rate."""
KEPT = 200
"""Samples kept: 10 s at ``SAMPLE_S`` with room to spare."""
_COLORS = ("#e6194b", "#3cb44b", "#4363d8", "#f58231", "#911eb4", "#42d4f4", "#f032e6", "#9a6324")


class JointPlots:
    """Two uPlot charts in the current GUI container (the robot's folder)."""

    def __init__(self, gui: Any, joint_labels: Sequence[str]) -> None:
        self.labels = tuple(joint_labels)
        self._samples: deque[JointSample] = deque(maxlen=KEPT)
        self._drawn_at = float("-inf")
        self._rest_drawn: tuple[tuple[float, ...], tuple[float, ...], bool] | None = None
        """The joints of the robot at rest last drawn, and whether its window was full then."""
        empty = self._data([], "positions")
        scales = {"x": {"time": False}}  # seconds before now, not a date
        self.positions = gui.add_uplot(
            empty, self._series(), title="joint positions (rad), last 10 s", aspect=2.0, scales=scales
        )
        self.velocities = gui.add_uplot(
            empty, self._series(), title="joint velocities (rad/s)", aspect=2.0, scales=scales
        )

    def _series(self) -> tuple[dict[str, Any], ...]:
        lines = tuple(
            {"label": label, "stroke": _COLORS[i % len(_COLORS)], "width": 1.5}
            for i, label in enumerate(self.labels)
        )
        return ({"label": "s"}, *lines)

    def record(self, sample: JointSample | None) -> None:
        """Keep ``sample`` (the robot's newest joints) if ``SAMPLE_S`` passed since the one kept last."""
        if sample is None or len(sample.positions) != len(self.labels):
            return
        if self._samples and sample.received - self._samples[-1].received < SAMPLE_S:
            return
        self._samples.append(sample)

    def redraw(self, now: float) -> bool:
        """Send the last ``WINDOW_S`` seconds to the page if ``REDRAW_S`` has passed (for a robot at
        rest, as the module says); whether it did."""
        if now - self._drawn_at < REDRAW_S:
            return False
        while self._samples and now - self._samples[0].received > WINDOW_S:
            self._samples.popleft()
        shown = list(self._samples)
        rest = _at_rest(shown)
        if self._still(rest, now):
            return False
        self._drawn_at = now
        full = bool(shown) and shown[-1].received - shown[0].received >= WINDOW_S - 2 * SAMPLE_S
        self._rest_drawn = None if rest is None else (*rest, full)
        self.positions.data = self._data(shown, "positions")
        self.velocities.data = self._data(shown, "velocities")
        return True

    def _still(self, rest: tuple[tuple[float, ...], tuple[float, ...]] | None, now: float) -> bool:
        """Whether the robot is at rest where it was last drawn, and that drawing still stands (its
        window was full, or ``REST_REDRAW_S`` has not passed)."""
        drawn = self._rest_drawn
        if rest is None or drawn is None or rest != drawn[:2]:
            return False
        return drawn[2] or now - self._drawn_at < REST_REDRAW_S

    def _data(self, shown: Sequence[JointSample], field: str) -> tuple[np.ndarray, ...]:
        """(times relative to now, then one array per joint), as uPlot takes them."""
        count = len(self.labels)
        if not shown:
            return (np.zeros(0), *(np.zeros(0) for _ in range(count)))
        last = shown[-1].received
        times = np.array([s.received - last for s in shown])
        values = np.array([getattr(s, field) for s in shown]).reshape(len(shown), count)
        return (times, *(values[:, i].copy() for i in range(count)))


def _at_rest(shown: Sequence[JointSample]) -> tuple[tuple[float, ...], tuple[float, ...]] | None:
    """The positions and velocities every sample in ``shown`` has, or None (none, or they differ)."""
    if not shown:
        return None
    first = shown[0]
    if all(s.positions == first.positions and s.velocities == first.velocities for s in shown):
        return first.positions, first.velocities
    return None
