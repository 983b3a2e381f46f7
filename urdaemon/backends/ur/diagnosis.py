"""What the ``doctor`` service learns about one UR controller, on the event loop and bounded in time.

Over the dashboard link the robot already has (one command at a time, each waiting at most what is
left of the budget): ``PolyscopeVersion``, ``is in remote control``, then ``robotmode`` up to
``ROUND_TRIPS`` times, each timed. Meanwhile a task reads the host receive time and the controller's
timestamp of the newest RTDE package every ``SAMPLE_EVERY_S`` (two attribute reads: the cycle does
no work for it), which give the packages' arrival jitter and the clock offset; the drift is judged
against a pair taken soon after the RTDE link came up (``Diagnosis.watch``, called by the backend's
watch of its links). The links are read from ``UrLinks``, the callback ports from the servers.
Nothing here commands the robot: every dashboard line sent is a query.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import astuple
from typing import Any

from urdaemon.backends.ur.links import UrLinks
from urdaemon.backends.ur.program import ControlProgram
from urdaemon.backends.ur.servers import CallbackServers
from urdaemon.errors import UrDaemonError
from urdaemon.model import RobotState
from urdaemon.protocols import dashboard as dash

__all__ = [
    "BUDGET_S",
    "DETREND_AFTER_S",
    "REFERENCE_LOOKS",
    "ROUND_TRIPS",
    "SAMPLE_EVERY_S",
    "Diagnosis",
    "clock_facts",
]

BUDGET_S = 3.0
"""The whole diagnosis ends within about this long (a reply already asked for may take the dashboard
link's own timeout)."""
ROUND_TRIPS = 20
"""``robotmode`` queries timed for the round trip."""
SAMPLE_EVERY_S = 0.005
"""How often the newest RTDE package's two times are read while the diagnosis runs."""
DETREND_AFTER_S = 1.0
"""The reference's drift is taken out of the jitter once it is at least this old."""
REFERENCE_LOOKS = 8
"""How many of the link watch's looks (every ~0.25 s) choose the clocks' reference pair."""
MIN_WINDOW_S = 0.5
"""The clock is sampled at least this long, however fast the dashboard answered."""


class Diagnosis:
    """What the doctor learns of one UR controller: through its ``links`` (RTDE, primary, the
    dashboard's queries), from the ``state`` RTDE fills (a cycle of ``period`` s), and where the
    ``servers`` listen for the ``program`` of a ``headless`` robot or not."""

    def __init__(
        self,
        links: UrLinks,
        state: RobotState,
        *,
        period: float,
        headless: bool,
        servers: CallbackServers,
        program: ControlProgram,
    ) -> None:
        self.links = links
        self.state = state
        self.period = period
        self.headless = headless
        self.servers = servers
        self.program = program
        self.reference: tuple[int, float] | None = None
        """(host receive time ns, controller timestamp s) of a package soon after the RTDE link came up,
        the one that waited least of ``REFERENCE_LOOKS``: the baseline of the clocks' drift."""
        self._reference_link: object | None = None
        self._looks = 0

    def watch(self) -> None:
        """Look at the newest package's two times, the first ``REFERENCE_LOOKS`` times per RTDE link
        once packages come, and keep the pair that waited least (the backend's watch calls this every
        few hundred ms: the cycle does nothing for it)."""
        rtde, state = self.links.rtde, self.state
        if rtde is None or not rtde.packages or not state.host_time_ns:
            return
        if rtde is not self._reference_link:
            self._reference_link, self._looks, self.reference = rtde, 0, None
        if self._looks >= REFERENCE_LOOKS:
            return
        self._looks += 1
        pair = (state.host_time_ns, state.controller_time)
        if self.reference is None or _offset(pair) < _offset(self.reference):
            self.reference = pair

    async def gather(self, budget_s: float = BUDGET_S) -> dict[str, Any]:
        """The controller's facts as ``doctor.checks`` reads them (under ``"controller"``)."""
        loop = asyncio.get_running_loop()
        started = loop.time()
        deadline = started + budget_s
        samples: list[tuple[int, float]] = []
        stop = asyncio.Event()
        sampler = loop.create_task(_sample(self.state, samples, stop, deadline))
        try:
            board = await _dashboard(self.links.dashboard_query, deadline)
            window = max(0.0, min(deadline, started + MIN_WINDOW_S) - loop.time())
            await asyncio.wait({sampler}, timeout=window)
        finally:
            stop.set()
            await sampler
        facts = self.link_facts()
        facts["dashboard"] = board
        for name in ("polyscope_version", "remote_control", "remote_control_text"):
            facts[name] = board.pop(name, None)
        reference = self.reference if self._reference_link is self.links.rtde else None
        facts["clock"] = clock_facts(samples, reference, self.period)
        return facts

    def link_facts(self) -> dict[str, Any]:
        """The links, the controller's version RTDE reported, and the callback ports."""
        links = self.links
        rtde, primary = links.rtde, links.primary
        version = rtde.controller_version if rtde is not None else None
        return {
            "address": links.address,
            "headless": self.headless,
            "read_only": links.read_only,
            "links": {
                "rtde": rtde is not None and not rtde.closed.done(),
                "primary": primary is not None and not primary.closed.done(),
                "error": self.state.lifecycle_reason,
            },
            "rtde_version": None if version is None else list(astuple(version)),
            "callbacks": self.servers.facts(self.program.host_ip),
        }


async def _dashboard(query: Callable[[str, float], Awaitable[str]], deadline: float) -> dict[str, Any]:
    """The version, remote control and the timed round trips; ``connected`` once anything answered."""
    loop = asyncio.get_running_loop()
    facts: dict[str, Any] = {"connected": False, "error": None, "round_trips_ms": []}
    slowest = 0.0  # s: a query is sent only with twice the slowest one's time left, so none times out

    async def timed(line: str) -> str:
        nonlocal slowest
        sent = time.perf_counter()
        text = await query(line, deadline - loop.time())
        slowest = max(slowest, time.perf_counter() - sent)
        return text

    try:
        text = await timed(dash.GetPolyscopeVersion().line)
        facts["connected"] = True
        facts["polyscope"] = text
        version = dash.GetPolyscopeVersion().decode_reply(text).version
        facts["polyscope_version"] = list(version) if version else None
        text = await timed(dash.IsInRemoteControl().line)
        facts["remote_control"] = dash.IsInRemoteControl().decode_reply(text).remote
        facts["remote_control_text"] = text
        trips: list[float] = facts["round_trips_ms"]
        for _ in range(ROUND_TRIPS):
            # a query bound to time out would drop the dashboard link users' commands share
            left = deadline - loop.time()
            if left <= 0 or left < 2.0 * slowest:
                break
            sent = time.perf_counter()
            await timed(dash.GetRobotMode().line)
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
        await asyncio.sleep(SAMPLE_EVERY_S)


def clock_facts(
    samples: Sequence[tuple[int, float]], reference: tuple[int, float] | None, period_s: float
) -> dict[str, Any]:
    """The offset of the host's clock to the controller's at the last sample (that of the packages
    that waited least), the packages' arrival jitter (peak to peak of the offsets) and, against
    ``reference`` (a pair taken when RTDE came up), the drift with its bound: the reference's own
    delay may be anything within the jitter. With a reference at least ``DETREND_AFTER_S`` old, the
    offsets are first taken about the drift it shows, so drift is not counted as jitter."""
    facts: dict[str, Any] = {"samples": len(samples), "period_ms": period_s * 1e3, "offset_s": None}
    if len(samples) < 2:  # one package in the whole window: the stream stands still
        return facts
    last = samples[-1][0]
    offsets = [_offset(pair) for pair in samples]
    elapsed_ns = last - reference[0] if reference is not None else 0
    then = _offset(reference) if reference is not None else 0
    slope = (offsets[-1] - then) / elapsed_ns if elapsed_ns >= DETREND_AFTER_S * 1e9 else 0.0
    residuals = [o - round(slope * (host - last)) for o, (host, _) in zip(offsets, samples, strict=True)]
    low, high = min(residuals), max(residuals)
    facts["offset_s"] = low / 1e9
    facts["jitter_ms"] = (high - low) / 1e6
    facts["baseline_s"] = elapsed_ns / 1e9
    facts["drift_ppm"] = facts["drift_bound_ppm"] = None
    if elapsed_ns > 0:
        facts["drift_ppm"] = (low - then) / elapsed_ns * 1e6
        facts["drift_bound_ppm"] = (high - low) / elapsed_ns * 1e6
    return facts


def _offset(pair: tuple[int, float]) -> int:
    """The host's time less the controller's, in ns, of one (host ns, controller s) pair."""
    return pair[0] - round(pair[1] * 1e9)
