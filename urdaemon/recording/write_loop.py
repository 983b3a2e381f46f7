"""``urdaemon record``'s one writer thread: takes what the subscriptions put in the inbox, converts it
and writes it with ``RecordingWriter``, ending a chunk every ``flush_s`` seconds so a recording cut
short loses at most that much (``recover.py``).

A write that fails (a full disk: ``OSError`` ENOSPC, an unwritable file) stops the thread; the error
is kept for the command to report, and nothing more is written.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

from urdaemon.recording.mcap_file import RecordingWriter
from urdaemon.recording.subscription import Inbox

__all__ = ["WriteLoop"]

IDLE_WAIT_S = 0.02
"""How long the thread sleeps when the inbox is empty (the inbox has no wake-up: no lock on Zenoh's side)."""


class WriteLoop:
    """Drains ``inbox`` into ``writer`` on its own thread until ``stop``; ``keep(key)`` filters."""

    def __init__(
        self,
        inbox: Inbox,
        writer: RecordingWriter,
        *,
        keep: Callable[[str], bool] | None = None,
        flush_s: float = 2.0,
    ) -> None:
        self._inbox = inbox
        self._writer = writer
        self._keep = keep
        self._flush_s = flush_s
        self._stopping = threading.Event()
        self.error: OSError | None = None
        """The write that failed, if one did (the thread stopped there)."""
        self.taken = 0
        """Samples taken from the inbox."""
        self._thread = threading.Thread(target=self._run, name="urdaemon-record-writer", daemon=True)

    def start(self) -> None:
        """Start writing."""
        self._thread.start()

    def stop(self, timeout: float | None = None) -> None:
        """Write what is still in the inbox, then the file's summary; wait for the thread."""
        self._stopping.set()
        self._thread.join(timeout)

    @property
    def alive(self) -> bool:
        """Still writing (False once stopped, or after a failed write)."""
        return self._thread.is_alive()

    def _run(self) -> None:
        try:
            self._drain()
            self._writer.finish()
        except OSError as err:
            self.error = err

    def _drain(self) -> None:
        next_flush = time.monotonic() + self._flush_s
        while True:
            stopping = self._stopping.is_set()
            items = self._inbox.take()
            if items:
                self.taken += len(items)
                self._write(items)
            elif stopping:
                return
            else:
                time.sleep(IDLE_WAIT_S)
            now = time.monotonic()
            if now >= next_flush:
                self._writer.flush()
                next_flush = now + self._flush_s

    def _write(self, items: list[tuple[str, bytes, int]]) -> None:
        add, keep = self._writer.add, self._keep
        for key, payload, receive_ns in items:
            if keep is None or keep(key):
                add(key, payload, receive_ns)
