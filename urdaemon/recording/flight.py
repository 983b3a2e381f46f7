"""The flight recorder's process: ``python -m urdaemon.recording.flight``, started and supervised by
the daemon (runtime/flight_recorder.py), never by hand.

The daemon feeds it through its stdin, a binary pipe of frames (flight_frames.py): the cell URDF first,
then every message the daemon publishes, in batches about every 50 ms, and its requests. It keeps the
last seconds in a ring (flight_ring.py) and writes a burst's seconds before and after its trigger to
``<dir>/<cell>_<time>_<reason>.mcap`` (named ``.partial`` until complete) with the shared
``RecordingWriter``, on a thread of its own so the ring goes on meanwhile. It has no Zenoh session:
the daemon's loop never touches the ring, the conversion or the disk, and nothing of the cell's Zenoh
setup (mode, TLS, access control) concerns it.

A request frame carries ``{"reason": "internal_error"}``, or ``{"reason": "request", "id": "3"}`` for
a client's query; stdin closing ends it (exit code 0), a frame that cannot be read too (logged, exit
code 1: only the daemon writes the pipe, so that is a bug). Its stdout says, one JSON line each:
``{"ready": true}`` once it reads its stdin; ``{"written": PATH, "reasons": [...], "requests": [...],
"messages": N}`` per file; ``{"failed": TEXT, "reasons": [...], "requests": [...]}`` when a file could
not be written. What it logs goes to stderr (the daemon's).
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

from urdaemon.errors import DescriptionError
from urdaemon.recording.flight_frames import REQUEST, SAMPLE, URDF, FrameError, FrameReader
from urdaemon.recording.flight_ring import Burst, Bursts, Ring, Triggers, file_name
from urdaemon.recording.mcap_file import RecordingWriter
from urdaemon.recording.subscription import Inbox

__all__ = ["QUIET_S", "FlightProcess", "main"]

log = logging.getLogger("urdaemon.flight")

QUIET_S = 10.0
"""Stream triggers this soon after a burst's last one are the same incident: no second file."""
IDLE_WAIT_S = 0.02
READ_BYTES = 1 << 20
"""The most read from the pipe at once."""


class FlightProcess:
    """The ring, the triggers and the files of one cell, fed from the daemon's pipe."""

    def __init__(self, args: argparse.Namespace, out: IO[str]) -> None:
        self._cell: str = args.cell
        self._dir = Path(args.dir)
        self._ring_s: float = args.ring_s
        self._ring = Ring(args.ring_s + args.after_s, args.max_mb * 1_000_000)
        self._triggers = Triggers()
        self._bursts = Bursts(args.after_s, QUIET_S)
        self._inbox = Inbox()
        self._requests: deque[tuple[str, str | None]] = deque()
        self._due: deque[tuple[Burst, list[tuple[str, bytes, int]]]] = deque()
        """Closed bursts, each with its window, waiting for the writer thread."""
        self._writing: threading.Thread | None = None
        self._stdin_closed = threading.Event()
        self._broken: str | None = None
        """Why the pipe could not be read (a frame that is none), if so."""
        self._out = out
        self._out_lock = threading.Lock()
        self._urdf: str | None = None

    def run(self, stdin: IO[bytes]) -> int:
        """Record until ``stdin`` closes; then write what is due. The exit code: 1 after a frame that
        could not be read."""
        threading.Thread(target=self._read_frames, args=(stdin,), name="flight-stdin", daemon=True).start()
        self._say({"ready": True})
        log.info("flight recorder of %r: keeping %g s in %s", self._cell, self._ring_s, self._dir)
        while not self._stdin_closed.is_set():
            if not self._step(time.time_ns()):
                time.sleep(IDLE_WAIT_S)
        self._finish()
        if self._broken is not None:
            log.error("flight recorder: stopped reading its pipe: %s", self._broken)
            return 1
        return 0

    def _step(self, now_ns: int) -> bool:
        items = self._inbox.take()
        ring, check, bursts = self._ring, self._triggers.check, self._bursts
        for key, payload, receive_ns in items:
            ring.add(key, payload, receive_ns)
            reason = check(key, payload)
            if reason is not None:
                log.info("trigger: %s", reason)
                bursts.trigger(reason, receive_ns)
            if bursts.open is not None:  # the stream reached its end: its window, before what follows
                self._close(bursts.due(receive_ns, 0))
        while self._requests:
            reason, request = self._requests.popleft()
            bursts.trigger(reason, now_ns, request)
        self._close(bursts.due(ring.newest_ns, now_ns))
        if self._due and (self._writing is None or not self._writing.is_alive()):
            burst, window = self._due.popleft()
            self._writing = threading.Thread(target=self._write, args=(burst, window), name="flight-write")
            self._writing.start()
        return bool(items)

    def _close(self, burst: Burst | None) -> None:
        """Queue a closed burst's file with its window now: the ring's seconds before its first
        trigger, and what came after it."""
        if burst is not None:
            self._due.append((burst, self._ring.snapshot(burst.first_ns - int(self._ring_s * 1e9))))

    def _read_frames(self, stdin: IO[bytes]) -> None:
        reader = FrameReader()
        read = getattr(stdin, "read1", stdin.read)
        offer = self._inbox.offer
        try:
            while data := read(READ_BYTES):
                for kind, key, payload, time_ns in reader.feed(data):
                    if kind == SAMPLE:
                        offer(key, payload, time_ns)
                    elif kind == REQUEST:
                        self._request(payload)
                    elif kind == URDF:
                        self._urdf = payload.decode(errors="replace")
            if reader.pending:
                log.warning("flight recorder: the pipe ended inside a frame (%d bytes)", reader.pending)
        except (FrameError, OSError) as err:
            self._broken = str(err)
        finally:
            self._stdin_closed.set()

    def _request(self, payload: bytes) -> None:
        try:
            request = json.loads(payload)
            reason = str(request.get("reason") or "request")
            ident = request.get("id")
            self._requests.append((reason, None if ident is None else str(ident)))
        except (ValueError, AttributeError):
            log.warning("flight recorder: a request is not a JSON object: %.80r", payload)

    def _finish(self) -> None:
        """The daemon is stopping: write the open burst now, and whatever is due."""
        while self._step(time.time_ns()):  # what arrived last, and the last requests
            pass
        self._close(self._bursts.due(sys.maxsize, sys.maxsize))
        if self._writing is not None:
            self._writing.join()
        while self._due:
            self._write(*self._due.popleft())

    def _write(self, burst: Burst, items: list[tuple[str, bytes, int]]) -> None:
        path = self._dir / file_name(self._cell, burst.first_ns, burst.reason)
        partial = path.with_name(path.name + ".partial")
        told = {"reasons": burst.reasons, "requests": burst.requests}
        try:
            self._dir.mkdir(parents=True, exist_ok=True)
            with partial.open("wb") as stream:
                writer = RecordingWriter(stream, cell=self._cell, urdf=self._urdf, metadata=_metadata(burst))
                for key, payload, receive_ns in items:
                    writer.add(key, payload, receive_ns)
                writer.finish()
            os.replace(partial, path)
        except (OSError, DescriptionError) as err:  # a URDF the writer cannot read fails this file too
            with contextlib.suppress(OSError):
                partial.unlink()
            self._say({"failed": f"cannot write {path}: {getattr(err, 'strerror', None) or err}", **told})
            return
        written = sum(writer.counts.written.values())
        self._say({"written": str(path), "messages": written, **told})

    def _say(self, message: dict[str, Any]) -> None:
        with self._out_lock:
            self._out.write(json.dumps(message) + "\n")
            self._out.flush()


def _metadata(burst: Burst) -> dict[str, str]:
    return {"flight_record": ",".join(burst.reasons), "trigger_ns": str(burst.first_ns)}


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m urdaemon.recording.flight")
    p.add_argument("--cell", required=True)
    p.add_argument("--dir", required=True)
    p.add_argument("--ring-s", type=float, required=True)
    p.add_argument("--after-s", type=float, default=1.0)
    p.add_argument("--max-mb", type=int, default=512)
    return p


def main(argv: list[str] | None = None) -> int:
    """Run the flight recorder until stdin closes."""
    args = _parser().parse_args(argv)
    # the daemon ends this process by closing its stdin (after it wrote what is due): a Ctrl-C or a
    # SIGTERM meant for the daemon must not cut a file short
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    logging.basicConfig(
        stream=sys.stderr, level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s"
    )
    return FlightProcess(args, sys.stdout).run(sys.stdin.buffer)


if __name__ == "__main__":
    sys.exit(main())
