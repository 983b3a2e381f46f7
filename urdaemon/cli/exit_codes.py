"""The ``urdaemon`` command's exit codes.

One rule: 2 when the input is wrong, whatever finds it (arguments; the cell file and what it names:
a key, a type, a calibration or xacro file, a servo arm's device, a start pose outside the arm's
limits; ``teleop`` without a terminal), so fixing the input is the cure; 1 when the input is fine
and the command failed (goal aborted, no answer, refused: also for the lease, with the daemon's reason
naming the holder; a Zenoh endpoint or port taken). ``serve`` checks the file and the start poses
before it opens Zenoh or a port, so a taken endpoint cannot turn them into 1 (a servo arm's devices
are looked at as the robots start, after Zenoh), and ``check`` exits 2 for what ``serve`` would (plus
a callback port taken now, which ``serve`` would retry forever). 0 success;
130 ``move`` interrupted by Ctrl-C (its goal canceled first; ``teleop`` quits on Ctrl-C with 0, the
robot stopping).
"""

from __future__ import annotations

__all__ = ["EXIT_BAD_INPUT", "EXIT_FAILED", "EXIT_INTERRUPTED", "EXIT_OK"]

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130
"""``move`` interrupted by Ctrl-C (after it canceled its goal), as shells report SIGINT."""
