"""The facts about the daemon's host that decide whether its cycles come on time: the kernel (is it
PREEMPT_RT), whether the process may use ``SCHED_FIFO``, and the scheduling of the calling thread
(the ``doctor`` service calls this on the event loop thread, so that is the loop's).

It reads only: ``uname``, ``/sys/kernel/realtime``, ``RLIMIT_RTPRIO``, the capability set in
``/proc/self/status`` and the thread's policy; it tries no policy change. What the cell file asked
for (``realtime_priority``) and how it went is ``scheduling.realtime_request``'s.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from urdaemon.scheduling import realtime_request

__all__ = ["CAP_SYS_NICE", "host_facts", "preempt_rt", "sys_nice_capable"]

CAP_SYS_NICE = 23
"""The capability's bit in the capability sets (linux/capability.h)."""
_POLICIES = {
    getattr(os, name): name
    for name in ("SCHED_OTHER", "SCHED_FIFO", "SCHED_RR", "SCHED_BATCH", "SCHED_IDLE")
    if hasattr(os, name)
}


def host_facts(
    *, proc_status: Path = Path("/proc/self/status"), realtime_file: Path = Path("/sys/kernel/realtime")
) -> dict[str, Any]:
    """The host's facts as ``checks.host_checks`` reads them."""
    uname = os.uname()
    realtime = _read(realtime_file)
    asked, error = realtime_request()
    policy, priority = _policy()
    return {
        "release": uname.release,
        "version": uname.version,
        "realtime_sysfs": realtime,
        "preempt_rt": preempt_rt(uname.version, realtime),
        "rtprio_limit": _rtprio_limit(),
        "cap_sys_nice": sys_nice_capable(_read(proc_status)),
        "root": os.geteuid() == 0 if hasattr(os, "geteuid") else False,
        "loop_policy": policy,
        "loop_priority": priority,
        "realtime_priority": asked,
        "realtime_error": error,
    }


def preempt_rt(version: str, realtime_sysfs: str | None) -> bool:
    """Whether the kernel is PREEMPT_RT: ``/sys/kernel/realtime`` holds 1, or ``uname -v`` says so."""
    return (realtime_sysfs or "").strip() == "1" or "PREEMPT_RT" in version


def sys_nice_capable(status: str | None) -> bool | None:
    """Whether ``CapEff`` of a ``/proc/<pid>/status`` text holds CAP_SYS_NICE (None: unknown)."""
    for line in (status or "").splitlines():
        if line.startswith("CapEff:"):
            try:
                return bool(int(line.split(":", 1)[1].strip(), 16) >> CAP_SYS_NICE & 1)
            except ValueError:
                return None
    return None


def _rtprio_limit() -> int | None:
    """The soft RLIMIT_RTPRIO (-1: unlimited; None where the platform has none)."""
    try:
        import resource
    except ImportError:  # pragma: no cover - not Unix
        return None
    limit = getattr(resource, "RLIMIT_RTPRIO", None)
    if limit is None:
        return None
    soft, _ = resource.getrlimit(limit)
    return -1 if soft == resource.RLIM_INFINITY else int(soft)


def _policy() -> tuple[str, int]:
    """The calling thread's scheduling policy's name and priority."""
    getter = getattr(os, "sched_getscheduler", None)
    if getter is None:  # pragma: no cover - not Linux
        return "unknown", 0
    policy = getter(0) & ~getattr(os, "SCHED_RESET_ON_FORK", 0)
    return _POLICIES.get(policy, str(policy)), int(os.sched_getparam(0).sched_priority)


def _read(path: Path) -> str | None:
    try:
        return path.read_text(encoding="ascii", errors="replace")
    except OSError:
        return None
