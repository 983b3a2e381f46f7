"""The running bridge: ``running_bridge`` connects to a cell, advertises its channels on a Foxglove
WebSocket server (foxglove-sdk) and serves them until the block ends. The command and the tests both
start it here.

Threads: Foxglove's threads only hand a client's subscribe and unsubscribe to this asyncio loop
(``_Listener``); the loop declares a channel's Zenoh subscriber when its first Foxglove subscriber
comes and undeclares it when the last one goes, so the daemon computes nothing (tf, tcp_pose) for a
channel no one watches. Zenoh's threads only queue each sample's bytes (``handoff.py``, bounded:
dropped and counted when full); the converter thread turns them into Foxglove messages
(``convert.py``) and logs them. The URDF is sent again to every new subscriber of its channel
(latched, as ``robot_state_publisher`` does) and served as the ``/robot_description`` parameter.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import threading
import time
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, cast

from urdaemon.cell_lookup import cell_description, served_cell
from urdaemon.client import Client, default_holder
from urdaemon.foxglove_bridge.channel_plan import ChannelPlan, channel_plan
from urdaemon.foxglove_bridge.convert import description_record, records_of
from urdaemon.foxglove_bridge.handoff import Handoff
from urdaemon.recording.channels import DESCRIPTION_TOPIC
from urdaemon.recording.tf_tree import joint_links

if TYPE_CHECKING:
    from foxglove.websocket import ServerListener

__all__ = ["DESCRIPTION_PARAMETER", "Bridge", "running_bridge"]

log = logging.getLogger("urdaemon.foxglove")

DESCRIPTION_PARAMETER = "/robot_description"
"""The parameter Foxglove's 3-D panel loads a URDF from by itself."""
TAKE_TIMEOUT_S = 0.2
"""The converter thread looks whether it should stop at least this often."""


@dataclass
class Bridge:
    """A running bridge: its ``url`` (ws://host:port), ``port``, the ``cell``, its ``robots`` and the
    ``plans`` of its channels; counts of what went through."""

    url: str
    port: int
    cell: str
    robots: list[str]
    plans: list[ChannelPlan]
    handoff: Handoff
    logged: int = 0
    """Foxglove messages logged."""
    failed: int = 0
    """Samples that could not be converted (logged once per distinct reason)."""
    subscriptions: dict[str, int] = field(default_factory=dict)
    """Foxglove subscribers per topic now."""
    following: set[str] = field(default_factory=set)
    """Topics whose Zenoh key is followed now (those with a Foxglove subscriber)."""


@contextlib.asynccontextmanager
async def running_bridge(
    target: Client | str,
    *,
    host: str = "127.0.0.1",
    port: int = 8765,
    cell: str | None = None,
    zenoh_config: str | None = None,
) -> AsyncIterator[Bridge]:
    """Serve the cell at ``target`` (a connected client, or an endpoint to connect to) over Foxglove's
    WebSocket protocol on ``host``:``port`` (0: a port the OS chooses) until the block ends. Raises
    ``ImportError`` without foxglove-sdk, ``UrDaemonError`` when no cell answers."""
    import foxglove

    async with contextlib.AsyncExitStack() as stack:
        if isinstance(target, Client):
            client = target
        else:
            holder = default_holder("urdaemon foxglove")
            client = await Client.connect(target, config_file=zenoh_config, holder=holder)
            stack.push_async_callback(client.close)
        cell, robots = await served_cell(client, cell)
        urdf = await cell_description(client, cell)
        joints = joint_links(urdf)
        handoff = Handoff()
        plans = channel_plan(cell, robots)
        context = foxglove.Context()
        channels = {
            plan.topic: foxglove.Channel(
                plan.topic,
                schema=foxglove.Schema(
                    name=plan.schema.name, encoding=plan.schema.encoding, data=plan.schema.data
                ),
                message_encoding=plan.message_encoding,
                context=context,
            )
            for plan in plans
        }
        loop = asyncio.get_running_loop()
        served = _Served(loop, client.session, plans, channels, handoff, DESCRIPTION_TOPIC, urdf)
        server = foxglove.start_server(
            name=f"urdaemon {cell}",
            host=host,
            port=port,
            capabilities=[foxglove.websocket.Capability.Parameters],
            server_listener=cast("ServerListener", _Listener(served, urdf)),  # implements the parts it needs
            context=context,
        )
        stack.callback(served.close)  # after the server: no subscription can come in any more
        stack.callback(server.stop)
        bridge = Bridge(f"ws://{_url_host(host)}:{server.port}", server.port, cell, robots, plans, handoff)
        served.bridge = bridge
        worker = threading.Thread(target=served.convert, args=(joints,), name="foxglove-convert", daemon=True)
        worker.start()
        stack.callback(worker.join, 5.0)
        stack.callback(served.stop.set)
        yield bridge


class _Served:
    """The channels, their Zenoh subscribers (on the loop) and the converter (on its thread)."""

    def __init__(
        self,
        loop: asyncio.AbstractEventLoop,
        session: Any,
        plans: list[ChannelPlan],
        channels: dict[str, Any],
        handoff: Handoff,
        description_topic: str,
        urdf: str,
    ) -> None:
        self.loop = loop
        self.session = session
        self.plans = {channels[p.topic].id(): p for p in plans}
        self.channels = channels
        self.handoff = handoff
        self.description_topic = description_topic
        self.urdf = urdf
        self.subscribers: dict[str, Any] = {}
        self.stop = threading.Event()
        self.bridge: Bridge | None = None
        self._reasons: set[str] = set()
        self._resend = threading.Event()
        self._closed = False

    # ------------------------------------------------------------------ on the loop

    def want(self, channel_id: int, delta: int) -> None:
        """A Foxglove client subscribed (``delta`` 1) or unsubscribed (-1) to a channel."""
        plan = self.plans.get(channel_id)
        if plan is None or self.bridge is None or self._closed:
            return
        counts = self.bridge.subscriptions
        now = counts[plan.topic] = max(0, counts.get(plan.topic, 0) + delta)
        if plan.key_expr is None:
            if delta > 0:
                self._resend.set()  # latched: every new subscriber gets the URDF
            return
        if now > 0 and plan.topic not in self.subscribers:
            self.subscribers[plan.topic] = self.session.declare_subscriber(
                plan.key_expr, self.handoff.on_sample
            )
            self.bridge.following.add(plan.topic)
            log.info("following %s for %s", plan.key_expr, plan.topic)
        elif now == 0 and plan.topic in self.subscribers:
            _undeclare(self.subscribers.pop(plan.topic))
            self.bridge.following.discard(plan.topic)
            log.info("no longer following %s", plan.key_expr)

    def close(self) -> None:
        """Undeclare every Zenoh subscriber; none is declared afterwards."""
        self._closed = True
        for sub in self.subscribers.values():
            _undeclare(sub)
        self.subscribers.clear()
        if self.bridge is not None:
            self.bridge.following.clear()

    # ------------------------------------------------------------------ on the converter thread

    def convert(self, joints: tuple[tuple[str, str], ...]) -> None:
        """The converter thread: samples taken from the handoff, converted and logged, until ``stop``."""
        while not self.stop.is_set():
            if self._resend.is_set():
                self._resend.clear()
                self._log([description_record(self.description_topic, self.urdf, time.time_ns())])
            item = self.handoff.take(TAKE_TIMEOUT_S)
            if item is None:
                continue
            key, payload, received = item
            try:
                records = records_of(key, payload, received, joints)
            except (ValueError, KeyError, TypeError) as err:
                self._failed(f"{key}: {type(err).__name__}: {err}")
                continue
            self._log(records)

    def _log(self, records: list[tuple[str, bytes, int]]) -> None:
        for topic, data, log_time in records:
            channel = self.channels.get(topic)
            if channel is None:
                continue
            channel.log(data, log_time=log_time)
            if self.bridge is not None:
                self.bridge.logged += 1

    def _failed(self, reason: str) -> None:
        if self.bridge is not None:
            self.bridge.failed += 1
        cause = reason.split(":", 1)[-1]
        if cause not in self._reasons and len(self._reasons) < 100:
            self._reasons.add(cause)
            log.warning("a message was not served: %s", reason[:300])


class _Listener:
    """foxglove-sdk's ``ServerListener``: on Foxglove's threads, it only hands subscriptions to the
    loop; the URDF parameter is answered from a string kept since the start."""

    def __init__(self, served: _Served, urdf: str) -> None:
        self._served = served
        self._urdf = urdf

    def _hand(self, fn: Callable[[int, int], None], channel_id: int, delta: int) -> None:
        with contextlib.suppress(RuntimeError):  # the loop has closed: the bridge is stopping
            self._served.loop.call_soon_threadsafe(fn, channel_id, delta)

    def on_subscribe(self, client: Any, channel: Any) -> None:
        self._hand(self._served.want, int(channel.id), 1)

    def on_unsubscribe(self, client: Any, channel: Any) -> None:
        self._hand(self._served.want, int(channel.id), -1)

    def on_get_parameters(
        self, client: Any, param_names: list[str], request_id: str | None = None
    ) -> list[Any]:
        import foxglove

        if param_names and DESCRIPTION_PARAMETER not in param_names:
            return []
        return [foxglove.Parameter(DESCRIPTION_PARAMETER, value=self._urdf)]

    def on_set_parameters(
        self, client: Any, parameters: list[Any], request_id: str | None = None
    ) -> list[Any]:
        """Parameters are read-only here: the URDF is the daemon's; the answer is the value kept."""
        return self.on_get_parameters(client, [DESCRIPTION_PARAMETER], request_id)


def _undeclare(sub: Any) -> None:
    with contextlib.suppress(Exception):
        sub.undeclare()


def _url_host(host: str) -> str:
    if host in ("0.0.0.0", "::", ""):
        return "127.0.0.1"
    return f"[{host}]" if ":" in host else host
