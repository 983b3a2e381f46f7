"""The view itself: ``running_view`` connects to a cell, serves the page (viser) and runs the view's
two loops until the block ends. The ``urdaemon view`` command and the tests both start it here.

Threads: Zenoh's threads only keep the newest messages (``feed.py``); viser's threads only hand
commands to this asyncio loop (``panel.py``). On the loop, the display task draws the cell, the
TCP frames and the panels every ``DISPLAY_PERIOD_S`` (~30 Hz), and the stream task sends each
enabled robot's slider targets every ``STREAM_PERIOD_S`` (50 Hz). When the last page closes, every
robot is disabled (its lease released: the daemon stops it); when the view ends, likewise.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time
from collections.abc import AsyncIterator, Sequence
from dataclasses import dataclass, field
from functools import partial
from typing import Any

from urdaemon.cell_lookup import WAIT_S, cell_description, served_cell
from urdaemon.client import Client, default_holder
from urdaemon.errors import UrTimeoutError
from urdaemon.publish.keys import RobotKeys
from urdaemon.view.control import STREAM_PERIOD_S, RobotControl
from urdaemon.view.feed import RobotFeed
from urdaemon.view.panel import RobotPanel, problem_of
from urdaemon.view.scene import CellScene

__all__ = ["DISPLAY_PERIOD_S", "View", "running_view"]

log = logging.getLogger("urdaemon.view")

DISPLAY_PERIOD_S = 1.0 / 30.0
"""The scene and the panels are updated at ~30 Hz, whatever rate the robots publish at."""
LAST_PAGE_CLOSED = "the last page was closed"


@dataclass
class View:
    """A running view: its page's ``url``, the viser ``server`` (a test may set a client's camera
    through it), the ``scene``, and each robot's ``panels``, ``controls`` and ``feeds``."""

    url: str
    server: Any
    client: Client
    cell: str
    scene: CellScene
    feeds: dict[str, RobotFeed]
    controls: dict[str, RobotControl]
    panels: dict[str, RobotPanel]
    draws: int = 0
    """Display updates done."""
    moves: int = 0
    """Display updates that moved the scene (the robots' joints had changed)."""
    _drawn: asyncio.Event = field(default_factory=asyncio.Event)

    def draw(self, now: float) -> None:
        """One display update: links at the robots' newest joints, TCP frames, problems, panels."""
        positions: dict[str, float] = {}
        for feed in self.feeds.values():
            sample = feed.joints()
            if sample is not None:
                positions.update(zip(sample.names, sample.positions, strict=False))
        with self.server.atomic():
            if self.scene.place({k: v for k, v in positions.items() if math.isfinite(v)}):
                self.moves += 1
            for name, feed in self.feeds.items():
                status = feed.status()
                if status is not None:
                    self.scene.set_tcp(name, status.get("tcp"))
                self.scene.set_problem(name, problem_of(status, feed.stale(now)))
                self.panels[name].show(now)
        self.draws += 1
        self._drawn.set()

    async def drawn(self, timeout: float) -> None:
        """Wait for the next display update (``UrTimeoutError`` after ``timeout``)."""
        self._drawn.clear()
        try:
            await asyncio.wait_for(self._drawn.wait(), timeout)
        except TimeoutError as err:
            raise UrTimeoutError(f"the view drew nothing within {timeout:g} s") from err

    async def disable_all(self, reason: str = "") -> None:
        """Disable every robot (stop streaming, release the leases)."""
        for control in self.controls.values():
            if control.enabled or control.targets is not None:
                await control.disable(reason)


@contextlib.asynccontextmanager
async def running_view(
    target: Client | str,
    *,
    host: str = "127.0.0.1",
    port: int = 0,
    cell: str | None = None,
    zenoh_config: str | None = None,
) -> AsyncIterator[View]:
    """Serve the view of the cell at ``target`` (a connected client, or an endpoint to connect to)
    on ``host``:``port`` (0: any free port; a taken port: the next free one, as viser does) until
    the block ends. Raises ``ImportError`` without viser, ``UrDaemonError`` when no cell answers."""
    import viser

    async with contextlib.AsyncExitStack() as stack:
        if isinstance(target, Client):
            client = target
        else:
            holder = default_holder("urdaemon view")
            client = await Client.connect(target, config_file=zenoh_config, holder=holder)
            stack.push_async_callback(client.close)
        view = await _start(stack, client, viser, host, port, cell)
        tasks = [asyncio.create_task(_displaying(view)), asyncio.create_task(_streaming(view))]
        try:
            yield view
        finally:
            for task in tasks:
                task.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)
            await view.disable_all()


async def _start(
    stack: contextlib.AsyncExitStack, client: Client, viser: Any, host: str, port: int, cell: str | None
) -> View:
    """Everything of a view but its loops; what must be undone is pushed on ``stack``."""
    from urdaemon.description.urdf import load_urdf

    loop = asyncio.get_running_loop()
    cell, robots = await served_cell(client, cell)
    urdf = await loop.run_in_executor(None, load_urdf, await cell_description(client, cell))
    feeds = {name: RobotFeed(name) for name in robots}
    for name, feed in feeds.items():
        feed.subscribe(client.session, RobotKeys(cell, name), loop)
        stack.callback(feed.close)
    await _first_joint_states(feeds)
    server = await loop.run_in_executor(None, partial(viser.ViserServer, host=host, port=port, verbose=False))
    stack.callback(server.stop)
    scene = CellScene(server, urdf, robots)
    controls: dict[str, RobotControl] = {}
    panels: dict[str, RobotPanel] = {}
    for name, feed in feeds.items():
        control = controls[name] = RobotControl(await client.robot(name, cell=cell), feed.joints)
        feed.on_rejected = control.on_rejected
        panels[name] = RobotPanel(server.gui, loop, feed, control, joint_rows(urdf, feed, name))
    view = View(
        f"http://{_url_host(host)}:{server.get_port()}", server, client, cell, scene, feeds, controls, panels
    )

    def on_disconnect(_: Any) -> None:  # on viser's thread
        if not server.get_clients():
            asyncio.run_coroutine_threadsafe(view.disable_all(LAST_PAGE_CLOSED), loop)

    server.on_client_disconnect(on_disconnect)
    return view


async def _first_joint_states(feeds: dict[str, RobotFeed]) -> None:
    """Wait (bounded) for every robot's first joint_states: its joint names and order come from
    there. A robot that sends none in time is shown with the URDF's joints."""
    with contextlib.suppress(TimeoutError):
        await asyncio.wait_for(
            asyncio.gather(*(feed.first_joint_states.wait() for feed in feeds.values())), WAIT_S
        )


def joint_rows(urdf: Any, feed: RobotFeed, robot: str) -> list[tuple[str, float, float]]:
    """(joint, lower, upper) of each of the robot's joints, in its controller's order (its
    joint_states' names; else the URDF's movable joints named ``<robot>_*``)."""
    sample = feed.joints()
    if sample is not None:
        names: Sequence[str] = sample.names
    else:
        names = [n for n in urdf.actuated_joint_names if n.startswith(f"{robot}_")]
    rows = []
    for name in names:
        joint = urdf.joint_map.get(name)
        limit = None if joint is None or joint.type == "continuous" else joint.limit
        low = -2 * math.pi if limit is None or limit.lower is None else float(limit.lower)
        high = 2 * math.pi if limit is None or limit.upper is None else float(limit.upper)
        rows.append((name, low, high))
    return rows


def _url_host(host: str) -> str:
    if host in ("0.0.0.0", "::", ""):
        return "127.0.0.1"
    return f"[{host}]" if ":" in host else host


async def _displaying(view: View) -> None:
    """The display task: ``view.draw`` every ``DISPLAY_PERIOD_S``."""
    loop = asyncio.get_running_loop()
    next_tick = loop.time()
    while True:
        try:
            view.draw(time.monotonic())
        except Exception:  # a drawing bug must not end the view (nor the streams' safety)
            log.exception("drawing the view failed")
        next_tick = max(next_tick + DISPLAY_PERIOD_S, loop.time())
        await asyncio.sleep(next_tick - loop.time())


async def _streaming(view: View) -> None:
    """The stream task: each enabled robot's targets every ``STREAM_PERIOD_S``."""
    loop = asyncio.get_running_loop()
    next_tick = loop.time()
    while True:
        for control in view.controls.values():
            control.tick()
        next_tick = max(next_tick + STREAM_PERIOD_S, loop.time())
        await asyncio.sleep(next_tick - loop.time())
