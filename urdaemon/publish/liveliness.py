"""The daemon's watch of liveliness tokens: only the keys it asked about, fed on Zenoh's threads, the
loop told of a change at most once at a time (``ZenohNode.liveliness_watch`` makes it; the lease
keeper uses it, runtime/lease_keeper.py)."""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

import zenoh

__all__ = ["LivelinessWatch"]


class LivelinessWatch:
    """Whether the liveliness tokens of the keys the daemon asked about are present (thread-safe).

    Interest only: the daemon ``watch``es a key (a lease holder's, an acquire's) and ``unwatch``es it
    when done; a sample of any other key is dropped on Zenoh's thread, never stored nor handed to
    the loop, so the state kept is bounded by the keys asked about, whatever tokens others declare.
    A watched key is present, gone, or not heard of yet (a token declared before the key was
    watched: ``probe`` asks Zenoh for it). At most one "changed" call waits for the loop, however
    many watched tokens come and go meanwhile.
    """

    def __init__(self, notify: Callable[[], bool], ask: Callable[[str], None] | None = None) -> None:
        self._lock = threading.Lock()
        self._wanted: dict[str, int] = {}
        """Each watched key and how many of the daemon's parts watch it."""
        self._present: dict[str, bool] = {}
        """What was heard of each watched key (missing: nothing yet)."""
        self._notify = notify
        self._ask = ask
        self._pending = False
        self.changed: Callable[[], None] = lambda: None
        """Runs on the loop after a change (set by the node)."""
        self.ignored = 0
        """Samples of keys nobody watched, dropped (a count, nothing kept of them)."""

    def watch(self, key: str) -> None:
        """Keep what is heard of ``key`` from now on (until as many ``unwatch`` calls)."""
        with self._lock:
            self._wanted[key] = self._wanted.get(key, 0) + 1

    def unwatch(self, key: str) -> None:
        """One part of the daemon no longer cares about ``key``; the last forgets it."""
        with self._lock:
            count = self._wanted.get(key, 0) - 1
            if count > 0:
                self._wanted[key] = count
            else:
                self._wanted.pop(key, None)
                self._present.pop(key, None)

    def probe(self, key: str) -> None:
        """Ask Zenoh whether the token ``key`` (watched) is there already; the answer arrives off the
        loop, as a sample would (``heard``)."""
        if self._ask is not None:
            self._ask(key)

    def alive(self, key: str) -> bool:
        """Whether the watched token ``key`` is present."""
        with self._lock:
            return self._present.get(key, False)

    def on_sample(self, sample: Any) -> None:
        """A token came (PUT) or went (DELETE): on Zenoh's thread."""
        self._record(str(sample.key_expr), sample.kind != zenoh.SampleKind.DELETE, overwrite=True)

    def heard(self, key: str) -> None:
        """A liveliness query found the token ``key`` (on Zenoh's thread). It counts only if no sample
        of the key arrived since it was watched: a DELETE after the answer was made wins."""
        self._record(key, True, overwrite=False)

    def _record(self, key: str, present: bool, *, overwrite: bool) -> None:
        with self._lock:
            if key not in self._wanted:
                self.ignored += 1
                return
            if not overwrite and key in self._present:
                return
            self._present[key] = present
            notify, self._pending = not self._pending, True
        if notify and not self._notify():
            with self._lock:
                self._pending = False

    def handed(self) -> None:
        """On the loop: tell ``changed`` (changes arriving from now on ask for another call)."""
        with self._lock:
            self._pending = False
        self.changed()
