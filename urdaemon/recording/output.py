"""Where a recording goes (a file, or a rosbag2 bag's directory and file) and how the recorder
says what went wrong: shared by ``record_command.py`` and ``record_session.py``."""

from __future__ import annotations

import errno
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import IO

__all__ = [
    "EXIT_BAD_INPUT",
    "EXIT_FAILED",
    "EXIT_OK",
    "Output",
    "cannot_write",
    "default_output",
    "error",
    "open_output",
]

EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT = 0, 1, 2


@dataclass(slots=True)
class Output:
    """Where a recording goes: the MCAP file, opened; with ``bag`` the rosbag2 directory it is in."""

    path: Path
    stream: IO[bytes]
    bag: Path | None = None


def open_output(target: Path, ros2: bool) -> Output:
    """Create the recording's file (with ``ros2``: the bag's directory and its ``NAME_0.mcap``);
    ``OSError`` when it cannot be written."""
    if not ros2:
        return Output(target, target.open("wb"))
    if target.exists():
        raise FileExistsError(
            errno.EEXIST, "the bag directory exists already (rosbag2 would not overwrite it)"
        )
    target.mkdir()
    path = target / f"{target.name}_0.mcap"
    return Output(path, path.open("wb"), target)


def default_output(cell: str, ros2: bool) -> Output:
    """``<cell>_<time>.mcap`` (a bag: ``<cell>_<time>/``) in the current directory."""
    stamp = time.strftime("%Y%m%d-%H%M%S")
    name = f"{cell}_{stamp}"
    return open_output(Path(name if ros2 else f"{name}.mcap"), ros2)


def cannot_write(target: str | Path, err: OSError) -> str:
    """The message of a file that cannot be written."""
    return f"cannot write {target}: {err.strerror or err}"


def error(text: str, code: int) -> int:
    """Say ``error: text`` on stderr; ``code``."""
    print(f"error: {text}", file=sys.stderr)
    return code
