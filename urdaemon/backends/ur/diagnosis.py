"""What the ``doctor`` service learns about one UR controller, on the event loop and bounded in time.

Over the dashboard link the robot already has (one command at a time, each waiting at most what is
left of the budget): ``PolyscopeVersion``, ``is in remote control``, then ``robotmode`` up to
``ROUND_TRIPS`` times, each timed. Meanwhile a task reads the host receive time and the controller's
timestamp of the newest RTDE package every ``SAMPLE_EVERY_S`` (two attribute reads: the cycle does
no work for it), which give the packages' arrival jitter and the clock offset; the drift is judged
against the pair the backend kept when its RTDE link came up (``clock_reference``). The links and
the callback ports are the backend's own facts (``UrBackend.link_facts``). Nothing here commands the
robot: every dashboard line sent is a query.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from urdaemon.errors import UrDaemonError
from urdaemon.protocols import dashboard as dash

if TYPE_CHECKING:
    from urdaemon.backends.ur.backend import UrBackend
    from urdaemon.model import RobotState

__all__ = ["BUDGET_S", "ROUND_TRIPS", "SAMPLE_EVERY_S", "clock_facts", "gather"]

BUDGET_S = 3.0
"""The whole diagnosis ends within about this long (a reply already asked for may take the dashboard
link's own timeout)."""
ROUND_TRIPS = 20
"""``robotmode`` queries timed for the round trip."""
SAMPLE_EVERY_S = 0.005
"""How often the newest RTDE package's two times are read while the diagnosis runs."""
MIN_WINDOW_S = 0.5
"""The clock is sampled at least this long, however fast the dashboard answered."""


async def gather(ur: UrBackend, budget_s: float = BUDGET_S) -> dict[str, Any]:
    """The controller's facts as ``doctor.checks`` reads them (under ``"controller"``)."""
    loop = asyncio.get_running_loop()
    started = loop.time()
    deadline = started + budget_s
    samples: list[tuple[int, float]] = []
    stop = asyncio.Event()
    sampler = loop.create_task(_sample(ur.state, samples, stop, deadline))
    try:
        board = await _dashboard(ur, deadline)
        await asyncio.wait({sampler}, timeout=max(0.0, min(deadline, started + MIN_WINDOW_S) - loop.time()))
    finally:
        stop.set()
        await sampler
    facts = ur.link_facts()
    facts["dashboard"] = board
    facts["polyscope_version"] = board.pop("polyscope_version", None)
    facts["remote_control"] = board.pop("remote_control", None)
    facts["remote_control_text"] = board.pop("remote_control_text", None)
    facts["clock"] = clock_facts(samples, ur.clock_reference, ur.period)
    return facts


async def _dashboard(ur: UrBackend, deadline: float) -> dict[str, Any]:
    """The version, remote control and the timed round trips; ``connected`` once anything answered."""
    loop = asyncio.get_running_loop()
    facts: dict[str, Any] = {"connected": False, "error": None, "round_trips_ms": []}
    try:
        text = await ur.dashboard_within(dash.GetPolyscopeVersion().line, deadline - loop.time())
        facts["connected"] = True
        facts["polyscope"] = text
        version = dash.GetPolyscopeVersion().decode_reply(text).version
        facts["polyscope_version"] = list(version) if version else None
        text = await ur.dashboard_within(dash.IsInRemoteControl().line, deadline - loop.time())
        facts["remote_control"] = dash.IsInRemoteControl().decode_reply(text).remote
        facts["remote_control_text"] = text
        trips: list[float] = facts["round_trips_ms"]
        for _ in range(ROUND_TRIPS):
            left = deadline - loop.time()
            if left <= 0:
                break
            sent = time.perf_counter()
            await ur.dashboard_within(dash.GetRobotMode().line, left)
            trips.append((time.perf_counter() - sent) * 1e3)
    except (UrDaemonError, OSError) as err:
        facts["error"] = str(err)
    return facts


async def _sample(
    state: RobotState, samples: list[tuple[int, float]], stop: asyncio.Event, deadline: float
) -> None:
    """Read the newest package's host receive time and controller timestamp until ``stop`` or the
    deadline (a package read twice is kept once)."""
    loop = asyncio.get_running_loop()
    last = None
    while not stop.is_set() and loop.time() < deadline:
        pair = (state.host_time_ns, state.controller_time)
        if pair[0] and pair != last:
            samples.append(pair)
            last = pair
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(stop.wait(), SAMPLE_EVERY_S)


def clock_facts(
    samples: Sequence[tuple[int, float]], reference: tuple[int, float] | None, period_s: float
) -> dict[str, Any]:
    """The offset of the host's clock to the controller's (the smallest of the samples', the package
    that waited least), the packages' arrival jitter (peak to peak of the offsets) and, against
    ``reference`` (a pair taken when RTDE came up), the drift with its bound: the reference's own
    delay may be anything within the jitter."""
    facts: dict[str, Any] = {"samples": len(samples), "period_ms": period_s * 1e3, "offset_s": None}
    if not samples:
        return facts
    offsets = [host - round(controller * 1e9) for host, controller in samples]
    low, high = min(offsets), max(offsets)
    facts["offset_s"] = low / 1e9
    facts["jitter_ms"] = (high - low) / 1e6
    facts["baseline_s"] = 0.0
    facts["drift_ppm"] = facts["drift_bound_ppm"] = None
    if reference is not None:
        elapsed_ns = samples[-1][0] - reference[0]
        facts["baseline_s"] = elapsed_ns / 1e9
        if elapsed_ns > 0:
            then = reference[0] - round(reference[1] * 1e9)
            facts["drift_ppm"] = (low - then) / elapsed_ns * 1e6
            facts["drift_bound_ppm"] = (high - low) / elapsed_ns * 1e6
    return facts
