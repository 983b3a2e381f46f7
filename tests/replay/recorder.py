"""A recorder for the replay tests, and the motion they record: every message a cell publishes, kept
as it arrived (with the joint states' ``cycle``, which a recording does not keep) and written into a
recording on demand; the comparison of a replay with its recording."""

from __future__ import annotations

import asyncio
import io
import json
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import zenoh

from urdaemon.client import Client
from urdaemon.recording.channels import recorded_keys
from urdaemon.recording.mcap_file import RecordingWriter

__all__ = ["Recorder", "State", "aligned_errors", "motion_starts", "record_motion", "settle"]

CELL = "testcell"
ALICE_A = [0.4, -1.3, 1.3, -1.4, -1.6, 0.3]
ALICE_B = [0.1, -1.45, 1.5, -1.6, -1.5, -0.1]
BOB_A = [-0.3, -1.7, 1.7, -1.6, -1.5, -0.2]


@dataclass(frozen=True)
class State:
    """One joint_states message as published."""

    cycle: int
    positions: tuple[float, ...]
    velocities: tuple[float, ...]


@dataclass
class Recorder:
    """Subscribes (on ``session``) to what a recorder of ``cell`` keeps; ``close`` ends it.

    Each subscriber fills a Zenoh FIFO channel (on Zenoh's side, without Python), emptied here when
    asked. On the daemon's own session (``record_motion``'s ``session``) it misses nothing: a put
    reaches a subscriber of its own session without a link, where the daemon's state publishers drop
    rather than wait when the machine is loaded (a recording with holes cannot be reproduced exactly:
    what the arm did in a hole is not in it)."""

    CAPACITY = 1_000_000

    session: Any
    cell: str
    received: list[tuple[str, bytes, int]] = field(default_factory=list)
    _lock: threading.Lock = field(default_factory=threading.Lock)
    _subs: list[Any] = field(default_factory=list)

    def start(self) -> Recorder:
        for key in recorded_keys(self.cell):
            self._subs.append(self.session.declare_subscriber(key, zenoh.handlers.FifoChannel(self.CAPACITY)))
        return self

    def _take(self) -> list[tuple[str, bytes, int]]:
        """Everything received so far, in the order it arrived on each key."""
        with self._lock:
            for sub in self._subs:
                for _ in range(self.CAPACITY):
                    sample = sub.try_recv()
                    if sample is None:
                        break
                    self.received.append((str(sample.key_expr), sample.payload.to_bytes(), time.time_ns()))
            return list(self.received)

    def close(self) -> None:
        self._take()
        for sub in self._subs:
            sub.undeclare()
        self._subs.clear()

    def states(self, robot: str) -> list[State]:
        """The robot's joint_states in the order they arrived (a `ur` robot's cycle count starts again
        when its control program reconnects)."""
        received = self._take()
        out = []
        for key, payload, _ in received:
            if key == f"{self.cell}/{robot}/joint_states":
                m = json.loads(payload)
                out.append(State(int(m["cycle"]), tuple(m["position"]), tuple(m["velocity"])))
        return out

    def write(self, path: Path, urdf: str | None) -> Path:
        """Everything received, as a recording (``RecordingWriter``)."""
        buffer = io.BytesIO()
        writer = RecordingWriter(buffer, cell=self.cell, urdf=urdf)
        received = self._take()
        for key, payload, receive_ns in received:
            writer.add(key, payload, receive_ns)
        writer.finish()
        path.write_bytes(buffer.getvalue())
        return path


def motion_starts(states: Sequence[State]) -> list[int]:
    """For each run of moving samples, the index of the rest sample just before it (0 for a run the
    states start with)."""
    starts = [0] if states and any(states[0].velocities) else []
    for i in range(1, len(states)):
        if any(states[i].velocities) and not any(states[i - 1].velocities):
            starts.append(i - 1)
    return starts


def aligned_errors(
    recorded: Sequence[State], replayed: Sequence[State], rate: float
) -> tuple[list[float], int]:
    """For each recorded sample of each move, the largest joint position error against the replayed
    sample at the same time offset ÷ rate, offsets counted from the move's fastest sample (its
    k-th move in both: a rest's length in cycles is not in a recording, whose time is the host's, and
    a cycle the mock missed makes the two differ; its fastest sample found in the replay by its
    positions), the move's offset shifted by the one of -1, 0, +1 cycle that fits best; and how many
    recorded samples had no replayed sample there (the subscriber missed them; samples after the last
    replayed one are left out)."""
    starts_r, starts_p = motion_starts(recorded), motion_starts(replayed)
    # the replay's first move may be its move to the recording's start (when the robot was not there)
    assert len(starts_p) - len(starts_r) in (0, 1), (
        f"{len(starts_r)} moves recorded, {len(starts_p)} replayed"
    )
    starts_p = starts_p[len(starts_p) - len(starts_r) :]
    by_cycle = {s.cycle: s for s in replayed}
    last = replayed[-1].cycle
    errors: list[float] = []
    missing = 0
    for k, (r0, p0) in enumerate(zip(starts_r, starts_p, strict=True)):
        end = starts_r[k + 1] if k + 1 < len(starts_r) else len(recorded)
        # the origin: the move's fastest sample (where a cycle moves the joints most), found in the
        # replay by its positions (the subscriber may have missed any one sample; a fake arm creeps
        # the last hair to where a goal starts, which makes the replay's move start earlier)
        stop_p = starts_p[k + 1] if k + 1 < len(starts_p) else len(replayed)
        anchor = max(recorded[r0:end], key=lambda s: max(abs(v) for v in s.velocities))
        base_r = anchor.cycle
        base_p = min(replayed[p0:stop_p], key=lambda s: _error(anchor, s)).cycle
        targets = [
            (state, base_p + round((state.cycle - base_r) / rate))
            for state in recorded[r0:end]
            if base_p + round((state.cycle - base_r) / rate) + 1 <= last
        ]
        best: tuple[float, list[float], int] | None = None
        for shift in (-1, 0, 1):
            found = [(state, by_cycle.get(target + shift)) for state, target in targets]
            errs = [_error(state, other) for state, other in found if other is not None]
            worst = max(errs, default=0.0)
            if best is None or worst < best[0]:
                best = (worst, errs, len(found) - len(errs))
        assert best is not None
        errors += best[1]
        missing += best[2]
    return errors, missing


def _error(a: State, b: State) -> float:
    return max(abs(x - y) for x, y in zip(a.positions, b.positions, strict=True))


async def settle(recorder: Recorder, robot: str, count: int) -> None:
    """Until ``count`` more joint_states of ``robot`` arrived (bounded)."""
    start = len(recorder.states(robot))
    for _ in range(500):
        if len(recorder.states(robot)) >= start + count:
            return
        await asyncio.sleep(0.01)
    raise AssertionError(f"{robot}: fewer than {count} joint_states arrived")


async def record_motion(client: Client, path: Path, session: Any = None) -> Recorder:
    """alice: two moves with a rest between; bob: one move while alice makes her first; recorded on
    ``session`` (default: the client's)."""
    recorder = Recorder(client.session if session is None else session, CELL).start()
    await settle(recorder, "alice", 20)
    alice, bob = await client.robot("alice"), await client.robot("bob")
    first, bobs = await asyncio.gather(alice.move(ALICE_A), bob.move(BOB_A))
    assert (await first.result(timeout=30))["status"] == "succeeded"
    assert (await bobs.result(timeout=30))["status"] == "succeeded"
    await settle(recorder, "alice", 40)
    second = await alice.move(ALICE_B)
    assert (await second.result(timeout=30))["status"] == "succeeded"
    await settle(recorder, "alice", 30)
    recorder.close()
    recorder.write(path, await client.robot_description(CELL))
    await alice.release()
    await bob.release()
    return recorder
