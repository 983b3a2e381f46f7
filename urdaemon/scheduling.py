"""What keeps the daemon's event loop thread on time: real-time scheduling (``realtime_priority`` in
the cell file) and no pauses of Python's cyclic garbage collector over the objects of startup.

The loop thread clocks every robot: while it waits for a core behind other processes, packages
queue up and turnarounds grow by whole scheduler time slices (milliseconds). Under ``SCHED_FIFO``
it runs as soon as a package arrives. Only that thread is raised: Zenoh's threads, started before,
keep the normal policy, and threads the loop thread starts later begin with the normal policy too
(``SCHED_RESET_ON_FORK``). Linux keeps 5 % of every second for other processes
(``/proc/sys/kernel/sched_rt_runtime_us``), so a runaway loop cannot lock the machine up.

The collector's full collections walk every container object the process has. After startup
(the cell model, the URDF and its XML, pydantic's validators, Zenoh's bindings, argparse) that is
about 100 000 objects, and one full collection stops the loop for 40–70 ms: 20–35 cycles at 500 Hz
with no command sent, enough to let a robot program's reverse-socket read time out on a loaded
machine. Full collections come when enough new objects have outlived two younger collections, for
example when a long trajectory goal is decoded. :func:`startup_objects_frozen` moves everything
alive once startup is done into the collector's permanent generation (``gc.freeze``), so later
collections walk only what was made since.
"""

from __future__ import annotations

import asyncio
import contextlib
import gc
import os
import sys
import weakref
from collections.abc import Callable, Iterator

from urdaemon.errors import UrDaemonError

__all__ = ["RealtimeUnavailable", "realtime_request", "startup_objects_frozen", "use_realtime_priority"]

_REQUESTS: weakref.WeakKeyDictionary[asyncio.AbstractEventLoop, tuple[int, str | None]] = (
    weakref.WeakKeyDictionary()
)
"""Per event loop (the daemon asks from its loop's thread): the priority last asked of
``use_realtime_priority`` and why it was refused (None: it took); gone with the loop."""


class RealtimeUnavailable(UrDaemonError, OSError):
    """The calling thread could not be given the real-time priority; the message says why."""


def use_realtime_priority(priority: int) -> Callable[[], None]:
    """Run the calling thread under ``SCHED_FIFO`` at ``priority`` (1–99); returns what puts the
    thread's previous policy back (call it on the same thread).

    Raises :class:`RealtimeUnavailable` where the platform has no ``SCHED_FIFO`` or the process may
    not use it (it needs ``CAP_SYS_NICE`` or an ``rtprio`` limit of at least ``priority``).
    """
    if not 1 <= priority <= 99:
        raise ValueError(f"realtime priority must be between 1 and 99, got {priority}")
    fifo = getattr(os, "SCHED_FIFO", None)
    setter = getattr(os, "sched_setscheduler", None)
    if fifo is None or setter is None or not sys.platform.startswith("linux"):
        raise RealtimeUnavailable(f"SCHED_FIFO is not available on {sys.platform}")
    before = os.sched_getscheduler(0), os.sched_getparam(0)
    try:
        setter(0, fifo | os.SCHED_RESET_ON_FORK, os.sched_param(priority))
    except OSError as err:
        _remember(priority, err.strerror or str(err))
        raise RealtimeUnavailable(
            f"not permitted to use SCHED_FIFO priority {priority} ({err.strerror}): give the user an "
            f"rtprio limit of at least {priority} (/etc/security/limits.conf, or LimitRTPRIO= in a "
            "systemd unit, or --ulimit rtprio= / cap_add SYS_NICE in a container) or the "
            "CAP_SYS_NICE capability"
        ) from err
    _remember(priority, None)

    def restore() -> None:
        setter(0, *before)
        _remember(0, None)

    return restore


def realtime_request() -> tuple[int, str | None]:
    """What was asked of ``use_realtime_priority`` on the running event loop's thread (0: nothing,
    or it was put back), and why it was refused (None: it took, or nothing was asked)."""
    loop = _running_loop()
    return (0, None) if loop is None else _REQUESTS.get(loop, (0, None))


def _remember(priority: int, refused: str | None) -> None:
    """Keep what was asked for the running loop (nothing outside one: no daemon asked it)."""
    loop = _running_loop()
    if loop is None:
        return
    if priority:
        _REQUESTS[loop] = (priority, refused)
    else:
        _REQUESTS.pop(loop, None)


def _running_loop() -> asyncio.AbstractEventLoop | None:
    try:
        return asyncio.get_running_loop()
    except RuntimeError:
        return None


@contextlib.contextmanager
def startup_objects_frozen() -> Iterator[int]:
    """Collect once, then keep every object alive now out of later collections (``gc.freeze``) until
    the block ends (``gc.unfreeze``); yields how many objects were frozen.

    Objects made later are collected as before, cyclic garbage included. The permanent generation
    is the process's own: leaving the block unfreezes whatever any caller froze.
    """
    gc.collect()
    gc.freeze()
    try:
        yield gc.get_freeze_count()
    finally:
        gc.unfreeze()
