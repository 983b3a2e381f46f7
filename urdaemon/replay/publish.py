"""``urdaemon replay FILE --publish``: the recorded cell, published again with no robot moving.

Every recorded message goes out on its key (``mcap_file.key_of``) at its recorded log time, the gaps
divided by the rate, as the daemon published it (what the recording has no field for, e.g.
``controller_time`` and ``cycle`` of a joint state, is ``null`` or left out). So that ``urdaemon
view``, ``urdaemon echo`` and a ``Client`` see the recorded cell as they see a served one, the
replay also stands in for what they ask the daemon (docs/replay.md):

- each recorded robot's liveliness token ``<cell>/<robot>/alive`` (how ``Client.robots`` and the view
  find the robots), declared before the first message and undeclared at the end;
- ``<cell>/robot_description``, answered with the recorded URDF;
- ``<cell>/<robot>/lease``, answered with a refusal saying the cell is a recording (so the view's
  enable, a ``move`` or ``lease`` say why, at once, instead of waiting for a daemon).

Goal feedback and results go out without the signature they had (a recording keeps no attachment):
``urdaemon.client`` does not take them as a goal's, which is right, as no goal of its runs.

A cell that a daemon serves is refused: its live messages would mix with the recorded ones.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import json
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, TextIO

import zenoh

from urdaemon.publish.keys import CellKeys, RobotKeys
from urdaemon.recording.mcap_file import Recorded, key_of
from urdaemon.replay.source import RecordedCell

__all__ = ["LEASE_REFUSAL", "Republisher", "served_robots"]

LEASE_REFUSAL = (
    "lease: cell {cell!r} is a recording replayed by `urdaemon replay --publish`: nothing commands its robots"
)
_AHEAD_S = 0.0005
"""Messages due within this much of now go out together (one wake-up for a cycle's messages)."""


def served_robots(session: Any, cell: str, timeout: float = 1.0) -> list[str]:
    """The robots of ``cell`` a daemon serves, seen by their liveliness tokens (blocking)."""
    found = []
    for reply in session.liveliness().get(f"{cell}/*/alive", timeout=timeout):
        if reply.ok is not None:
            found.append(str(reply.ok.key_expr).split("/")[1])
    return sorted(set(found))


@dataclass
class Republisher:
    """Publishes ``recorded`` on ``session`` at ``rate``; ``published`` counts what went out."""

    session: Any
    recorded: RecordedCell
    rate: float
    err: TextIO
    published: int = 0
    _declared: list[Any] = field(default_factory=list)

    def robots(self) -> list[str]:
        """Every robot a recorded message is about."""
        names = set(self.recorded.names)
        for topic in self.recorded.topics:
            parts = topic.split("/")
            if len(parts) >= 4 and parts[2] not in ("goal", "tf", "robot_description"):
                names.add(parts[2])
        return sorted(names)

    def declare(self) -> None:
        """The robots' liveliness tokens and the queryables a viewer asks (undone by ``close``)."""
        cell = self.recorded.cell
        for robot in self.robots():
            keys = RobotKeys(cell, robot)
            self._declared.append(self.session.liveliness().declare_token(keys.alive))
            self._declared.append(self.session.declare_queryable(keys.lease, self._refuse_lease))
        if self.recorded.urdf:
            key = CellKeys(cell).robot_description
            self._declared.append(self.session.declare_queryable(key, self._answer_urdf))

    def close(self) -> None:
        """Undeclare the tokens and queryables."""
        for entity in reversed(self._declared):
            with contextlib.suppress(Exception):
                entity.undeclare()
        self._declared.clear()

    def _answer_urdf(self, query: Any) -> None:  # on Zenoh's thread
        if str(query.key_expr) == CellKeys(self.recorded.cell).robot_description and self.recorded.urdf:
            query.reply(query.key_expr, self.recorded.urdf.encode())

    def _refuse_lease(self, query: Any) -> None:  # on Zenoh's thread
        reason = LEASE_REFUSAL.format(cell=self.recorded.cell)
        query.reply(
            query.key_expr, json.dumps({"v": 1, "ok": False, "reason": reason, "lease": None}).encode()
        )

    async def wait_for_subscriber(self) -> None:
        """Until some session subscribes to a recorded robot's joint_states (or, with none, any key)."""
        keys = [RobotKeys(self.recorded.cell, r).joint_states for r in self.recorded.robots] or [
            key_of(m.topic, m.message) for m in itertools.islice(self.recorded.messages(), 1)
        ]
        loop = asyncio.get_running_loop()
        matched = asyncio.Event()

        def on_matching(status: Any) -> None:  # on Zenoh's thread
            if status.matching:
                with contextlib.suppress(RuntimeError):  # the loop has closed
                    loop.call_soon_threadsafe(matched.set)

        publishers = [self.session.declare_publisher(key) for key in keys]
        listeners = [p.declare_matching_listener(on_matching) for p in publishers]
        try:
            if not any(p.matching_status.matching for p in publishers):
                await matched.wait()
        finally:
            for entity in (*listeners, *publishers):
                with contextlib.suppress(Exception):
                    entity.undeclare()

    async def run(self) -> None:
        """Publish every recorded message at its time (the first at once)."""
        loop = asyncio.get_running_loop()
        messages = self.recorded.messages()
        record = next(messages, None)
        if record is None:
            return
        first, start = record.log_time_ns, loop.time()
        while record is not None:
            wait = self._due(start, first, record) - loop.time()
            if wait > _AHEAD_S:
                await asyncio.sleep(wait)
            now = loop.time()
            while record is not None and self._due(start, first, record) <= now + _AHEAD_S:
                self._put(record)
                record = next(messages, None)

    def _due(self, start: float, first_ns: int, record: Recorded) -> float:
        """When (loop time) ``record`` goes out: its recorded offset divided by the rate."""
        return start + (record.log_time_ns - first_ns) * 1e-9 / self.rate

    def _put(self, record: Recorded) -> None:
        payload = json.dumps(record.message, separators=(",", ":")).encode()
        self.session.put(
            key_of(record.topic, record.message), payload, congestion_control=zenoh.CongestionControl.BLOCK
        )
        self.published += 1


def replay_session_config(listen: Sequence[str], connect: Sequence[str]) -> Any:
    """A peer session that listens where viewers connect, and joins ``connect`` (if any)."""
    from urdaemon.publish.session_config import zenoh_config

    return zenoh_config("peer", list(listen), list(connect))


async def publish_recording(
    recorded: RecordedCell,
    rate: float,
    listen: Sequence[str],
    connect: Sequence[str],
    wait: bool,
    err: TextIO,
) -> int:
    """``--publish``: refuse a served cell, declare, (wait for a subscriber,) publish; the exit code."""
    loop = asyncio.get_running_loop()
    try:
        session = await loop.run_in_executor(None, zenoh.open, replay_session_config(listen, connect))
    except zenoh.ZError as error:
        from urdaemon.client import zenoh_message

        print(
            f"error: cannot open a Zenoh session listening on {', '.join(listen)}: {zenoh_message(error)}",
            file=err,
        )
        return 1
    try:
        if connect:
            await _peer(session)
        served = await loop.run_in_executor(None, served_robots, session, recorded.cell)
        if served:
            print(
                f"error: cell {recorded.cell!r} is served by a daemon (robots alive: {', '.join(served)}; "
                f"seen through {', '.join(connect) or ', '.join(listen)}): its live messages would mix with "
                "the recording's; stop that daemon, or publish where it is not reached",
                file=err,
            )
            return 1
        republisher = Republisher(session, recorded, rate, err)
        republisher.declare()
        try:
            if wait:
                print("waiting for a subscriber to the recorded joint states", file=err)
                await republisher.wait_for_subscriber()
            print(
                f"publishing {recorded.count} recorded messages of cell {recorded.cell!r} at rate {rate:g}",
                file=err,
            )
            started = time.monotonic()
            await republisher.run()
            print(
                f"published {republisher.published} messages in {time.monotonic() - started:.3f} s", file=err
            )
        finally:
            republisher.close()
    finally:
        await loop.run_in_executor(None, session.close)
    return 0


async def _peer(session: Any, timeout: float = 5.0) -> None:
    """Wait (bounded) until the session reached a peer or router it connects to."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout
    while not (list(session.info.peers_zid()) or list(session.info.routers_zid())):
        if loop.time() > deadline:
            return
        await asyncio.sleep(0.05)
