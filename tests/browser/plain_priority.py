"""Run a command as one more ordinary process of the test run: ``python plain_priority.py COMMAND
[ARG...]`` runs COMMAND at nice 0, unable to raise its own priority.

Chromium is the command (tests/browser/chromium.py). Software WebGL keeps its GPU process busy for
as long as a page is open, up to one and a half of this machine's two cores, and two things made it
starve the real-time tests (fake controllers, the daemons' cycles) of a suite run beside this one:

- Playwright's own launch starts the browser in a new session. Linux's autogroup scheduling
  (``/proc/sys/kernel/sched_autogroup_enabled``) shares the CPU between sessions first, so the
  browser alone got as much CPU as a whole suite. The browser tests therefore start Chromium
  themselves, in the test's session, and attach to it (``connect_over_cdp``).
- Run as root (CI), Chromium raises its browser and GPU processes to nice -8. This drops the
  ``CAP_SYS_NICE`` capability from the bounding set before running the command, so those raises
  fail and every Chromium process stays at this nice value, with every thread it starts.

A lower priority was tried and is worse: a browser kept at nice 19 (or its session's autogroup at
nice 10 or 19) waits so long for each of the thousands of wake-ups a page load takes that, beside
two CPU-bound processes, the page did not load within two minutes.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import os
import sys

NICE = 0
"""The test processes' own: each of the browser's processes gets the share any of them gets."""
PR_CAPBSET_DROP = 24
CAP_SYS_NICE = 23
"""From <linux/prctl.h> and <linux/capability.h>."""


def drop_priority_raises() -> None:
    """``CAP_SYS_NICE`` out of the bounding set: what this process runs cannot lower its nice value
    (nor take a real-time policy). Without the right to drop it (not root), it had no such right."""
    libc = ctypes.CDLL(ctypes.util.find_library("c"), use_errno=True)
    with contextlib.suppress(AttributeError):
        libc.prctl(PR_CAPBSET_DROP, CAP_SYS_NICE, 0, 0, 0)


def main(argv: list[str]) -> None:
    if not argv:
        raise SystemExit("usage: plain_priority.py COMMAND [ARG...]")
    os.setpriority(os.PRIO_PROCESS, 0, NICE)
    drop_priority_raises()
    os.execv(argv[0], argv)


if __name__ == "__main__":
    main(sys.argv[1:])
