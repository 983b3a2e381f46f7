"""The flight recorder's process: ``python -m urdaemon.recording.flight``, started and supervised by
the daemon (runtime/flight_recorder.py), never by hand.

It subscribes to everything the cell publishes (``recorded_keys``) over the daemon's own endpoint,
keeps the last seconds in a ring (flight_ring.py) and writes a burst's seconds before and after its
trigger to ``<dir>/<cell>_<time>_<reason>.mcap`` (named ``.partial`` until complete) with the shared
``RecordingWriter``, on a thread of its own so the ring goes on meanwhile. The daemon's loop never
touches the ring, the conversion or the disk: they cost this process's memory and CPU, not its.

Its stdin takes one JSON line per request from the daemon: ``{"reason": "internal_error"}``, or
``{"reason": "request", "id": "3"}`` for a client's query; stdin closing ends it. Its stdout says, one
JSON line each: ``{"ready": true}`` once subscribed; ``{"written": PATH, "reasons": [...], "requests":
[...], "messages": N}`` per file; ``{"failed": TEXT, "reasons": [...], "requests": [...]}`` when a
file could not be written. What it logs goes to stderr (the daemon's).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import logging
import os
import signal
import sys
import threading
import time
from collections import deque
from pathlib import Path
from typing import IO, Any

from urdaemon.recording.channels import recorded_keys
from urdaemon.recording.flight_ring import Burst, Bursts, Ring, Triggers, file_name
from urdaemon.recording.mcap_file import RecordingWriter
from urdaemon.recording.subscription import Inbox, subscribe

__all__ = ["QUIET_S", "FlightProcess", "main"]

log = logging.getLogger("urdaemon.flight")

QUIET_S = 10.0
"""Stream triggers this soon after a burst's last one are the same incident: no second file."""
IDLE_WAIT_S = 0.02
CONNECT_TIMEOUT_S = 10.0


class FlightProcess:
    """The ring, the triggers and the files of one cell, fed from ``session``."""

    def __init__(self, session: Any, args: argparse.Namespace, out: IO[str]) -> None:
        self._session = session
        self._cell: str = args.cell
        self._dir = Path(args.dir)
        self._ring_s: float = args.ring_s
        self._ring = Ring(args.ring_s + args.after_s, args.max_mb * 1_000_000)
        self._triggers = Triggers()
        self._bursts = Bursts(args.after_s, QUIET_S)
        self._inbox = Inbox()
        self._requests: deque[tuple[str, str | None]] = deque()
        self._due: deque[Burst] = deque()
        self._writing: threading.Thread | None = None
        self._stdin_closed = threading.Event()
        self._out = out
        self._out_lock = threading.Lock()
        self._urdf: str | None = None

    def run(self, stdin: IO[str]) -> None:
        """Record until ``stdin`` closes; then write what is due and return."""
        self._urdf = self._fetch_urdf()
        subscribers = subscribe(self._session, recorded_keys(self._cell), self._inbox)
        threading.Thread(target=self._read_requests, args=(stdin,), name="flight-stdin", daemon=True).start()
        self._say({"ready": True})
        log.info("flight recorder of %r: keeping %g s in %s", self._cell, self._ring_s, self._dir)
        try:
            while not self._stdin_closed.is_set():
                if not self._step(time.time_ns()):
                    time.sleep(IDLE_WAIT_S)
        finally:
            for subscriber in subscribers:
                with contextlib.suppress(Exception):
                    subscriber.undeclare()
        self._finish()

    def _step(self, now_ns: int) -> bool:
        items = self._inbox.take()
        ring, check, bursts = self._ring, self._triggers.check, self._bursts
        for key, payload, receive_ns in items:
            ring.add(key, payload, receive_ns)
            reason = check(key, payload)
            if reason is not None:
                log.info("trigger: %s", reason)
                bursts.trigger(reason, receive_ns)
        while self._requests:
            reason, request = self._requests.popleft()
            bursts.trigger(reason, now_ns, request)
        burst = bursts.due(now_ns)
        if burst is not None:
            self._due.append(burst)
        if self._due and (self._writing is None or not self._writing.is_alive()):
            self._start_write(self._due.popleft())
        return bool(items)

    def _read_requests(self, stdin: IO[str]) -> None:
        for line in stdin:
            try:
                request = json.loads(line)
                reason = str(request.get("reason") or "request")
                ident = request.get("id")
                self._requests.append((reason, None if ident is None else str(ident)))
            except (ValueError, AttributeError):
                log.warning("flight recorder: a request is not a JSON object: %.80r", line)
        self._stdin_closed.set()

    def _finish(self) -> None:
        """The daemon is stopping: write the open burst now, and whatever is due."""
        self._step(time.time_ns())  # what arrived last, and the last requests
        burst = self._bursts.due(sys.maxsize)
        if burst is not None:
            self._due.append(burst)
        if self._writing is not None:
            self._writing.join()
        while self._due:
            self._write(self._due.popleft(), self._ring.snapshot())

    def _start_write(self, burst: Burst) -> None:
        snapshot = self._ring.snapshot()
        self._writing = threading.Thread(target=self._write, args=(burst, snapshot), name="flight-write")
        self._writing.start()

    def _write(self, burst: Burst, items: list[tuple[str, bytes, int]]) -> None:
        path = self._dir / file_name(self._cell, burst.first_ns, burst.reason)
        partial = path.with_name(path.name + ".partial")
        told = {"reasons": burst.reasons, "requests": burst.requests}
        try:
            if self._urdf is None:
                self._urdf = self._fetch_urdf()
            self._dir.mkdir(parents=True, exist_ok=True)
            with partial.open("wb") as stream:
                writer = RecordingWriter(stream, cell=self._cell, urdf=self._urdf, metadata=_metadata(burst))
                for key, payload, receive_ns in items:
                    writer.add(key, payload, receive_ns)
                writer.finish()
            os.replace(partial, path)
        except OSError as err:
            with contextlib.suppress(OSError):
                partial.unlink()
            self._say({"failed": f"cannot write {path}: {err.strerror or err}", **told})
            return
        written = sum(writer.counts.written.values())
        self._say({"written": str(path), "messages": written, **told})

    def _fetch_urdf(self) -> str | None:
        try:
            for reply in self._session.get(f"{self._cell}/robot_description", timeout=5.0):
                if reply.ok is not None:
                    return str(reply.ok.payload.to_string())
        except Exception as err:  # the file is still worth writing without it
            log.warning("flight recorder: no cell URDF: %s", err)
        return None

    def _say(self, message: dict[str, Any]) -> None:
        with self._out_lock:
            self._out.write(json.dumps(message) + "\n")
            self._out.flush()


def _metadata(burst: Burst) -> dict[str, str]:
    return {"flight_record": ",".join(burst.reasons), "trigger_ns": str(burst.first_ns)}


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m urdaemon.recording.flight")
    p.add_argument("--connect", required=True)
    p.add_argument("--cell", required=True)
    p.add_argument("--dir", required=True)
    p.add_argument("--ring-s", type=float, required=True)
    p.add_argument("--after-s", type=float, default=1.0)
    p.add_argument("--max-mb", type=int, default=512)
    p.add_argument("--low-latency", action="store_true")
    return p


def main(argv: list[str] | None = None) -> int:
    """Run the flight recorder until stdin closes."""
    import zenoh

    from urdaemon.publish.node import zenoh_config

    args = _parser().parse_args(argv)
    # the daemon ends this process by closing its stdin (after it wrote what is due): a Ctrl-C or a
    # SIGTERM meant for the daemon must not cut a file short
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    logging.basicConfig(
        stream=sys.stderr, level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s"
    )
    conf = zenoh_config("peer", [], [args.connect], low_latency=args.low_latency)
    conf.insert_json5("connect/timeout_ms", json.dumps(int(CONNECT_TIMEOUT_S * 1000)))
    conf.insert_json5("transport/shared_memory/enabled", "false")
    try:
        session = zenoh.open(conf)
    except zenoh.ZError as err:
        log.error("flight recorder: cannot connect to %s: %s", args.connect, err)
        return 1
    deadline = time.monotonic() + CONNECT_TIMEOUT_S
    while not (list(session.info.peers_zid()) or list(session.info.routers_zid())):
        if time.monotonic() > deadline:
            log.error("flight recorder: nothing answered at %s within %g s", args.connect, CONNECT_TIMEOUT_S)
            session.close()  # type: ignore[no-untyped-call]
            return 1
        time.sleep(0.05)
    try:
        FlightProcess(session, args, sys.stdout).run(sys.stdin)
    finally:
        session.close()  # type: ignore[no-untyped-call]
    return 0


if __name__ == "__main__":
    sys.exit(main())
