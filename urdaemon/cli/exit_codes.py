"""The ``urdaemon`` command's exit codes.

0 success; 1 a command failed (goal aborted, no answer, refused: also for the lease, with the daemon's
reason naming the holder); 2 bad input (config, arguments; ``teleop`` without a terminal); 130 ``move``
interrupted by Ctrl-C (its goal canceled first; ``teleop`` quits on Ctrl-C with 0, the robot stopping).
"""

from __future__ import annotations

__all__ = ["EXIT_BAD_INPUT", "EXIT_FAILED", "EXIT_INTERRUPTED", "EXIT_OK"]

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130
"""``move`` interrupted by Ctrl-C (after it canceled its goal), as shells report SIGINT."""
